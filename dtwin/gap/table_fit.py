"""Fitting a unit of a twin table to a recording: windows, initial states and parameters.

Specification: docs/gap.md §Twin file (Where, Which on any wiring).

A unit (:func:`dtwin.twin.simulate.units_of`) is compared with the recording over **windows**
of :attr:`UnitData.window` samples that tile each part of the recording (training, choosing,
scoring) separately; every window restarts from its own initial states. Those states are
nuisance parameters fitted per window by least squares (started from the recording for a state
that is a recorded output, and from the end of the previous window otherwise), so neither an
unrecorded state nor the noise on a recorded one biases the comparison. A :class:`Variant` is
the unit's twin or the twin with one candidate effect: its compiled model, its extra params
and the maps applied to the recorded inputs and to the simulated outputs. :func:`fit_variant`
fits a variant's params (and every training window's states) on the training part with
``scipy.optimize.least_squares`` and a sparse Jacobian (a window's states touch only its own
rows); :func:`part_error` re-fits only the window states of another part with the params held.

Arrays are time-first: ``(n_samples,)`` or ``(n_samples, n_channels)``.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.twin.simulate import MAX_SUBSTEPS, UnitModel, UnitSpec, window_rows

__all__ = [
    "MAX_FIT_SAMPLES",
    "UnitData",
    "Variant",
    "VariantFit",
    "windows_of",
    "fit_variant",
    "part_error",
    "state_guess",
    "map_fits",
    "FIT_PROCESSES",
]

#: Most training samples a fit uses (evenly spaced windows beyond it).
MAX_FIT_SAMPLES = 4000
#: Most samples of a part a fitted variant is scored on (evenly spaced windows beyond it).
MAX_PART_SAMPLES = 10000
#: Largest ``h·ρ`` of a Runge-Kutta step for a candidate term's own slope.
TERM_RHO = 2.0
#: Largest normalised residual of a diverged simulation (keeps least squares finite).
_DIVERGED = 1e3
#: Most processes that fit a unit's candidates side by side (:func:`map_fits`).
FIT_PROCESSES = 2


def windows_of(start: int, stop: int, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Tile samples ``start … stop − 1`` with windows of ``length`` (the last one absorbs a rest).

    Returns
    -------
    (starts, stops) : numpy.ndarray of int64, shape (n_windows,)
    """
    n = stop - start
    count = max(1, n // max(length, 2))
    edges = start + np.round(np.linspace(0, n, count + 1)).astype(np.int64)
    return edges[:-1].copy(), edges[1:].copy()


@dataclass
class UnitData:
    """A unit with its recorded signals and the diagnoser's layout.

    Attributes
    ----------
    spec, model : UnitSpec, UnitModel
        The unit and its compiled twin.
    inputs : numpy.ndarray, shape (n_samples, n_inputs)
        Recorded inputs, in ``spec.inputs`` order.
    outputs : numpy.ndarray, shape (n_samples, n_outputs)
        Recorded outputs, in ``spec.outputs`` order.
    dt : float
        Sample period, s.
    norm : numpy.ndarray, shape (n_outputs,)
        Standard deviation of each recorded output over the training part (the gaps' unit).
    linear : numpy.ndarray of bool, shape (n_inputs,)
        Each input linear between samples (True) or held (False).
    substeps : int
        Runge-Kutta steps per sample.
    window : int
        Samples per window.
    parts : dict of str to (int, int)
        ``train``, ``choose`` and ``score``: sample ranges.
    declared : dict of str to float
        The twin's declared params (qualified names).
    """

    spec: UnitSpec
    model: UnitModel
    inputs: np.ndarray
    outputs: np.ndarray
    dt: float
    norm: np.ndarray
    linear: np.ndarray
    substeps: int
    window: int
    parts: dict[str, tuple[int, int]]
    declared: dict[str, float]
    guess: np.ndarray | None = field(default=None, repr=False)
    bandwidth: float = 0.0

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return len(self.outputs)

    def windows(self, part: str, cap: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return the windows of a part; with ``cap``, at most ``cap`` samples (spaced evenly)."""
        starts, stops = windows_of(*self.parts[part], self.window)
        if cap is not None and int(np.sum(stops - starts)) > cap:
            keep = max(1, cap // self.window)
            chosen = np.unique(np.round(np.linspace(0, len(starts) - 1, keep)).astype(int))
            starts, stops = starts[chosen], stops[chosen]
        return starts, stops


def _identity(values: np.ndarray, theta: Mapping[str, float], data: UnitData) -> np.ndarray:
    return values


@dataclass(frozen=True)
class Variant:
    """The unit's twin, or the twin with one candidate effect.

    Attributes
    ----------
    name : str
        ``linear`` for the twin itself, else the effect's name.
    at : str or None
        Where the effect attaches: a signal, a qualified state or a param.
    model : UnitModel
        The compiled model (its ``param_names`` end with the effect's in-program params).
    effect_params : tuple of str
        Every param of the effect (in-program and map params), in report order.
    starts, bounds, scales : dict
        Start value, ``(low, high)`` and typical size of each effect param.
    input_map, output_map : callable
        ``(values, theta, data) → values`` on the recorded inputs and on the simulated outputs.
    limits : callable or None
        ``theta → (lo, hi)`` state bounds (a ``state_limit``).
    refits_linear : bool
        The candidate is the twin with every param re-fitted (``parameter_mismatch``).
    linear_form : bool
        The candidate keeps the twin's model class (a re-fit or an output gain).
    fixed : dict
        Effect params set, not fitted (a quantizer's lattice).
    screen_starts : tuple of dict
        Other starts of effect params the screening also fits from (a state limit's), the
        lowest cost kept.
    report : tuple or None
        A named effect's ``(param, factor(m, σ), mass param, σ)``: its reported param is
        ``factor·θ`` (a mass-spring-damper's force).
    stiffness : callable or None
        ``theta → ρ``, the largest rate (1/s) the effect's term adds to the unit's Jacobian:
        the Runge-Kutta sub-steps grow with it (:func:`substeps_for`).
    output_inverse : callable or None
        ``(values, theta, data) → values``: the recorded outputs as the signals themselves, an
        output effect undone where it has an inverse (a drift, a gain, a delay); None else.
    """

    name: str
    at: str | None
    model: UnitModel
    effect_params: tuple[str, ...] = ()
    starts: Mapping[str, float] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    scales: Mapping[str, float] = field(default_factory=dict)
    input_map: Callable = _identity
    output_map: Callable = _identity
    limits: Callable | None = None
    refits_linear: bool = False
    linear_form: bool = False
    fixed: Mapping[str, float] = field(default_factory=dict)
    report: tuple | None = None
    stiffness: Callable | None = None
    screen_starts: tuple = ()
    output_inverse: Callable | None = None


@dataclass
class VariantFit:
    """A variant fitted on the training part.

    ``theta`` holds every param (the twin's and the effect's) by name; ``x0`` the training
    windows' states; ``cost`` the training sum of squares of the normalised residual;
    ``jacobian`` its Jacobian over the free params (columns ``free``) at the optimum, rows the
    residual's, ``residual`` the residual itself.
    """

    variant: Variant
    theta: dict[str, float]
    free: tuple[str, ...]
    x0: np.ndarray
    cost: float
    n_residuals: int
    jacobian: np.ndarray | None = field(default=None, repr=False)
    residual: np.ndarray | None = field(default=None, repr=False)
    success: bool = True


def substeps_for(data: UnitData, variant: Variant, theta: Mapping[str, float]) -> int:
    """Return the Runge-Kutta sub-steps of a variant: the unit's, doubled while a term is stiff.

    A term whose slope reaches ``ρ`` (``variant.stiffness``) needs ``h·ρ ≤`` :data:`TERM_RHO`:
    within RK4's stability interval (2.78 on the negative real axis); its accuracy matters only
    where the slope is that steep (a friction's smoothed sign near rest), unlike the twin's own
    modes (:func:`dtwin.twin.simulate.choose_substeps`). At most
    :data:`~dtwin.twin.simulate.MAX_SUBSTEPS`.
    """
    substeps = data.substeps
    if variant.stiffness is None:
        return substeps
    rho = variant.stiffness(theta)
    while substeps < MAX_SUBSTEPS and data.dt / substeps * rho > TERM_RHO:
        substeps *= 2
    return substeps


def _simulate_rows(data, variant, thetas, starts, stops, x0s) -> list[np.ndarray]:
    """Return each param set's mapped outputs on the windows' rows, shape ``(n_rows, n_outputs)``.

    ``thetas`` are param dicts, ``x0s`` their windows' start states ``(n_batch, n_windows,
    n_states)``; rows as :func:`~dtwin.twin.simulate.window_rows`. The sets are simulated in
    one compiled pass per number of Runge-Kutta sub-steps (:meth:`UnitModel.simulate_batch`),
    each exactly as alone; an output map sees the whole recording's samples (NaN outside the
    windows), as it would after a single simulation.
    """
    model = variant.model
    rows = window_rows(starts, stops)
    out: list[np.ndarray | None] = [None] * len(thetas)
    groups: dict[int, list[int]] = {}
    for b, theta in enumerate(thetas):
        groups.setdefault(substeps_for(data, variant, theta), []).append(b)
    with np.errstate(all="ignore"):
        for substeps, members in groups.items():
            sets: list[np.ndarray] = []
            input_of = []
            for b in members:
                inputs = variant.input_map(data.inputs, thetas[b], data)
                same = (i for i, u in enumerate(sets) if u is inputs or np.array_equal(u, inputs))
                index = next(same, len(sets))
                if index == len(sets):
                    sets.append(inputs)
                input_of.append(index)
            values = [[thetas[b][name] for name in model.param_names] for b in members]
            limits = [variant.limits(thetas[b]) if variant.limits else None for b in members]
            options = dict(substeps=substeps, linear=data.linear)
            if hasattr(model, "simulate_batch"):
                y, _ = model.simulate_batch(
                    sets, input_of, values, starts, stops, x0s[members], data.dt,
                    limits=limits, **options,
                )  # fmt: skip
            else:  # a model without a batch (an FMU): one simulation each
                y = [
                    model.simulate(sets[i], v, starts, stops, x0s[b], data.dt, limits=lim,
                                   **options)[0][rows]
                    for i, v, b, lim in zip(input_of, values, members, limits, strict=True)
                ]  # fmt: skip
            for yb, b in zip(y, members, strict=True):
                if variant.output_map is not _identity:
                    full = np.full((data.n_samples, yb.shape[1]), np.nan)
                    full[rows] = yb
                    yb = variant.output_map(full, thetas[b], data)[rows]
                out[b] = yb
    return out


def _simulate(data, variant, theta, starts, stops, x0):
    """Return the variant's mapped outputs over the windows, shape ``(n_samples, n_outputs)``.

    NaN outside the windows.
    """
    (y,) = _simulate_rows(data, variant, [theta], starts, stops, np.asarray(x0)[None])
    full = np.full((data.n_samples, y.shape[1]), np.nan)
    full[window_rows(starts, stops)] = y
    return full


def _normalised(data, y, recorded):
    """Return the residual ``(simulated − recorded)/norm`` on the windows' rows, flattened.

    Diverged values are clipped to ±:data:`_DIVERGED`.
    """
    residual = (y - recorded) / data.norm
    residual = np.where(np.isfinite(residual), residual, _DIVERGED)
    return np.clip(residual, -_DIVERGED, _DIVERGED).ravel()


def _batch_map(residuals):
    """Return a map-like for ``least_squares(workers=...)``: one batch per Jacobian.

    Every point of one finite-difference Jacobian is simulated in one batch (``residuals`` maps
    a list of points to their residuals): the same residuals as one call each.
    """

    def evaluate(_fun, points):
        return residuals(list(points))

    return evaluate


def state_guess(data: UnitData, theta: Mapping[str, float], variant: Variant) -> np.ndarray:
    """Start states at every sample, shape ``(n_samples, n_states)``: a chained run.

    Windows of the whole recording are run in turn, each from the end of the previous one, a
    recorded state reset to its recorded value at each start; the first starts from the
    declared initial states, the recorded ones, and 0 for the rest.
    """
    spec = data.spec
    n_states = len(spec.states)
    starts, stops = windows_of(0, data.n_samples, data.window)
    guess = np.zeros((data.n_samples, n_states))
    state = np.array([spec.initial.get(s, 0.0) for s in spec.states])
    recorded = {spec.states.index(s): spec.outputs.index(o) for o, s in spec.output_states.items()}
    values = [theta[name] for name in variant.model.param_names]
    inputs = variant.input_map(data.inputs, theta, data)
    if hasattr(variant.model, "simulate_chained"):  # one compiled pass
        reset = np.array(list(recorded), dtype=np.int64)
        reset_values = data.outputs[starts][:, list(recorded.values())]
        with np.errstate(all="ignore"):
            guess[window_rows(starts, stops)] = variant.model.simulate_chained(
                inputs, values, starts, stops, state, reset, reset_values, data.dt,
                substeps=data.substeps, linear=data.linear,
            )  # fmt: skip
        return guess
    for a, b in zip(starts, stops, strict=False):  # a model without it (an FMU): window by window
        for j, o in recorded.items():
            state[j] = data.outputs[a, o]
        with np.errstate(all="ignore"):
            _, states = variant.model.simulate(
                inputs, values, np.array([a]), np.array([b]), state[None, :], data.dt,
                substeps=data.substeps, linear=data.linear,
            )  # fmt: skip
        guess[a:b] = states[a:b]
        end = states[b - 1]
        state = np.where(np.isfinite(end), end, state)
    return guess


def _free_layout(data, variant, mode, nominal, band):
    """Return the free params, their starts, bounds and scales for a fit in ``mode``."""
    names, start, low, high, scale = [], [], [], [], []
    tolerance = {"band": band, "free": math.inf}.get(mode)
    if tolerance is not None:
        for name, value in nominal.items():
            if name in data.spec.defaults:
                continue  # a block's default the file does not write is structure, not a value
            centre = data.declared.get(name, value)
            declared = abs(centre)
            if mode == "band" and declared == 0.0:
                continue  # a param declared 0 (no offset) stays 0 within any relative band
            typical = declared if declared > 0 else 1.0
            width = tolerance * typical
            lo, hi = centre - width, centre + width
            if mode == "free" and data.declared.get(name, value) > 0:
                lo = 0.0
            names.append(name)
            start.append(value)
            low.append(lo)
            high.append(hi)
            scale.append(typical)
    for name in variant.effect_params:
        if name in variant.fixed:
            continue
        names.append(name)
        start.append(variant.starts[name])
        low.append(variant.bounds[name][0])
        high.append(variant.bounds[name][1])
        scale.append(variant.scales[name])
    start = np.clip(start, np.nextafter(low, np.inf), np.nextafter(high, -np.inf))
    return names, np.array(start), np.array(low), np.array(high), np.array(scale)


def fit_variant(
    data: UnitData,
    variant: Variant,
    nominal: Mapping[str, float],
    *,
    mode: str = "fixed",
    cap: int | None = MAX_FIT_SAMPLES,
    max_nfev: int = 60,
    fit_states: bool = True,
    band: float = 0.05,
    x0: np.ndarray | None = None,
    start: Mapping[str, float] | None = None,
    windows: tuple[np.ndarray, np.ndarray] | None = None,
) -> VariantFit:
    """Fit a variant's params and every training window's states on the training part.

    Parameters
    ----------
    data : UnitData
    variant : Variant
    nominal : mapping of str to float
        The twin's params (qualified) to start from.
    mode : {"fixed", "band", "free"}
        The twin's params held (``fixed``), re-fitted within 5 % of their declared value
        (``band``: ``band`` of their declared value, the calibration tolerance; a param
        declared 0 stays 0) or re-fitted freely (``free``, sign kept for a positive declared
        param); a block's default that the file does not write
        (:attr:`~dtwin.twin.simulate.UnitSpec.defaults`) is held in both.
    cap : int, optional
        Most training samples used (:data:`MAX_FIT_SAMPLES`).
    max_nfev : int
        Most residual evaluations of least squares.
    fit_states : bool
        Fit the windows' states (True) or keep their start values.
    band : float
        The calibration tolerance of ``mode="band"``.
    x0 : numpy.ndarray, shape (n_windows, n_states), optional
        The training windows' start states (default: :func:`state_guess` at their starts).
    start : mapping of str to float, optional
        Start values of the effect's params (default ``variant.starts``: a screening fit's
        values make the full fit shorter).
    windows : (starts, stops), optional
        The training windows to fit on (default: ``data.windows("train", cap)``).

    Returns
    -------
    VariantFit
    """
    from scipy.optimize import least_squares

    starts, stops = data.windows("train", cap) if windows is None else windows
    if start:
        variant = replace(variant, starts={**variant.starts, **start})
    names, p0, low, high, scale = _free_layout(data, variant, mode, nominal, band)
    theta = {**nominal, **variant.starts, **variant.fixed}
    guess = data.guess if data.guess is not None else state_guess(data, theta, variant)
    x0 = np.ascontiguousarray(guess[starts] if x0 is None else x0)
    recorded = data.outputs[window_rows(starts, stops)]
    n_states = x0.shape[1] if fit_states else 0
    state_scale = _state_scales(guess, n_states)

    def unpack(z):
        values = dict(theta)
        values.update(zip(names, z[: len(names)], strict=False))
        states = z[len(names) :].reshape(len(starts), n_states) if n_states else x0
        return values, states

    def residuals(points):
        unpacked = [unpack(z) for z in points]
        x0s = np.stack([states for _, states in unpacked])
        ys = _simulate_rows(data, variant, [v for v, _ in unpacked], starts, stops, x0s)
        return [_normalised(data, y, recorded) for y in ys]

    def residual(z):
        return residuals([z])[0]

    z0 = np.concatenate([p0, x0.ravel() if n_states else []])
    lower = np.concatenate([low, np.full(len(starts) * n_states, -np.inf)])
    upper = np.concatenate([high, np.full(len(starts) * n_states, np.inf)])
    scales = np.concatenate([scale, np.tile(state_scale, len(starts))])
    # scipy's sparse trust region fails on one or two columns; dense is as cheap there
    columns = len(names) + len(starts) * n_states
    sparsity = (
        _sparsity(data, starts, stops, len(names), n_states) if n_states and columns > 2 else None
    )
    if len(z0) == 0:
        r = residual(z0)
        return VariantFit(variant, dict(theta), (), x0, float(r @ r), len(r), None, r)
    result = least_squares(
        residual, z0, bounds=(lower, upper), x_scale=scales, jac_sparsity=sparsity,
        max_nfev=max_nfev, xtol=1e-5, ftol=1e-6, workers=_batch_map(residuals),
    )  # fmt: skip
    values, states = unpack(result.x)
    jac = result.jac.toarray() if hasattr(result.jac, "toarray") else np.asarray(result.jac)
    return VariantFit(
        variant, values, tuple(names), np.ascontiguousarray(states), float(result.fun @ result.fun),
        len(result.fun), jac, result.fun, bool(result.status > 0),
    )  # fmt: skip


def _state_scales(guess: np.ndarray, n_states: int) -> np.ndarray:
    if not n_states:
        return np.zeros(0)
    spread = np.nanstd(guess, axis=0)
    level = np.nanmax(np.abs(guess), axis=0)
    return np.where(spread > 0, spread, np.where(level > 0, level, 1.0))


def _sparsity(data, starts, stops, n_params, n_states):
    """Jacobian sparsity: params touch every row, a window's states its own rows.

    A CSC matrix (scipy's finite differences read it column by column), int8 ones.
    """
    from scipy.sparse import csc_matrix

    n_out = data.outputs.shape[1]
    heights = (np.asarray(stops) - np.asarray(starts)) * n_out
    n_rows = int(heights.sum())
    first = np.concatenate([[0], np.cumsum(heights)[:-1]])
    # column c holds rows [row_start[c], row_stop[c]): every row for a param, a window's own
    row_start = np.concatenate([np.zeros(n_params, int), np.repeat(first, n_states)])
    row_stop = np.concatenate([np.full(n_params, n_rows), np.repeat(first + heights, n_states)])
    indptr = np.concatenate([[0], np.cumsum(row_stop - row_start)])
    indices = np.concatenate([np.arange(a, b) for a, b in zip(row_start, row_stop, strict=True)])
    shape = (n_rows, n_params + len(starts) * n_states)
    return csc_matrix((np.ones(len(indices), dtype=np.int8), indices, indptr), shape=shape)


def part_error(
    data: UnitData,
    fit: VariantFit,
    part: str,
    *,
    fit_states: bool = True,
    cap: int | None = MAX_PART_SAMPLES,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the fitted variant's error on a part, its window states re-fitted (params held).

    With ``cap``, at most that many samples of the part are simulated (evenly spaced windows,
    :data:`MAX_PART_SAMPLES`); the others are NaN.

    Returns
    -------
    (error, simulated) : numpy.ndarray, shape (n_samples, n_outputs)
        ``simulated − recorded`` and the simulation, NaN outside the part.
    """
    from scipy.optimize import least_squares

    variant, theta = fit.variant, fit.theta
    starts, stops = data.windows(part, cap)
    guess = data.guess if data.guess is not None else state_guess(data, theta, variant)
    x0 = np.ascontiguousarray(guess[starts])
    recorded = data.outputs[window_rows(starts, stops)]
    n_states = x0.shape[1]
    if fit_states and n_states:

        def residuals(points):
            x0s = np.stack([z.reshape(len(starts), n_states) for z in points])
            ys = _simulate_rows(data, variant, [theta] * len(points), starts, stops, x0s)
            return [_normalised(data, y, recorded) for y in ys]

        def residual(z):
            return residuals([z])[0]

        columns = len(starts) * n_states
        # scipy's sparse trust region fails on one or two columns; dense is as cheap there
        sparsity = _sparsity(data, starts, stops, 0, n_states) if columns > 2 else None
        result = least_squares(
            residual, x0.ravel(), x_scale=np.tile(_state_scales(guess, n_states), len(starts)),
            jac_sparsity=sparsity, max_nfev=20, xtol=1e-5, workers=_batch_map(residuals),
        )  # fmt: skip
        x0 = result.x.reshape(len(starts), n_states)
    simulated = _simulate(data, variant, theta, starts, stops, x0)
    return simulated - data.outputs, simulated


def require_finite_fit(fit: VariantFit, unit: str) -> None:
    """Refuse a twin whose simulation diverges everywhere (a clear error, not a traceback)."""
    if fit.residual is not None and np.all(np.abs(fit.residual) >= _DIVERGED):
        raise DtwinValueError(
            f"unit {unit}: the twin's simulation is not finite on the recording (check its "
            "params and initial states)"
        )


def rms_by_output(error: np.ndarray, rows: slice, norm: np.ndarray) -> np.ndarray:
    """Normalised RMS of ``error`` over ``rows`` per output, shape ``(n_outputs,)``."""
    part = error[rows] / norm
    with np.errstate(over="ignore", invalid="ignore"):
        return np.sqrt(np.nanmean(part**2, axis=0))


def combined(gaps: Sequence[float]) -> float:
    """One gap for several outputs: the RMS of their normalised gaps."""
    values = np.asarray(gaps, dtype=float)
    return float(np.sqrt(np.mean(values**2)))


#: The function and items of the :func:`map_fits` running now (read by its forked workers).
_TASK: tuple | None = None
#: This process is a :func:`map_fits` worker (its own fits run in turn).
_IN_WORKER = False


def _mark_worker() -> None:
    global _IN_WORKER
    _IN_WORKER = True


def _run_task(index: int):
    function, items = _TASK
    return function(items[index])


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def map_fits(function: Callable, items: Sequence) -> list:
    """Return ``[function(item) for item in items]``, the items shared among forked processes.

    Up to :data:`FIT_PROCESSES` processes (no more than the cores this process may use), each
    a fork of this one, so ``function`` may be a closure; results come back pickled, in
    order, and are those of the calls made here (the same code on the same inputs). Where
    fork is not available, inside a worker (this one's, or any daemonic process such as a
    user's ``multiprocessing.Pool`` worker), or for one item, the calls run here in turn.
    ``function``'s results must pickle (a :class:`VariantFit` without its ``variant``).
    """
    global _TASK
    items = list(items)
    processes = min(FIT_PROCESSES, len(items), _cores())
    daemon = multiprocessing.current_process().daemon  # a Pool's worker may have no children
    if (
        processes < 2
        or _IN_WORKER
        or daemon
        or "fork" not in multiprocessing.get_all_start_methods()
    ):
        return [function(item) for item in items]
    _TASK = (function, items)
    try:
        context = multiprocessing.get_context("fork")
        with context.Pool(processes, initializer=_mark_worker) as pool:
            return pool.map(_run_task, range(len(items)), chunksize=1)
    finally:
        _TASK = None
