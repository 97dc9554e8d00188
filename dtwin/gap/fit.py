"""Fitting a module's twin, with or without a candidate effect, on the training part.

Specification: docs/gap.md §Which (fitting) and §Calibration from data.

Parameters are fitted by **simulation error**: the module is driven with its recorded input and
its simulated output is compared with the recorded output over the training samples
(:func:`scipy.optimize.least_squares`, trust-region reflective with bounds). Simulation error,
unlike one-step (equation-error) least squares, is not biased by noise on the recorded output
(a rig's position sensor) and scores the model on what the gap measures. The plant (M1) is
simulated in a few segments, each restarted from the recorded state (multiple shooting), so
that its process noise, which an open-loop run integrates into a slow drift, cannot dominate
the fit. Non-convex parameters (a saturation level, a delay, a quantizer step) are started
from several points; the few best starts are refined.

Calibration (:func:`calibrate_linear`) fits a module's linear twin from scratch: an ARX
least-squares estimate (paper Eq. (24)) gives the starting point, then simulation error refines
it. For the plant it also finds an input offset and an input delay in whole samples, and fits
the ARX on a decimated signal when the sample rate is high, since ARX on samples much faster
than the dynamics is ill-conditioned. When its input reacts to the position's noise (a
feedback loop, :func:`dtwin.gap.closed_loop.in_loop`), the exact plant with a causal hold is
then fitted by prediction error with a noise model
(:func:`dtwin.gap.closed_loop.loop_prediction_error_fit`; docs/gap.md §Closed loop).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from dtwin.gap.closed_loop import CAUSAL_HOLDS, in_loop, loop_prediction_error_fit
from dtwin.gap.effects import (
    MAX_DELAY_SAMPLES,
    Effect,
    Scales,
    find_lattice,
    quantizer_log_density,
    refine_lattice,
)
from dtwin.gap.models import (
    LINEAR_PARAMS,
    ModuleData,
    first_order_lag,
    plant_windows,
    simulate_module,
)
from dtwin.twin.exact import hold_matrices
from dtwin.twin.paper_modules import EULER, ZOH
from dtwin.twin.wiring import ACTUATOR, FUSION, KPI, PLANT, SENSOR, role_of

__all__ = [
    "CandidateFit",
    "train_segments",
    "training_view",
    "linear_typical",
    "fit_candidate",
    "fit_diff_step",
    "refit_delay",
    "calibrate_linear",
]

logger = logging.getLogger(__name__)

_N_REFINE = 3
_MAX_NFEV = 300
#: Step tolerance of the least-squares fit, relative, in units of each parameter's typical size:
#: a fit stops once its step is below ``FIT_XTOL·(FIT_XTOL + ‖z‖)`` (``z = θ/typical``), so
#: its parameters are known to no better (:mod:`dtwin.gap.intervals`).
FIT_XTOL = 1e-6
#: Finite-difference step of the Jacobian, relative to each parameter's typical size, of a fit
#: whose exact plant carries a candidate force (SciPy's default, ``√ε ≈ 1.5e-8``, elsewhere).
#: Such a training error is rough on small scales, though its trend is smooth: a window's
#: initial state is a local least-squares fit under the force, which moves in steps where a
#: warm-up passes through a stick or a reversal, and a friction's stick–slip changes a window's
#: error in steps where a parameter moves a simulated velocity across rest. At SciPy's step the
#: Jacobian is the slope of those steps, and the fit stops at its start (a closed-loop rig's
#: Coulomb friction, docs/gap.md §Which: a change of 1e-4 of ``Fc`` moved the training cost by
#: 16 %). A step of 1e-3 of the typical size reads the trend; its truncation error moves the
#: optimum by about half a step (the rig families' friction fits have 95 % intervals of ±0.1 %
#: to ±20 % of their value).
FORCE_DIFF_STEP = 1e-3


def fit_diff_step(data: ModuleData, effect: Effect | None) -> float | None:
    """Return the finite-difference step of a candidate's fit, relative to each typical size.

    :data:`FORCE_DIFF_STEP` for a candidate force on the exact plant (a training error rough on
    small scales), None (SciPy's default) elsewhere. SciPy steps each parameter, in units of its
    typical size ``z = θ/typical``, by ``step·max(1, |z|)``; the intervals' Jacobian
    (:mod:`dtwin.gap.intervals`) reads the same error with the same step.
    """
    rough = data.discretisation != EULER and effect is not None and effect.stage == "force"
    return FORCE_DIFF_STEP if rough else None


@dataclass(frozen=True)
class CandidateFit:
    """A module's twin fitted on the training part.

    Attributes
    ----------
    lin : dict of str to float
        Linear parameters (fitted or fixed).
    theta : tuple of float
        Effect parameters, in the order of ``effect.params`` (empty for the linear twin).
    n_free : int
        Number of fitted parameters (linear and effect).
    train_rms : float
        RMS simulation error on the training samples, output units.
    """

    lin: dict[str, float]
    theta: tuple[float, ...]
    n_free: int
    train_rms: float


#: Most training samples the plant's fit simulates (longer recordings are sampled in segments).
MAX_FIT_SAMPLES = 16000
#: Fewest windows the windowed plant's fit spreads over the training part.
MIN_FIT_WINDOWS = 4


def training_view(data: ModuleData, n_train: int) -> tuple[ModuleData, list | None]:
    """Return the module's data as the fit sees it, and its training segments.

    A windowed plant whose window is longer than ``MAX_FIT_SAMPLES / MIN_FIT_WINDOWS`` is fitted
    over ``MIN_FIT_WINDOWS`` windows of that length (their warm-up scaled with them) spread
    evenly over the training part: a single long window, the first, would see only the start
    of the experiment (a recording that begins with a low-amplitude ramp fitted the
    small-signal dynamics and lost to a plain output-error fit on the held-out part, 0.20 vs
    0.12). Everything else: ``data`` unchanged and :func:`train_segments`.
    """
    longest = MAX_FIT_SAMPLES // MIN_FIT_WINDOWS
    if data.role == PLANT and data.horizon is not None and data.horizon > longest:
        data = replace(data, horizon=longest)
    return data, train_segments(data, n_train)


def train_segments(data: ModuleData, n_train: int) -> list[tuple[int, int]] | None:
    """Return the plant's multiple-shooting segments over the training part (None elsewhere).

    Free run (no ``data.horizon``) of the Euler twin: up to four equal segments of at least 200
    samples each; on long recordings each segment keeps only its first ``MAX_FIT_SAMPLES / 4``
    samples, spread over the whole training part. Free run of an exact plant: one run over the
    first ``MAX_FIT_SAMPLES`` training samples (restarts from a velocity estimated on noisy
    samples would bias the fit). With a horizon: the windows of the gap
    (:func:`~dtwin.gap.models.plant_windows`), evenly thinned to at most ``MAX_FIT_SAMPLES``
    samples.
    """
    if data.role != PLANT:
        return None
    if data.horizon is not None:
        windows = plant_windows(n_train, data.horizon, data.restarts)
        keep = max(1, MAX_FIT_SAMPLES // max(int(data.horizon), 1))
        if len(windows) > keep:
            chosen = np.linspace(0, len(windows) - 1, keep).round().astype(int)
            windows = [windows[i] for i in sorted(set(chosen.tolist()))]
        return windows
    if data.discretisation != EULER:
        # a stable plant forgets its start: one free run, no restart from a noisy velocity
        return [(0, min(n_train, MAX_FIT_SAMPLES))]
    if data.restarts:
        return plant_windows(n_train, None, data.restarts)
    n_segments = max(1, min(4, n_train // 200))
    edges = np.linspace(0, n_train, n_segments + 1).astype(int)
    longest = MAX_FIT_SAMPLES // n_segments
    return [(int(a), int(min(b, a + longest))) for a, b in itertools.pairwise(edges)]


def linear_typical(
    name: str, lin: Mapping[str, float], scales: Scales, *, scale_free: bool = False
) -> dict[str, float]:
    """Return a typical magnitude of each linear parameter (its nominal size, or a data scale).

    ``scale_free`` (the exact plant, any units): ``m, c, k`` are typically their own size, with
    no absolute floor of 1 (a mass of 1e-6 in volt units is as ordinary as one of 1e6); a zero
    ``k`` or ``c`` is typically that of a mode of 1000 samples.
    """
    if scale_free and role_of(name) == PLANT:
        return _plant_typical(lin, scales)
    typical = {}
    for key, value in lin.items():
        if key == "bias":
            fallback = scales.output_std
        elif key == "tau":
            fallback = 10 * scales.dt
        elif key == "u_offset":
            fallback = scales.input_std
        elif key == "c":
            fallback = 0.1 * math.sqrt(max(lin.get("k", 0.0), 1e-12) * lin.get("m", 1.0))
        else:
            fallback = 1.0
        typical[key] = max(abs(float(value)), fallback, 1e-12)
    return typical


def _plant_typical(lin: Mapping[str, float], scales: Scales) -> dict[str, float]:
    mass = abs(float(lin.get("m", 0.0))) or 1.0
    rate = 2 * math.pi / (1000 * scales.dt)
    typical = {
        "m": mass,
        "k": abs(float(lin.get("k", 0.0))) or mass * rate**2,
        "c": abs(float(lin.get("c", 0.0))) or mass * rate,
    }
    for key, value in lin.items():
        if key not in typical:
            fallback = scales.input_std if key == "u_offset" else 1.0
            typical[key] = max(abs(float(value)), fallback, 1e-300)
    return typical


def _bounds_free(name: str, lin: Mapping[str, float], scales: Scales, typical) -> dict:
    bounds = {}
    for key in lin:
        if key in ("tau", "m"):
            bounds[key] = (typical[key] * 1e-3, typical[key] * 1e3)
        elif key in ("c", "k"):
            bounds[key] = (0.0, typical[key] * 1e3)
        elif key == "alpha":
            bounds[key] = (0.0, 1.0)
        elif key == "delay_samples":
            continue
        else:
            bounds[key] = (-np.inf, np.inf)
    if "tau" in bounds:
        bounds["tau"] = (max(bounds["tau"][0], scales.dt / 50), bounds["tau"][1])
    return bounds


def _residual_fn(data, effect, fixed, free_names, n_train, segments):
    target = data.output[:n_train]
    mask = np.zeros(n_train, dtype=bool)
    for start, stop in segments or [(0, n_train)]:
        mask[start + 1 : stop] = True
    n_lin = len(free_names)
    scale = max(float(np.std(data.output)), 1e-300)

    def residual(vector):
        lin = dict(fixed)
        lin.update(zip(free_names, vector[:n_lin], strict=True))
        predicted = simulate_module(
            data, lin, effect, vector[n_lin:], stop=n_train, segments=segments
        )
        error = (predicted - target)[mask] / scale
        error = np.where(np.isnan(predicted[mask]), 0.0, error)  # unscored warm-up samples
        return np.clip(np.nan_to_num(error, nan=1e6, posinf=1e6, neginf=-1e6), -1e6, 1e6)

    return residual, scale


def fit_candidate(
    data: ModuleData,
    effect: Effect | None,
    lin_start: Mapping[str, float],
    *,
    n_train: int,
    free: Sequence[str] | None = None,
    lin_bounds: Mapping[str, tuple[float, float]] | None = None,
    starts: Sequence[Sequence[float]] | None = None,
    n_refine: int = _N_REFINE,
    incumbent: CandidateFit | None = None,
) -> CandidateFit:
    """Fit a module's linear parameters and an effect's parameters on the training part.

    Parameters
    ----------
    data : ModuleData
        The module's recorded signals.
    effect : Effect or None
        The candidate; ``None`` (or ``parameter_mismatch``) fits the linear twin alone.
    lin_start : mapping
        Starting (and, for parameters not in ``free``, fixed) linear parameters.
    n_train : int
        Number of training samples (from the start).
    free : sequence of str, optional
        Linear parameters to fit; default all of :data:`LINEAR_PARAMS` for the module, plus
        ``u_offset`` when present.
    lin_bounds : mapping, optional
        Bounds of the free linear parameters; default a wide physical box.
    starts : sequence of sequence of float, optional
        The effect parameters' starting points (each with ``lin_start``); default
        ``effect.starts(scales)``.
    n_refine : int, default 3
        How many of the starts, the lowest-cost first, are refined by least squares.
    incumbent : CandidateFit, optional
        A fit of the same model already made (same ``data``, ``effect`` and ``n_train``): the
        starts are refined only if one of them trains better than it, and it is returned
        unless the new fit trains better (a start from another model's fit, which may only
        confirm the incumbent's optimum).

    Returns
    -------
    CandidateFit
    """
    scales = data.scales
    if effect is not None and effect.lattice:
        return _fit_quantization(data, effect, lin_start, n_train, free, lin_bounds)
    lin_start = dict(lin_start)
    if free is None:
        free = [k for k in (*LINEAR_PARAMS[data.name], "u_offset") if k in lin_start]
    free = list(free)
    exact = data.discretisation != EULER
    typical = linear_typical(data.name, lin_start, scales, scale_free=exact)
    bounds_all = dict(_bounds_free(data.name, lin_start, scales, typical))
    bounds_all.update(lin_bounds or {})
    effect_params = effect.n_params if effect is not None else 0
    eff_bounds = effect.bounds(scales) if effect_params else []
    eff_starts = [[]]
    if effect_params:
        eff_starts = [list(theta) for theta in starts] if starts else effect.starts(scales)
    eff_typical = effect.typical(scales) if effect_params else []
    low = np.array([bounds_all[k][0] for k in free] + [b[0] for b in eff_bounds], dtype=float)
    high = np.array([bounds_all[k][1] for k in free] + [b[1] for b in eff_bounds], dtype=float)
    x_scale = np.array([typical[k] for k in free] + [abs(v) for v in eff_typical], dtype=float)
    x_scale = np.where(x_scale > 0, x_scale, 1.0)
    data, segments = training_view(data, n_train)
    residual, scale = _residual_fn(data, effect, lin_start, free, n_train, segments)

    width = np.where(np.isfinite(high - low), high - low, 0.0)
    starts = []
    for eff0 in eff_starts:
        x0 = np.array([lin_start[k] for k in free] + list(eff0), dtype=float)
        starts.append(np.clip(x0, low + 1e-9 * width, high - 1e-9 * width))
    if not len(starts[0]):
        r = residual(starts[0])
        return CandidateFit(lin_start, (), 0, float(np.sqrt(np.mean(r**2))) * scale)
    n_used = max(1, sum(b - a - 1 for a, b in segments or [(0, n_train)]))
    to_beat = math.inf if incumbent is None else (incumbent.train_rms / scale) ** 2 * n_used
    diff_step = fit_diff_step(data, effect)
    best_x, best_cost = _refine_starts(
        residual, starts, (low, high), x_scale, n_refine, to_beat, diff_step
    )
    if best_cost >= to_beat:
        return incumbent
    lin = dict(lin_start)
    lin.update({k: float(v) for k, v in zip(free, best_x[: len(free)], strict=True)})
    theta = tuple(float(v) for v in best_x[len(free) :])
    return CandidateFit(lin, theta, len(best_x), math.sqrt(best_cost / n_used) * scale)


def _refine_starts(residual, starts, bounds, x_scale, n_refine, to_beat, diff_step=None):
    """Return ``(x, cost)``: the best of the starts and of the fits from the ``n_refine`` best.

    No fit is made when no start costs less than ``to_beat`` (an incumbent fit's cost);
    ``diff_step`` is :func:`_scaled_least_squares`'.
    """
    costs = [float(np.sum(residual(x0) ** 2)) for x0 in starts]
    best_x, best_cost = starts[int(np.argmin(costs))], min(costs)
    if best_cost >= to_beat:
        return best_x, best_cost
    for index in np.argsort(costs)[:n_refine]:
        result = _scaled_least_squares(residual, starts[index], *bounds, x_scale, diff_step)
        if result is None:
            logger.debug("fit failed from start %d", index)
            continue
        x_fit, cost = result
        if cost < best_cost:
            best_x, best_cost = x_fit, cost
    return best_x, best_cost


def _scaled_least_squares(
    residual, start, low, high, typical, diff_step: float | None = None
) -> tuple[np.ndarray, float] | None:
    """Minimise ``Σ residual(x)²`` over ``x / typical``; return ``(x, cost)`` or None on failure.

    Every parameter is fitted in units of its typical size, so that the finite-difference
    step of the Jacobian is relative to that size. SciPy's default step is absolute for
    ``|x| < 1`` (``√ε ≈ 1.5e-8``): a cubic stiffness of typical size 1e10 (a rig recorded in
    micrometres) started at 0 would see a zero Jacobian column and never move. ``diff_step``
    (SciPy's, relative to ``max(1, |x/typical|)``; None: its default) is
    :data:`FORCE_DIFF_STEP` for a training error that is rough on small scales.
    """

    def scaled(z: np.ndarray) -> np.ndarray:
        return residual(z * typical)

    try:
        result = least_squares(
            scaled,
            start / typical,
            bounds=(low / typical, high / typical),
            method="trf",
            max_nfev=_MAX_NFEV,
            ftol=1e-6,
            xtol=FIT_XTOL,
            gtol=1e-8,
            diff_step=diff_step,
        )
    except (ValueError, FloatingPointError):  # pragma: no cover - defensive
        return None
    return result.x * typical, float(np.sum(result.fun**2))


def _fit_quantization(data, effect, lin_start, n_train, free, lin_bounds) -> CandidateFit:
    """Quantizer: its step from the lattice the recorded values sit on, then the linear twin.

    A quantizer after noise barely changes the *mean* output, so its step is not identifiable
    by least squares; the lattice of the recorded values identifies it directly
    (:func:`~dtwin.gap.effects.find_lattice`). The lattice's blur gives the noise after the
    quantizer; the rest of the module's noise is put before it.
    """
    scales = data.scales
    y = data.output[:n_train]
    low = max(1e-9 * scales.output_std, 0.25 * scales.noise_std, 1e-3 * scales.output_std)
    q, offset, conc = find_lattice(y, low, 2.0 * scales.output_std)
    after = q * math.sqrt(max(-math.log(max(conc, 1e-12)), 0.0) / (2 * math.pi**2))
    if after < 0.1 * q:  # values on a lattice: its step, offset and blur by least squares
        q, offset, after = refine_lattice(y, q, offset)
    fitted = fit_candidate(data, None, lin_start, n_train=n_train, free=free, lin_bounds=lin_bounds)
    lin = fitted.lin
    clean = simulate_module(data, lin, stop=n_train)[:n_train]
    before = _noise_before_quantizer(y, clean, q, offset, after, scales.noise_std)
    theta = (q, offset, before)
    residual, scale = _residual_fn(data, effect, lin, [], n_train, None)
    rms = float(np.sqrt(np.mean(residual(np.array(theta)) ** 2))) * scale
    return CandidateFit(lin, theta, fitted.n_free + 2, rms)


def _noise_before_quantizer(y, clean, step, offset, after, noise_std) -> float:
    """Return the noise before a quantizer: its maximum-likelihood value on the training part.

    ``quantizer_log_density`` (:mod:`dtwin.gap.effects`) summed over the training samples,
    maximised over ``σ_b`` in ``[q/1000, 2·max(noise_std, q)]`` (log scale, bounded Brent). The
    module's noise level less the lattice's blur, the former start, is only as good as that
    level: without a twin noise level the data floor of a coarse staircase (most differences
    zero) read 0.008 for a true 0.02 and the quantizer lost to `unexplained`.
    """
    from scipy.optimize import minimize_scalar

    after = max(after, step / 100.0)

    def negative_log_likelihood(log_sigma: float) -> float:
        sigma = math.exp(log_sigma)
        return -float(np.sum(quantizer_log_density(y, clean, step, offset, sigma, after)))

    low = math.log(step / 1000.0)
    high = math.log(2.0 * max(noise_std, step))
    found = minimize_scalar(
        negative_log_likelihood, bounds=(low, high), method="bounded", options={"xatol": 0.01}
    )
    return float(math.exp(found.x))


# --- calibration from data --------------------------------------------------------------


def _lag_coefficient_to_tau(a: float, dt: float) -> float:
    a = min(max(a, 1e-6), 1 - 1e-9)
    return -dt / math.log(a)


def _arx_first_order(y: np.ndarray, u: np.ndarray) -> tuple[float, float, float]:
    phi = np.column_stack([y[:-1], u[:-1], np.ones(len(y) - 1)])
    coef, *_ = np.linalg.lstsq(phi, y[1:], rcond=None)
    return float(coef[0]), float(coef[1]), float(coef[2])


def _exact_plant_from_arx(x, u, dt, factor, hold):
    """``m, c, k, u_offset`` of the exact plant from a second-order ARX on decimated samples.

    The ARX poles are mapped to continuous ones (``s = ln(z)/step``), which give ``c/m`` and
    ``k/m``; ``m`` matches the static gain of the numerator (its coefficient sum), which is
    finite for an integrating plant too. The first-order and band-limited holds add the
    same-sample input (a band-limited input also reaches ``x[k]`` through later samples, which
    the output-error refinement then accounts for).
    """
    xs, us = x[::factor], u[::factor]
    step = dt * factor
    n = len(xs)
    if n < 20:
        return None
    rows = np.arange(2, n)
    same_sample = hold != ZOH  # the first-order and band-limited holds let u[k] act on x[k]
    lags = [us[rows], us[rows - 1], us[rows - 2]] if same_sample else [us[rows - 1], us[rows - 2]]
    phi = np.column_stack([xs[rows - 1], xs[rows - 2], *lags, np.ones(len(rows))])
    coef, *_ = np.linalg.lstsq(phi, xs[rows], rcond=None)
    poles = np.roots([1.0, -coef[0], -coef[1]]).astype(complex)
    if np.any((np.abs(poles.imag) < 1e-12) & (poles.real <= 0)) or np.any(np.abs(poles) == 0):
        return None
    continuous = np.log(poles) / step
    c_per_m = max(float(-continuous.sum().real), 0.0)
    k_per_m = max(float((continuous[0] * continuous[1]).real), 0.0)
    gain_arx = float(np.sum(coef[2:-1]))
    # the static gain is the same for every hold (its taps sum to the zero-order hold's)
    a, taps, _ = hold_matrices(c_per_m, k_per_m, step, ZOH)
    gain_unit = float(taps[0, 0] * (1.0 - a[1, 1]) + a[0, 1] * taps[0, 1])
    if not gain_arx > 0 or not gain_unit > 0:
        return None
    m = gain_unit / gain_arx
    offset = -float(coef[-1]) / gain_arx
    return {"m": m, "c": c_per_m * m, "k": k_per_m * m, "u_offset": offset, "delay_samples": 0}


def _plant_from_arx(x, u, dt, factor, hold=EULER, delay=0):
    xs, us = x[::factor], u[::factor]
    step = dt * factor
    d = delay // factor
    n = len(xs)
    if n < 20 + d:
        return None
    rows = np.arange(2 + d, n)
    phi = np.column_stack([xs[rows - 1], xs[rows - 2], us[rows - 2 - d], np.ones(len(rows))])
    coef, *_ = np.linalg.lstsq(phi, xs[rows], rcond=None)
    a1, a2, beta, gamma = (float(v) for v in coef)
    if beta <= 0:
        return None
    m = step * step / beta
    c = (2 - a1) * m / step
    k = (-a2 - 1 + c * step / m) * m / (step * step)
    if not (m > 0 and c >= 0 and k >= 0):
        c, k = max(c, 0.0), max(k, 0.0)
    # the force units of a decimated fit equal the original ones; only dt changed
    return {"m": m, "c": c, "k": k, "u_offset": -gamma / beta, "delay_samples": delay}


def _exact_arx_by_delay(x, u, dt, hold, cost) -> dict[int, tuple[float, dict]]:
    """Return the best ARX start of the exact plant per whole-sample delay (over decimations).

    Each candidate is scored by ``cost`` (training simulation error); the values are
    ``(cost, start)``.
    """
    by_delay = {}
    for delay in range(0, MAX_DELAY_SAMPLES + 1):
        shifted = np.concatenate([np.full(delay, u[0]), u[: len(u) - delay]])
        factor, scored = 1, []
        while len(x) // factor >= 100:
            lin = _exact_plant_from_arx(x, shifted, dt, factor, hold)
            if lin is not None:
                lin["delay_samples"] = delay
                scored.append((cost(lin), factor, lin))
            factor *= 2
        if scored:
            best_cost, _, best = min(scored, key=lambda item: item[0])
            by_delay[delay] = (best_cost, best)
    return by_delay


#: Delays (samples) at which the output-error fit is tried first; the best one's neighbours next.
DELAY_GRID = (0, 1, 2, 4, 6, 9, 13, 18, 25)


def _fit_delay(
    data: ModuleData, starts: dict[int, tuple[float, dict]], n_train: int, near: int | None = None
) -> dict[str, float]:
    """Output-error fits over a grid of delays, then around the best one; the best fit wins.

    ARX estimates of a delay are biased by output noise; the training simulation error of the
    refined fits is not. With ``near`` (a delay already found with another hold) its
    neighbours are tried, and the delay of this hold's best ARX start: a hold that does not
    fit the recording (a zero-order hold on a continuous input at 3 samples per period) finds
    a wrong delay (18 samples for a true 0), which the right hold must not inherit.
    """
    fits = {}

    def fit_at(delay: int) -> None:
        if delay in starts and delay not in fits:
            fits[delay] = fit_candidate(data, None, starts[delay][1], n_train=n_train)

    best_start = min(starts, key=lambda d: starts[d][0])
    for delay in DELAY_GRID if near is None else (near, best_start):
        fit_at(delay)
    if not fits:  # no ARX start at the tried delays: the one nearest to them
        fit_at(min(starts, key=lambda d: abs(d - (near or 0))))
    best = min(fits, key=lambda d: fits[d].train_rms)
    for delay in range(best - 2, best + 3):
        fit_at(delay)
    best = min(fits, key=lambda d: fits[d].train_rms)
    return fits[best].lin


def _training_cost(data: ModuleData, n_train: int, effect: Effect | None = None, theta=()):
    """Return ``(view, cost)``: the fit's view of the plant and ``cost(lin)``, its training MSE.

    ``cost`` simulates the plant (with ``effect`` at ``theta``) over the training segments of
    :func:`training_view` and averages the squared error over their scored samples.
    """
    x = data.output[:n_train]
    data, segments = training_view(data, n_train)
    mask = np.zeros(n_train, dtype=bool)
    for start, stop in segments:
        mask[start + 1 : stop] = True

    def cost(lin):
        sim = simulate_module(data, lin, effect, theta, stop=n_train, segments=segments)
        error = (sim - x)[mask]
        error = error[~np.isnan(error)]  # unscored warm-up samples
        return float(np.mean(error**2)) if len(error) and np.all(np.isfinite(error)) else np.inf

    return data, cost


def refit_delay(
    data: ModuleData, effect: Effect, fitted: CandidateFit, n_train: int
) -> CandidateFit:
    """Return a calibrated plant's candidate re-fitted at the input delay that suits it best.

    Parameters
    ----------
    data : ModuleData
        The plant's recorded signals.
    effect : Effect
        The candidate.
    fitted : CandidateFit
        The candidate fitted at the linear twin's delay (``lin["delay_samples"]``).
    n_train : int
        Number of training samples.

    Returns
    -------
    CandidateFit
        The best by training error of ``fitted``, the candidate fitted again at the
        whole-sample delay (0 to ``MAX_DELAY_SAMPLES``) where ``fitted``'s parameters leave the
        smallest training error, and the candidate fitted again (from ``fitted``'s parameters)
        at each delay of :data:`DELAY_GRID` shorter than its own.

    Notes
    -----
    docs/gap.md §Which. The calibrated twin's delay is chosen by a linear output-error fit,
    which reads an unmodelled effect partly as a lag: a rig's Coulomb friction at 980 samples
    per period gave 13 samples for a true 0, and Coulomb friction fitted at 13 left a choosing
    gap of 0.036 where it leaves 0.010 at 0. Every candidate fits the delay with its effect.
    The scan at fixed parameters does not always see it: the linear parameters fitted with
    the lag absorb it (a Stribeck rig at 622 samples per period calibrated at 9 samples for a
    true 0 kept 9, training error 8.6e-4; fitted again at 1 sample, 6.5e-4 with Coulomb
    friction and 5.0e-4 with Stribeck friction), so the shorter delays are fitted again.
    """
    if "delay_samples" not in fitted.lin:
        return fitted
    _, cost = _training_cost(data, n_train, effect, fitted.theta)
    costs = {d: cost(dict(fitted.lin, delay_samples=d)) for d in range(MAX_DELAY_SAMPLES + 1)}
    own = int(fitted.lin["delay_samples"])
    best_fit = fitted
    best = min(costs, key=lambda d: costs[d])
    if best != own:
        again = fit_candidate(data, effect, dict(fitted.lin, delay_samples=best), n_train=n_train)
        best_fit = again if again.train_rms < best_fit.train_rms else best_fit
    for delay in (d for d in DELAY_GRID if d < own and d != best):
        shorter = fit_candidate(
            data,
            effect,
            dict(fitted.lin, delay_samples=delay),
            n_train=n_train,
            starts=[fitted.theta],
        )
        best_fit = shorter if shorter.train_rms < best_fit.train_rms else best_fit
    return best_fit


def _calibrate_plant(data: ModuleData, n_train: int, near: int | None) -> dict[str, float]:
    x, u = data.output[:n_train], data.inputs["u_act"][:n_train]
    data, cost = _training_cost(data, n_train)
    if data.discretisation != EULER:
        starts = _exact_arx_by_delay(x, u, data.dt, data.discretisation, cost)
        if starts:
            lin = _fit_delay(data, starts, n_train, near)
            if data.discretisation in CAUSAL_HOLDS and in_loop(u, x):
                # docs/gap.md §Closed loop: the output-error fit is biased by noise fed back
                arx = [starts[d][1] for d in (0, 1) if d in starts]
                horizon = data.horizon or n_train
                lin, _ = loop_prediction_error_fit(
                    x, u, data.dt, data.discretisation, [lin, *arx], horizon
                )
                # the offset by output error, the dynamics fixed: its regressor (the plant's
                # response to a constant) holds no fed-back noise, and a noise model with a
                # root near 1 leaves it unidentified in the prediction-error cost
                lin = fit_candidate(data, None, lin, n_train=n_train, free=["u_offset"]).lin
            return lin
    candidates = []
    factor = 1
    while n_train // factor >= 100:
        lin = _plant_from_arx(x, u, data.dt, factor)
        if lin is not None:
            candidates.append((cost(lin), lin))
        factor *= 2
    if not candidates:
        guess = {"m": 1.0, "c": 1.0, "k": 1.0, "u_offset": 0.0, "delay_samples": 0}
        candidates.append((cost(guess), guess))
    _, best = min(candidates, key=lambda item: item[0])
    delays = []
    for delay in range(0, MAX_DELAY_SAMPLES + 1):
        trial = dict(best, delay_samples=delay)
        delays.append((cost(trial), delay))
    best["delay_samples"] = min(delays)[1]
    fitted = fit_candidate(data, None, best, n_train=n_train)
    return fitted.lin


def calibrate_linear(
    data: ModuleData, n_train: int, delay_near: int | None = None
) -> dict[str, float]:
    """Return a module's linear twin parameters fitted from the training part alone.

    Parameters
    ----------
    data : ModuleData
        The module's recorded signals (recording units).
    n_train : int
        Number of training samples.
    delay_near : int, optional
        The exact plant: search the input delay next to this one only.

    Returns
    -------
    dict of str to float
        :data:`LINEAR_PARAMS` of the module; the plant adds ``u_offset`` (input units) and
        ``delay_samples`` (extra whole-sample input delay).
    """
    return _CALIBRATORS[data.role](data, n_train, delay_near)


def _calibrate_actuator(data: ModuleData, n_train: int, near: int | None) -> dict[str, float]:
    """Return the lag's ``tau``: first-order ARX, refined by simulation error."""
    y = data.output[:n_train]
    a, _, _ = _arx_first_order(y, data.inputs["u_cmd"][:n_train])
    start = {"tau": _lag_coefficient_to_tau(a, data.dt)}
    return fit_candidate(data, None, start, n_train=n_train).lin


def _calibrate_sensor(data: ModuleData, n_train: int, near: int | None) -> dict[str, float]:
    """Return the lag's ``tau`` (first-order ARX) and offset ``bias``, refined together."""
    y = data.output[:n_train]
    x = data.inputs["x"][:n_train]
    a, _, _ = _arx_first_order(y, x)
    tau = _lag_coefficient_to_tau(a, data.dt)
    bias = float(np.mean(y - first_order_lag(x, tau, data.dt, x[0])))
    start = {"tau": tau, "bias": bias}
    return fit_candidate(data, None, start, n_train=n_train).lin


def _calibrate_fusion(data: ModuleData, n_train: int, near: int | None) -> dict[str, float]:
    """Return the weight ``alpha`` by least squares, clipped to [0, 1]."""
    y = data.output[:n_train]
    y_a, y_b = data.inputs["y_A"][:n_train], data.inputs["y_B"][:n_train]
    diff = y_a - y_b
    alpha = float(np.dot(diff, y - y_b) / max(np.dot(diff, diff), 1e-300))
    return {"alpha": min(max(alpha, 0.0), 1.0)}


def _calibrate_kpi(data: ModuleData, n_train: int, near: int | None) -> dict[str, float]:
    """Return the weights ``w1, w2`` by least squares on position and velocity."""
    y = data.output[:n_train]
    phi = np.column_stack([data.inputs["x"][:n_train], data.velocity[:n_train]])
    coef, *_ = np.linalg.lstsq(phi, y, rcond=None)
    return {"w1": float(coef[0]), "w2": float(coef[1])}


#: Each role's calibration ``(data, n_train, delay_near) → linear parameters``.
_CALIBRATORS = {
    ACTUATOR: _calibrate_actuator,
    PLANT: _calibrate_plant,
    SENSOR: _calibrate_sensor,
    FUSION: _calibrate_fusion,
    KPI: _calibrate_kpi,
}
