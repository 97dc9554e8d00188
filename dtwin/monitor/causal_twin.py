"""The twin run causally: residuals a live monitor can reproduce sample by sample.

Specification: docs/monitor.md §Residuals. The diagnoser's residuals
(:func:`dtwin.gap.table_residuals.table_residuals`) fit every window's states on the window
itself, which needs the window's future. Here each unit of the twin table
(:func:`dtwin.twin.simulate.units_of`) is **frozen** (:func:`freeze_units`: its params fitted
once, on the nominal stretch, as the diagnoser fits them) and then **continued**: from its state
at the previous sample to the next, a state that is a recorded output moved by its mean
residual over the last :func:`reset_span` samples at every window start (every
:attr:`FrozenUnit.window` samples; a reset to the reading itself would put the reading's noise
into the state for a time constant), the others carried on.
At a start (the first sample, or after a jump in time) the states are unknown: the first
:attr:`CausalTwin.settling` samples are the **settling period**, over which each unit's initial
states are fitted by least squares (params held, as the diagnoser fits a window's states); no
residual is given inside it. The residual of a recorded output is ``recorded − twin``.

:class:`CausalTwin` takes samples in chunks of any size and gives the same bits whatever the
cut, so ``dtwin regimes`` (one chunk: the whole recording) and ``dtwin monitor`` (what the
stream holds) agree. Arrays are time-first: ``(n_samples, n_columns)``.
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.twin.simulate import UnitModel, UnitSpec, units_of

__all__ = [
    "FrozenUnit",
    "CausalRows",
    "CausalTwin",
    "freeze_units",
    "frozen_units_from_mapping",
    "channel_names",
    "settling_samples",
    "reset_span",
    "SETTLE_SHARE",
    "MIN_SETTLE",
]

#: Largest normalised residual of a diverged start fit (keeps least squares finite).
_DIVERGED = 1e3
_FIRST = np.zeros(1, dtype=np.int64)
#: Share of a unit's window (ten time constants of its slowest mode) its settling period lasts.
SETTLE_SHARE = 0.3
#: Fewest samples of a settling period (of a unit with states that are not recorded).
MIN_SETTLE = 20


def settling_samples(window: int) -> int:
    """Return the samples over which a unit's unrecorded states are fitted at a start.

    :data:`SETTLE_SHARE` of the unit's window (the diagnoser's: ten time constants of its
    slowest mode), so three time constants, at least :data:`MIN_SETTLE` samples.

    Examples
    --------
    >>> settling_samples(346), settling_samples(40)
    (104, 20)
    """
    return max(MIN_SETTLE, math.ceil(SETTLE_SHARE * window))


def reset_span(window: int) -> int:
    """Return the samples whose mean residual moves a recorded state at a window cut.

    One time constant of the unit's slowest mode (a tenth of its window), at least 1: the
    reading's noise enters the state divided by about the square root of it, while a drift
    slower than a time constant is followed.

    Examples
    --------
    >>> reset_span(335), reset_span(5)
    (33, 1)
    """
    return max(1, window // 10)


def channel_names(units: Sequence[FrozenUnit]) -> list[str]:
    """Return the residual channels ``<unit>:<signal>`` of ``units``, in order."""
    return [f"{u.name}:{signal}" for u in units for signal in u.outputs]


def _fingerprint(spec: UnitSpec) -> str:
    """Return a digest of the unit's equations (targets, texts, bound names) and params.

    A unit with discrete modules (``discretisation: euler | zoh``) adds how each state steps:
    params fitted under one stepping rule do not continue under another. A continuous unit's
    digest is as before it could say so.
    """
    parts = [(a.target, a.text, sorted(a.symbols.items())) for a in spec.assignments]
    parts += [sorted(spec.params), list(spec.output_states.items())]
    if spec.stepping:
        parts.append(sorted(spec.stepping.items()))
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class FrozenUnit:
    """One unit of the twin with its params fixed: what the monitor continues.

    Attributes
    ----------
    name : str
        The unit's modules joined by ``+``.
    inputs, outputs, states : tuple of str
        Its recorded inputs, recorded outputs and qualified states.
    theta : dict of str to float
        Every param (qualified name) as fitted on the nominal stretch.
    window : int
        Samples between resets of the states that are recorded outputs.
    substeps : int
        Runge-Kutta steps per sample.
    linear : tuple of bool
        Each input linear between samples (True) or held.
    settle : int
        Samples over which the initial states are fitted at a start (:func:`settling_samples`;
        1 when every state is a recorded output).
    norm : tuple of float
        Each output's standard deviation on the nominal stretch (the start fit's unit).
    x_typical, x_scale : tuple of float
        Each state's median and spread over the nominal stretch (the start fit's first
        guess and scale).
    fingerprint : str
        Digest of the unit's equations: a model file is refused for another twin.
    """

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    states: tuple[str, ...]
    theta: dict[str, float]
    window: int
    substeps: int
    linear: tuple[bool, ...]
    settle: int
    norm: tuple[float, ...]
    x_typical: tuple[float, ...]
    x_scale: tuple[float, ...]
    fingerprint: str

    def to_mapping(self) -> dict:
        """Return the unit as plain data (``regimes.json``'s ``twin.units``)."""
        return asdict(self)


def _unit_from_mapping(raw: Mapping) -> FrozenUnit:
    tuples = ("inputs", "outputs", "states", "linear", "norm", "x_typical", "x_scale")
    values = {key: tuple(raw[key]) for key in tuples}
    return FrozenUnit(
        name=str(raw["name"]),
        theta={str(k): float(v) for k, v in raw["theta"].items()},
        window=int(raw["window"]),
        substeps=int(raw["substeps"]),
        settle=int(raw["settle"]),
        fingerprint=str(raw["fingerprint"]),
        **values,
    )


def frozen_units_from_mapping(raw: Sequence[Mapping], table) -> list[FrozenUnit]:
    """Return the frozen units of ``regimes.json`` after checking that they are ``table``'s.

    Parameters
    ----------
    raw : sequence of mapping
        ``regimes.json``'s ``twin.units``.
    table : dtwin.twin.table.TwinTable

    Raises
    ------
    DtwinValueError
        One line naming the first unit, signal or equation that differs.
    """
    try:
        units = [_unit_from_mapping(entry) for entry in raw]
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise DtwinValueError(f"regimes file: twin.units is malformed ({error})") from error
    recorded = {s for u in units for s in (*u.inputs, *u.outputs)}
    specs = {spec.name: spec for spec in units_of(table, sorted(recorded))}
    if sorted(specs) != sorted(u.name for u in units):
        raise DtwinValueError(
            "regimes file does not match the twin: it was fitted for unit(s) "
            f"{', '.join(u.name for u in units)}; on those signals the twin has "
            f"{', '.join(specs) or 'none'} (modules {', '.join(m.name for m in table.modules)})"
        )
    for unit in units:
        spec = specs[unit.name]
        for key in ("inputs", "outputs", "states"):
            if tuple(getattr(spec, key)) != getattr(unit, key):
                raise DtwinValueError(
                    f"regimes file does not match the twin: unit {unit.name} {key} "
                    f"{', '.join(getattr(unit, key))} (the twin: {', '.join(getattr(spec, key))})"
                )
        if _fingerprint(spec) != unit.fingerprint:
            raise DtwinValueError(
                f"regimes file does not match the twin: unit {unit.name}'s equations or params "
                "differ from those it was fitted with (run dtwin regimes again)"
            )
    return units


def freeze_units(recording, table, rows: tuple[int, int], *, calibrate: bool = False):
    """Fit every unit's params on ``rows`` of the recording, as the diagnoser does; freeze them.

    Parameters
    ----------
    recording : dtwin.gap.recording.Recording
    table : dtwin.twin.table.TwinTable
    rows : (int, int)
        The nominal stretch, samples ``rows[0] … rows[1] − 1``.
    calibrate : bool
        Fit every param freely (else within the calibration tolerance of its declared value).

    Returns
    -------
    list of FrozenUnit
        In table order.
    """
    from threadpoolctl import threadpool_limits

    from dtwin.gap.results import GapSettings
    from dtwin.gap.table_diagnose import _nominal_fit
    from dtwin.gap.table_fit import require_finite_fit, state_guess

    settings = GapSettings()
    stop = rows[1]  # only the nominal stretch is read: the twin runs over no later sample
    recording = replace(
        recording, t=recording.t[:stop], signals={k: v[:stop] for k, v in recording.signals.items()}
    )
    parts = {"train": rows, "choose": (stop, stop), "score": (stop, stop)}
    units = []
    with threadpool_limits(limits=1):
        for spec in units_of(table, list(recording.signals)):
            if spec.states:
                data = _prepared(spec, recording, table, parts, settings, calibrate)
            else:
                data = _algebraic_data(spec, recording, parts)
            if _unrecorded(spec):
                fit = _continuous_fit(data, settings, calibrate)
            else:
                fit = _nominal_fit(data, settings, calibrate)
            require_finite_fit(fit, spec.name)
            guess = state_guess(data, fit.theta, fit.variant)[slice(*rows)]
            units.append(_frozen(spec, data, fit, guess))
    return units


def _unrecorded(spec: UnitSpec) -> bool:
    """Whether the unit has a state that is no recorded output (it runs open loop)."""
    recorded = set(spec.output_states.values())
    return any(s not in recorded for s in spec.states)


def _continuous_fit(data, settings, calibrate):
    """Fit a unit's params on one run over the whole nominal stretch (its first states free).

    A unit with unrecorded states is continued open loop by the monitor, so its params are
    fitted on the residual the monitor computes: one run from the stretch's first sample.
    The diagnoser's fit gives every window (a quarter of the stretch at most) its own initial
    states, which absorb a slow mode's error: on a thermal twin whose slowest time constant is
    longer than its windows, params fitted that way were off by up to 6 % (2 % declared) and
    the residual of the unseen half sat a residual sd off.
    """
    from dtwin.gap.table_diagnose import _nominal_fit

    start, stop = data.parts["train"]
    return _nominal_fit(replace(data, window=stop - start), settings, calibrate)


def _prepared(spec, recording, table, parts, settings, calibrate):
    """Return the diagnoser's layout of a unit with states (holds, substeps, window)."""
    from dtwin.gap.table_diagnose import _prepare_unit

    try:
        return _prepare_unit(spec, recording, table, parts, settings, calibrate)
    except OverflowError as error:  # no decaying mode: no time constant sets a window
        raise DtwinValueError(
            f"unit {spec.name}: no state decays (an integrator alone?), so no window can be "
            "chosen for it; record one of its states or add its feedback"
        ) from error


def _algebraic_data(spec: UnitSpec, recording, parts):
    """Return the layout of a unit without states (outputs are functions of the inputs)."""
    from dtwin.gap.table_fit import UnitData

    train = slice(*parts["train"])
    n = recording.n_samples
    inputs = np.column_stack([recording.signals[s] for s in spec.inputs] or [np.zeros((n, 0))])
    outputs = np.column_stack([recording.signals[s] for s in spec.outputs])
    norm = outputs[train].std(axis=0)
    if not np.all(norm > 0):
        raise DtwinValueError(f"unit {spec.name}: an output does not vary on the nominal stretch")
    linear = np.ones(len(spec.inputs), dtype=bool)  # read at the samples only
    return UnitData(spec, UnitModel.from_spec(spec), np.ascontiguousarray(inputs), outputs,
                    recording.dt, norm, linear, 1, parts["train"][1] - parts["train"][0],
                    parts, dict(spec.params))  # fmt: skip


def _frozen(spec: UnitSpec, data, fit, guess: np.ndarray) -> FrozenUnit:
    unrecorded = _unrecorded(spec)
    typical = np.nanmedian(guess, axis=0) if len(spec.states) else np.zeros(0)
    spread = np.nanstd(guess, axis=0) if len(spec.states) else np.zeros(0)
    scale = np.where(spread > 0, spread, np.maximum(np.abs(typical), 1.0))
    return FrozenUnit(
        name=spec.name,
        inputs=tuple(spec.inputs),
        outputs=tuple(spec.outputs),
        states=tuple(spec.states),
        theta={k: float(v) for k, v in fit.theta.items()},
        window=int(data.window),
        substeps=int(data.substeps),
        linear=tuple(bool(v) for v in data.linear),
        settle=settling_samples(int(data.window)) if unrecorded else 1,
        norm=tuple(float(v) for v in data.norm),
        x_typical=tuple(float(v) for v in np.nan_to_num(typical)),
        x_scale=tuple(float(v) for v in scale),
        fingerprint=_fingerprint(spec),
    )


@dataclass(frozen=True)
class CausalRows:
    """What :meth:`CausalTwin.feed` returns for a chunk of samples.

    Attributes
    ----------
    simulated, residuals : ndarray, shape (n, n_channels)
        The twin's outputs and ``recorded − twin`` per channel (:func:`channel_names`);
        NaN inside the settling period and at missing samples (residuals only).
    settling : ndarray of bool, shape (n,)
        The sample lies in a settling period.
    """

    simulated: np.ndarray
    residuals: np.ndarray
    settling: np.ndarray


class _UnitRunner:
    """One frozen unit compiled, with its place in the stream's columns and its running state."""

    def __init__(self, unit: FrozenUnit, spec: UnitSpec, columns: Sequence[str], dt: float):
        self.unit, self.dt = unit, dt
        self.model = UnitModel.from_spec(spec)
        self.theta = np.array([unit.theta[name] for name in self.model.param_names])
        self.in_cols = np.array([columns.index(s) for s in unit.inputs], dtype=np.int64)
        self.out_cols = np.array([columns.index(s) for s in unit.outputs], dtype=np.int64)
        pairs = [
            (spec.states.index(st), spec.outputs.index(o)) for o, st in spec.output_states.items()
        ]
        self.reset_states = np.array([p[0] for p in pairs], dtype=np.int64)
        self.reset_outputs = np.array([p[1] for p in pairs], dtype=np.int64)
        self.state = np.zeros(len(spec.states))
        self.span = reset_span(unit.window)
        self.recent = np.zeros((0, len(pairs)))
        n_states = len(spec.states)
        self.limits = (np.full(n_states, -np.inf), np.full(n_states, np.inf))
        self.linear = np.asarray(unit.linear, dtype=np.bool_)

    def start_state(self, rows: np.ndarray) -> None:
        """Fit the initial states on the first ``settle`` rows (params held)."""
        u, y = rows[:, self.in_cols], rows[:, self.out_cols]
        x = np.array(self.unit.x_typical, dtype=float)
        x[self.reset_states] = y[0, self.reset_outputs]
        if self.unit.settle > 1 and len(x):
            x = self._fitted_start(u[: self.unit.settle], y[: self.unit.settle], x)
        self.state = x
        self.recent = np.zeros((0, len(self.reset_states)))

    def _fitted_start(self, u: np.ndarray, y: np.ndarray, guess: np.ndarray) -> np.ndarray:
        from scipy.optimize import least_squares

        norm = np.asarray(self.unit.norm)
        starts, stops = np.array([0]), np.array([len(u)])

        def residual(x):
            with np.errstate(all="ignore"):
                simulated, _ = self.model.simulate(
                    u, self.theta, starts, stops, x[None, :], self.dt,
                    substeps=self.unit.substeps, linear=self.unit.linear,
                )  # fmt: skip
            r = (simulated - y) / norm
            r = np.where(np.isnan(y), 0.0, np.where(np.isfinite(r), r, _DIVERGED))
            return np.clip(r, -_DIVERGED, _DIVERGED).ravel()

        fit = least_squares(
            residual, guess, x_scale=np.asarray(self.unit.x_scale), max_nfev=100, xtol=1e-10
        )
        return fit.x

    def _simulate(self, u: np.ndarray, t0: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the outputs and states of rows ``u`` from the state at row 0 (one window).

        The caller holds floating-point warnings off (a diverging state is checked after).
        """
        return self.model.simulate(
            u, self.theta, _FIRST, np.array([len(u)]), self.state[None, :], self.dt,
            substeps=self.unit.substeps, linear=self.linear, limits=self.limits, t0=t0,
        )  # fmt: skip

    def run(self, rows: np.ndarray, k0: int, t0: float) -> np.ndarray:
        """Return the outputs at ``rows`` (row 0: the state's sample); move the state on.

        Rows are run in windows cut where the global index ``k0 + r`` is a multiple of the
        unit's window (never at row 0: its state is given); at a cut the states that are
        recorded outputs are moved by their outputs' mean residual over the last
        :func:`reset_span` samples (finite ones), and the cut's output is the moved state's. A
        unit without such states runs in one piece.
        """
        n, window = len(rows), self.unit.window
        first = (-k0) % window or window
        if n == 2 and (first > 1 or not len(self.reset_states)):  # a live stream's one sample
            out, states = self._simulate(rows[:, self.in_cols], t0)
            self.state = states[-1]
            if len(self.reset_states):
                gaps = rows[1:, self.out_cols[self.reset_outputs]] - out[1:, self.reset_outputs]
                self.recent = np.vstack([self.recent, gaps])[-self.span :]
            return out
        u, y = rows[:, self.in_cols], rows[:, self.out_cols]
        out = np.empty((n, len(self.out_cols)))
        cuts = list(range(first, n, window)) if len(self.reset_states) else []
        bounds = [0, *cuts] + ([n - 1] if not cuts or cuts[-1] != n - 1 else [])
        if n == 1:
            out[:] = self._simulate(u, t0)[0]
        moved = len(self.reset_states) > 0
        if moved:
            recorded = y[:, self.reset_outputs]
            before = np.full_like(recorded, np.nan)  # the outputs before any move: residuals
        for a, b in itertools.pairwise(bounds):
            outputs, states = self._simulate(u[a : b + 1], t0 + a * self.dt)
            out[a : b + 1] = outputs
            if moved:
                before[a + 1 : b + 1] = outputs[1:, self.reset_outputs]
            self.state = states[-1].copy()
            if b in cuts:
                self._move(recorded, before, b)
                if b == n - 1:
                    out[b] = self._simulate(u[b : b + 1], t0 + b * self.dt)[0][0]
        if moved:
            gaps = recorded[1:] - before[1:]
            self.recent = np.vstack([self.recent, gaps])[-self.span :]
        return out

    def _move(self, recorded: np.ndarray, before: np.ndarray, b: int) -> None:
        """Move the reset states by the mean residual of the ``span`` samples up to row ``b``."""
        lo = max(1, b - self.span + 1)
        gaps = recorded[lo : b + 1] - before[lo : b + 1]
        older = self.span - len(gaps)
        if older > 0 and len(self.recent):
            gaps = np.vstack([self.recent[-older:], gaps])
        finite = np.isfinite(gaps)
        counts = finite.sum(axis=0)
        keep = counts > 0
        shift = np.where(finite, gaps, 0.0).sum(axis=0)[keep] / counts[keep]
        self.state[self.reset_states[keep]] += shift


class CausalTwin:
    """The frozen twin continued over a stream of samples (module docstring).

    Parameters
    ----------
    units : sequence of FrozenUnit
    table : dtwin.twin.table.TwinTable
        The twin the units belong to (:func:`frozen_units_from_mapping` checked it).
    dt : float
        Sample period, s.
    channels : collection of str, optional
        Run only the units holding one of these channels (default: every unit).

    Attributes
    ----------
    columns : tuple of str
        The signals a sample row carries, in order: every unit's inputs and outputs.
    channels : list of str
        The residual channels of the units run (:func:`channel_names`).
    settling : int
        Samples of the settling period after a start (the longest of the units').
    """

    def __init__(self, units: Sequence[FrozenUnit], table, dt: float, channels=None):
        if not units:
            raise DtwinValueError("the twin has no unit with a recorded output to monitor")
        self.columns = tuple(dict.fromkeys(s for u in units for s in (*u.inputs, *u.outputs)))
        specs = {spec.name: spec for spec in units_of(table, list(self.columns))}
        self.settling = max(u.settle for u in units)  # every unit's, as dtwin regimes had it
        if channels is not None:  # run only the units holding one of these channels
            units = [u for u in units if set(channel_names([u])) & set(channels)]
        self.runners = [_UnitRunner(u, specs[u.name], self.columns, dt) for u in units]
        self.output_columns = np.array([i for r in self.runners for i in r.out_cols], dtype=int)
        self.channels = channel_names(units)
        self.dt = float(dt)
        self.restart(0.0)

    def restart(self, t0: float) -> None:
        """Forget the states: the next sample starts a settling period at time ``t0`` (s)."""
        self.t0 = float(t0)
        self.buffer: list[np.ndarray] = []
        self.k = -1  # global index of the last sample run
        self.last: np.ndarray | None = None

    @property
    def settled(self) -> bool:
        """Whether the settling period is over."""
        return self.last is not None

    @property
    def diverged(self) -> bool:
        """Whether a unit's state is no longer finite (the twin must restart)."""
        states = [r.state for r in self.runners]
        return self.settled and not np.isfinite(np.concatenate(states)).all()

    def feed(self, rows: np.ndarray) -> CausalRows:
        """Run the twin over the next samples; return their outputs and residuals.

        Parameters
        ----------
        rows : ndarray, shape (n, len(columns))
            Consecutive samples (one every ``dt``); a missing sample is a row whose outputs
            are NaN and whose inputs are interpolated.

        Returns
        -------
        CausalRows
        """
        rows = np.asarray(rows, dtype=float).reshape(-1, len(self.columns))
        n = len(rows)
        if self.settled:  # the common case: every row continues the run
            with np.errstate(all="ignore"):  # a diverging state is checked after (diverged)
                simulated = self._continue(rows)
                residuals = rows[:, self.output_columns] - simulated
            return CausalRows(simulated, residuals, np.zeros(n, dtype=bool))
        simulated = np.full((n, len(self.channels)), np.nan)
        settling = np.zeros(n, dtype=bool)
        first = 0
        with np.errstate(all="ignore"):  # a diverging state is checked after (diverged)
            if not self.settled:
                first = min(n, self.settling - sum(len(b) for b in self.buffer))
                self.buffer.append(rows[:first])
                settling[:first] = True
                if sum(len(b) for b in self.buffer) == self.settling:
                    self._settle(np.concatenate(self.buffer))
            if first < n and self.settled:
                simulated[first:] = self._continue(rows[first:])
            residuals = np.full_like(simulated, np.nan)
            residuals[first:] = rows[first:, self.output_columns] - simulated[first:]
        return CausalRows(simulated, residuals, settling)

    def _settle(self, rows: np.ndarray) -> None:
        for runner in self.runners:
            runner.start_state(rows)
            runner.run(rows, 0, self.t0)
        self.k = len(rows) - 1
        self.last = rows[-1]
        self.buffer = []

    def _continue(self, rows: np.ndarray) -> np.ndarray:
        chunk = np.vstack([self.last[None, :], rows])
        t0 = self.t0 + self.k * self.dt
        out = np.hstack([runner.run(chunk, self.k, t0)[1:] for runner in self.runners])
        self.k += len(rows)
        self.last = rows[-1]
        return out
