"""Whether a plant's recorded input is computed from its measured output (a feedback loop).

Specification: docs/gap.md §Closed loop.

A position loop whose output is the recorded force feeds the position's measurement noise
into the input. A fit that lets the input at sample ``k`` (or later) act on the position at
``k`` can then explain that noise through the loop, and its parameters drift towards the
controller's inverse: the direct prediction-error method is consistent under feedback only if
the loop holds a delay, here the plant's (Ljung, *System Identification*, 2nd ed., §13.4).
The first-order and band-limited holds let ``u[k]`` (and, band-limited, later samples) act on
``x[k]``; the zero-order hold and the Euler plant do not. :func:`feedback_test` tells a loop
from an open-loop input by whether the position at and before sample ``k`` explains ``u[k]``
beyond what the input's own neighbours on both sides explain (a Granger-type test with a
χ² null distribution and a stated size, :data:`FEEDBACK_SIZE`): in open loop the position
holds nothing of ``u[k]`` that its neighbours do not, however few samples per period.

A causal plant is not enough when the noise is coloured: the noise the loop fed into the input
a few samples ago is still in the position, so an output-error fit explains part of it through
the plant and drifts. :func:`loop_prediction_error_fit` is the prediction-error method with a
noise model (Box–Jenkins: the plant's output error whitened by a monic FIR filter fitted with
it), consistent under feedback when the loop holds a delay (Ljung §13.4).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter
from scipy.stats import chi2

from dtwin.gap.effects import MAX_DELAY_SAMPLES, fractional_delay
from dtwin.twin.exact import exact_plant_response, free_response_basis, hold_matrices
from dtwin.twin.paper_modules import EULER, ZOH
from dtwin.twin.wiring import PLANT, only_module

__all__ = [
    "CAUSAL_HOLDS",
    "FEEDBACK_LAGS",
    "FEEDBACK_NEIGHBOURS",
    "FEEDBACK_SIZE",
    "FEEDBACK_THRESHOLD",
    "FEEDBACK_MIN_SHARE",
    "FeedbackTest",
    "feedback_test",
    "causal_holds",
    "in_loop",
    "LOOP_WINDOW",
    "NOISE_ORDER",
    "loop_whitened_error",
    "loop_prediction_error_fit",
]

#: The plant discretisations in which ``u[k]`` does not act on ``x[k]`` (the loop's delay).
CAUSAL_HOLDS = (EULER, ZOH)

#: Lags of the position in :func:`feedback_test`: ``x[k], x[k−1], …, x[k−FEEDBACK_LAGS]``.
FEEDBACK_LAGS = 2
#: Input samples on each side of ``u[k]`` that :func:`feedback_test` interpolates it from.
FEEDBACK_NEIGHBOURS = 20
#: Size of the feedback test: the chance that an open-loop recording is read as a loop.
FEEDBACK_SIZE = 1e-4
#: Smallest statistic read as a feedback loop: the χ² quantile of :data:`FEEDBACK_SIZE` with
#: ``FEEDBACK_LAGS + 1`` degrees of freedom (21.1; docs/gap.md §Closed loop).
FEEDBACK_THRESHOLD = float(chi2.isf(FEEDBACK_SIZE, FEEDBACK_LAGS + 1))
#: Smallest share of the input's variance that the fed-back noise must hold for a loop to be
#: treated as one (docs/gap.md §Closed loop: set between the EMPS axis, 7e-8, fitted well in
#: open loop, and the weakest loop the rig families read, 3e-4; not derived from a bias bound).
FEEDBACK_MIN_SHARE = 1e-5
#: At most this many regression rows (evenly thinned): the test's power needs a few thousand.
FEEDBACK_MAX_ROWS = 50_000


class FeedbackTest(NamedTuple):
    """The feedback test of a plant's input and position (:func:`feedback_test`)."""

    #: Wald statistic of the position's coefficients, χ² with ``FEEDBACK_LAGS + 1`` degrees of
    #: freedom in open loop.
    statistic: float
    #: Share of the input's variance that the position's coefficients explain.
    share: float

    @property
    def loop(self) -> bool:
        """Whether the input is read as computed from the measured position."""
        return self.statistic >= FEEDBACK_THRESHOLD and self.share >= FEEDBACK_MIN_SHARE


def feedback_test(u: np.ndarray, x: np.ndarray) -> FeedbackTest:
    """Test whether the input reacts to the position's noise (a Granger-type test).

    Parameters
    ----------
    u, x : numpy.ndarray, shape (n_samples,)
        Recorded input and position (the training part), any units.

    Returns
    -------
    FeedbackTest
        ``u[k]`` is regressed by least squares on a constant, its :data:`FEEDBACK_NEIGHBOURS`
        neighbours on each side and the position ``x[k], …, x[k − FEEDBACK_LAGS]``.
        ``statistic`` is the Wald statistic ``b'·(P'P)·b/σ̂²`` of the position's coefficients
        ``b`` (``P`` the position's columns less their projection on the neighbours, ``σ̂²``
        the residual variance), ``share`` ``b'·(P'P)·b`` over the sum of squares of ``u``.
        In open loop the position up to ``k`` is the plant's response to inputs that the
        neighbours of ``u[k]`` interpolate, plus noise the input never saw: ``b = 0`` and the
        statistic is χ² with ``FEEDBACK_LAGS + 1`` degrees of freedom, at any sampling rate
        (the input's own dynamics are in the neighbours; a plant's lag or hold cannot make the
        position lead an input it follows). A controller computing ``u[k]`` from the measured
        ``x[k]`` and ``x[k − 1]`` puts those samples' noise into the input, which no neighbour
        holds in full. Both 0 for records too short to tell (fewer than ten rows per
        regressor). docs/gap.md §Closed loop.
    """
    u = np.asarray(u, dtype=float)
    x = np.asarray(x, dtype=float)
    side, lags = FEEDBACK_NEIGHBOURS, FEEDBACK_LAGS
    n_rows = len(u) - 2 * side - lags
    if n_rows < 10 * (2 * side + lags + 2) or not (np.std(u) > 0 and np.std(x) > 0):
        return FeedbackTest(0.0, 0.0)
    u = (u - np.mean(u)) / np.std(u)
    x = (x - np.mean(x)) / np.std(x)
    rows = side + lags + np.arange(0, n_rows, -(-n_rows // FEEDBACK_MAX_ROWS))
    offsets = np.concatenate([np.arange(-side, 0), np.arange(1, side + 1)])
    neighbours = np.column_stack([np.ones(len(rows)), u[rows[:, None] + offsets]])
    basis, _ = np.linalg.qr(neighbours)
    target = u[rows] - basis @ (basis.T @ u[rows])
    position = x[rows[:, None] - np.arange(lags + 1)]
    position = position - basis @ (basis.T @ position)
    coef, *_ = np.linalg.lstsq(position, target, rcond=None)
    residual = target - position @ coef
    variance = float(residual @ residual) / (len(rows) - neighbours.shape[1] - lags - 1)
    explained = float(coef @ (position.T @ position) @ coef)
    if not variance > 0:
        return FeedbackTest(0.0, 0.0)
    return FeedbackTest(explained / variance, explained / len(rows))


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
        input reacts to its output's noise (:func:`in_loop`), the holds of
        :data:`CAUSAL_HOLDS` among ``holds`` and one note giving the test; otherwise ``holds``
        unchanged, with a note when the test is significant but the fed-back noise too small
        to matter (below :data:`FEEDBACK_MIN_SHARE`).
    """
    plant = only_module(PLANT)
    if plant not in names or len(holds) == 1:
        return holds, []
    test = feedback_test(signals["u_act"][:n_train], signals["x"][:n_train])
    if test.statistic < FEEDBACK_THRESHOLD:
        return holds, []
    if not test.loop:
        note = (
            f"{plant}'s input reacts to the position's noise (feedback statistic "
            f"{test.statistic:.1f} >= {FEEDBACK_THRESHOLD:.1f}), but that noise is "
            f"{test.share:.1e} of the input's variance (< {FEEDBACK_MIN_SHARE:.0e}): fitted as "
            "in open loop (docs/gap.md, Closed loop)"
        )
        return holds, [note]
    causal = tuple(h for h in holds if h in CAUSAL_HOLDS)
    note = (
        f"{plant} runs in a feedback loop: its input reacts to the position's noise (feedback "
        f"statistic {test.statistic:.1f} >= {FEEDBACK_THRESHOLD:.1f}, size "
        f"{FEEDBACK_SIZE:.0e}; {test.share:.1e} of the input's variance); only causal plants "
        f"({', '.join(causal)}) were tried (docs/gap.md, Closed loop)"
    )
    return causal, [note]


def in_loop(u: np.ndarray, x: np.ndarray) -> bool:
    """Return whether a plant's input reacts to its position's noise (a feedback loop).

    ``u``, ``x`` shape ``(n_samples,)``: the training part. :attr:`FeedbackTest.loop` of
    :func:`feedback_test`, the rule :func:`causal_holds` applies.
    """
    return feedback_test(u, x).loop


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
