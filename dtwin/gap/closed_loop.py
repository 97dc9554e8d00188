"""Whether a plant's recorded input is computed from its measured output (a feedback loop).

Specification: docs/gap.md §Closed loop.

A position loop whose output is the recorded force feeds the position's measurement noise
into the input. A fit that lets the input at sample ``k`` (or later) act on the position at
``k`` can then explain that noise through the loop, and its parameters drift towards the
controller's inverse: the direct prediction-error method is consistent under feedback only if
the loop holds a delay, here the plant's (Ljung, *System Identification*, 2nd ed., §13.4).
The first-order and band-limited holds let ``u[k]`` (and, band-limited, later samples) act on
``x[k]``; the zero-order hold and the Euler plant do not. :func:`feedback_statistic` tells a
loop from an open-loop input by the direction in which the two signals' noise bands are
related: the input's band reacts to the output's noise at the same and earlier samples in a
loop, while in open loop the output's band follows the input (later samples) or neither.

A causal plant is not enough when the noise is coloured: the noise the loop fed into the input
a few samples ago is still in the position, so an output-error fit explains part of it through
the plant and drifts. :func:`loop_prediction_error_fit` is the prediction-error method with a
noise model (Box–Jenkins: the plant's output error whitened by a monic FIR filter fitted with
it), consistent under feedback when the loop holds a delay (Ljung §13.4).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter, savgol_filter

from dtwin.exact_plant import exact_plant_response, free_response_basis, hold_matrices
from dtwin.gap.effects import MAX_DELAY_SAMPLES, fractional_delay
from dtwin.modules import EULER, ZOH
from dtwin.wiring import PLANT, only_module

__all__ = [
    "CAUSAL_HOLDS",
    "FEEDBACK_THRESHOLD",
    "FEEDBACK_LAGS",
    "feedback_statistic",
    "loop_statistic",
    "causal_holds",
    "in_loop",
    "LOOP_WINDOW",
    "NOISE_ORDER",
    "loop_whitened_error",
    "loop_prediction_error_fit",
]

#: The plant discretisations in which ``u[k]`` does not act on ``x[k]`` (the loop's delay).
CAUSAL_HOLDS = (EULER, ZOH)

#: Lags (samples) of each side of :func:`feedback_statistic`.
FEEDBACK_LAGS = 2
#: Smallest statistic read as a feedback loop (docs/gap.md §Closed loop: open-loop rigs and
#: the paper asset ≤ 0.094, PD-loop rigs flagged ≥ 0.21).
FEEDBACK_THRESHOLD = 0.15


def _share_explained(target: np.ndarray, regressors: np.ndarray) -> float:
    """Return the share of ``target``'s energy a least-squares fit on ``regressors`` explains."""
    energy = float(target @ target)
    if not energy > 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(regressors, target, rcond=None)
    error = target - regressors @ coef
    return 1.0 - float(error @ error) / energy


def feedback_statistic(u: np.ndarray, x: np.ndarray, window: int) -> float:
    """Return how much more the input's noise band follows the output's than it leads it.

    Parameters
    ----------
    u, x : numpy.ndarray, shape (n_samples,)
        Recorded input and output (the training part), any units.
    window : int
        Samples of the cubic Savitzky-Golay smoother whose residual is the output's noise (the
        position smoothing window of :func:`dtwin.gap.models.plant_state_from_position`).

    Returns
    -------
    float
        ``R²_past − R²_future``: the share of the input's band (its residual after the same
        smoother) that a least-squares fit on the output's band at lags ``0 … FEEDBACK_LAGS``
        explains, less the share the output's band at lags ``−1 … −(FEEDBACK_LAGS + 1)`` (later
        samples) explains. Near 0 or negative in open loop; large when a controller computes the
        input from the noisy output. 0 for records too short to tell.
    """
    window = int(window) | 1
    lags = FEEDBACK_LAGS
    n = len(u)
    rows = np.arange(window + lags + 1, n - window - lags - 1)
    if len(rows) < 50 * (lags + 2) or n < window:
        return 0.0
    band_u = u - savgol_filter(u, window, 3)
    band_x = x - savgol_filter(x, window, 3)
    past = np.column_stack([band_x[rows - j] for j in range(lags + 1)])
    future = np.column_stack([band_x[rows + j] for j in range(1, lags + 2)])
    target = band_u[rows]
    return _share_explained(target, past) - _share_explained(target, future)


def loop_statistic(u: np.ndarray, x: np.ndarray) -> float:
    """Return :func:`feedback_statistic` with the position's own smoothing window.

    The window is the widest whose residual is still only the position's noise
    (``dtwin.gap.models._smoothing_window``), so the band holds noise, not dynamics.
    """
    from dtwin.gap.models import _smoothing_window

    return feedback_statistic(u, x, _smoothing_window(x))


def causal_holds(
    signals: Mapping[str, np.ndarray], names: Sequence[str], holds: tuple[str, ...], n_train: int
) -> tuple[tuple[str, ...], list[str]]:
    """Return the plant's holds to try and a note: only causal ones inside a feedback loop.

    Parameters
    ----------
    signals : mapping of str to numpy.ndarray
        The recording's signals, each shape ``(n_samples,)``.
    names : sequence of str
        The diagnosed modules.
    holds : tuple of str
        The plant discretisations the twin file allows (one: declared, kept as declared).
    n_train : int
        Training samples (the statistic reads them only).

    Returns
    -------
    tuple
        ``(holds, notes)``: when M1 is diagnosed, more than one hold is allowed and the plant's
        input reacts to its output's noise (:func:`loop_statistic` at least
        :data:`FEEDBACK_THRESHOLD`), the holds of :data:`CAUSAL_HOLDS` among ``holds`` and one
        note giving the statistic; otherwise ``holds`` unchanged and no note.
    """
    plant = only_module(PLANT)
    if plant not in names or len(holds) == 1:
        return holds, []
    statistic = loop_statistic(signals["u_act"][:n_train], signals["x"][:n_train])
    if statistic < FEEDBACK_THRESHOLD:
        return holds, []
    causal = tuple(h for h in holds if h in CAUSAL_HOLDS)
    note = (
        f"{plant} runs in a feedback loop: its input reacts to the position's noise (statistic "
        f"{statistic:.2f} >= {FEEDBACK_THRESHOLD}); only causal plants ({', '.join(causal)}) "
        "were tried (docs/gap.md, Closed loop)"
    )
    return causal, [note]


def in_loop(u: np.ndarray, x: np.ndarray) -> bool:
    """Return whether a plant's input reacts to its position's noise (a feedback loop).

    ``u``, ``x`` shape ``(n_samples,)``: the training part. :func:`loop_statistic` at least
    :data:`FEEDBACK_THRESHOLD`, the rule :func:`causal_holds` applies.
    """
    return loop_statistic(u, x) >= FEEDBACK_THRESHOLD


#: Shortest window (samples) of :func:`loop_prediction_error_fit`: each window's initial state
#: is two nuisance parameters fitted with the plant, so longer windows bias the plant less.
LOOP_WINDOW = 1000
#: Order of the noise model's whitening filter ``1 + l₁·q⁻¹ + … + l_p·q⁻ᵖ`` (an AR(p) noise).
NOISE_ORDER = 2
#: A longer input delay must lower the prediction-error cost by more than this share.
DELAY_GAIN = 0.01
_PLANT_KEYS = ("m", "c", "k", "u_offset")


def loop_whitened_error(
    x: np.ndarray,
    u: np.ndarray,
    lin: Mapping[str, float],
    noise: Sequence[float],
    dt: float,
    hold: str,
    window: int,
) -> np.ndarray:
    """Return the plant's whitened output error over back-to-back windows, shape ``(n_w, L)``.

    Parameters
    ----------
    x, u : numpy.ndarray, shape (n_samples,)
        Recorded position and input (the training part), recording units.
    lin : mapping
        ``m, c, k, u_offset, delay_samples`` of the exact plant (docs/gap.md §Modules).
    noise : sequence of float
        ``l₁ … l_p``: the whitening filter ``L(q) = 1 + Σ l_i·q⁻ⁱ``, the inverse of the noise
        model ``H = 1/L`` (AR(p) measurement noise).
    dt : float
        Sample period, s.
    hold : str
        The exact plant's hold (a causal one in a loop: ``zoh``).
    window : int
        Window length ``L``, samples; ``n_w = n_samples // L`` windows tile the record.

    Returns
    -------
    numpy.ndarray, shape (n_w, L − p)
        ``ε = L(q)·(x − G·u)`` in each window, ``G·u`` the plant's response from rest, with the
        window's free response (its initial position and velocity) fitted to minimise
        ``Σε²`` (variable projection: ``ε`` is orthogonal to the whitened free-response
        basis). The first ``p`` samples of a window, which the filter reaches before it,
        are dropped. Box–Jenkins prediction errors of an output-error plant with noise
        ``H = 1/L`` (Ljung §4.2, the predictor ``ŷ = (1 − L)·y + L·G·u``).
    """
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    order = len(noise)
    drive = fractional_delay(np.asarray(u, dtype=float), float(lin.get("delay_samples", 0)))
    drive = drive - float(lin.get("u_offset", 0.0))
    n_w = len(x) // window
    stop = n_w * window
    zeros = np.zeros(stop)
    forced = exact_plant_response(
        drive[:stop],
        m,
        c,
        k,
        dt,
        windows=[(i * window, (i + 1) * window) for i in range(n_w)],
        x_start=zeros,
        v_start=zeros,
        hold=hold,
    )
    whiten = np.concatenate([[1.0], np.asarray(noise, dtype=float)])
    error = lfilter(whiten, [1.0], (x[:stop] - forced).reshape(n_w, window), axis=1)[:, order:]
    basis = free_response_basis(hold_matrices(c / m, k / m, dt, hold), window)
    basis = lfilter(whiten, [1.0], basis, axis=0)[order:]
    q, _ = np.linalg.qr(basis)
    return error - (error @ q) @ q.T


def _loop_typical(start: Mapping[str, float], u: np.ndarray, dt: float) -> np.ndarray:
    """Typical sizes of ``m, c, k, u_offset`` and the noise filter (a zero c or k: a slow mode)."""
    mass = abs(float(start["m"])) or 1.0
    rate = 2 * math.pi / (1000 * dt)
    return np.array(
        [
            mass,
            abs(float(start["c"])) or mass * rate,
            abs(float(start["k"])) or mass * rate**2,
            max(float(np.std(u)), 1e-300),
            *([1.0] * NOISE_ORDER),
        ]
    )


def _fit_at_delay(x, u, dt, hold, window, start, noise, delay, *, fit_noise=True):
    """Prediction-error fit of ``m, c, k, u_offset`` (and the noise filter) at one delay.

    ``fit_noise`` False keeps the filter ``noise`` fixed. Returns ``(cost, lin, noise)``:
    ``cost`` the mean squared whitened error over ``var(x)``.
    """
    n_noise = NOISE_ORDER if fit_noise else 0
    typical = _loop_typical(start, u, dt)[: 4 + n_noise]
    x0 = np.array([float(start[key]) for key in _PLANT_KEYS] + list(noise)[:n_noise]) / typical
    low = np.array([1e-3 * typical[0], 0.0, 0.0, -np.inf, *([-2.0] * n_noise)]) / typical
    high = np.array([1e3 * typical[0], 1e3 * typical[1], 1e3 * typical[2], np.inf])
    high = np.concatenate([high, [2.0] * n_noise]) / typical
    x0 = np.clip(x0, low, high)
    scale = max(float(np.std(x)), 1e-300)

    def residual(z: np.ndarray) -> np.ndarray:
        theta = z * typical
        lin = dict(zip(_PLANT_KEYS, theta[:4], strict=True), delay_samples=delay)
        whiten = theta[4:] if fit_noise else noise
        with np.errstate(all="ignore"):
            error = loop_whitened_error(x, u, lin, whiten, dt, hold, window).ravel() / scale
        return np.clip(np.nan_to_num(error, nan=1e6, posinf=1e6, neginf=-1e6), -1e6, 1e6)

    found = least_squares(
        residual, x0, bounds=(low, high), method="trf", max_nfev=200, xtol=1e-8, ftol=1e-8
    )
    theta = found.x * typical
    lin = dict(zip(_PLANT_KEYS, (float(v) for v in theta[:4]), strict=True))
    lin["delay_samples"] = delay
    fitted = tuple(float(v) for v in theta[4:]) if fit_noise else tuple(noise)
    return float(np.mean(found.fun**2)), lin, fitted


def _fit_from(x, u, dt, hold, window, start):
    """Fit the plant with white noise first, then plant and noise filter together (delay 0).

    Fitted together from the start, a plant far off (a spring of 0.3·m·ω² for a true 0) let
    the filter take a root at 1 (a difference: ``1 − 1.21·q⁻¹ + 0.21·q⁻²``) that absorbed the
    drift, and the mass stopped at 3 % of the truth.
    """
    white = (0.0,) * NOISE_ORDER
    _, plant, _ = _fit_at_delay(x, u, dt, hold, window, start, white, 0, fit_noise=False)
    return _fit_at_delay(x, u, dt, hold, window, plant, white, 0)


def loop_prediction_error_fit(
    x: np.ndarray,
    u: np.ndarray,
    dt: float,
    hold: str,
    starts: Sequence[Mapping[str, float]],
    horizon: int,
) -> tuple[dict[str, float], tuple[float, ...]]:
    """Return the exact plant fitted by prediction error with a noise model, and the model.

    Parameters
    ----------
    x, u : numpy.ndarray, shape (n_samples,)
        Recorded position and input of the training part (recording units), the input computed
        by a feedback loop from the measured position.
    dt : float
        Sample period, s.
    hold : str
        The exact plant's hold (causal: ``zoh``).
    starts : sequence of mapping
        ``m, c, k, u_offset`` to start from (their delays are not used): the output-error fit
        and ARX estimates. Each is fitted at delay 0 and the best is kept; the output-error
        fit alone can start in the wrong basin (a PD loop with white noise fed back: a mass
        17,800 times the truth, from which the fit stalled at a bound).
    horizon : int
        The diagnoser's window for the plant (samples); the fit's windows are at least
        :data:`LOOP_WINDOW` long and at most the record.

    Returns
    -------
    tuple
        ``(lin, noise)``: ``m, c, k, u_offset, delay_samples`` minimising the whitened
        output error of :func:`loop_whitened_error` (``m, c, k`` in the recording's units, the
        delay in whole samples) and the whitening filter ``l₁ … l_p``.

    Notes
    -----
    docs/gap.md §Closed loop. The fit starts at delay 0 (a digital loop's own delay is the zero-
    order hold's) and tries the longer delays of the output-error grid in turn while each
    lowers the cost by more than :data:`DELAY_GAIN`: at hundreds of samples per period a delay
    of a sample or two trades against the mass and barely moves the cost (0.4 % at 137 samples
    per period for a true 0), and a delay the output-error fit read from the fed-back noise
    (25 samples for a true 0) must not survive.
    """
    window = int(min(max(int(horizon), LOOP_WINDOW), len(x)))
    fits = [_fit_from(x, u, dt, hold, window, start) for start in starts]
    best = min(fits, key=lambda fit: fit[0])
    for delay in (1, 2, 4, 6, 9, 13, 18, MAX_DELAY_SAMPLES):
        trial = _fit_at_delay(x, u, dt, hold, window, best[1], best[2], delay)
        if not trial[0] < best[0] * (1.0 - DELAY_GAIN):
            break
        best = trial
    return best[1], best[2]
