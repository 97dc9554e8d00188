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
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.signal import savgol_filter

from dtwin.modules import EULER, ZOH

__all__ = [
    "CAUSAL_HOLDS",
    "FEEDBACK_THRESHOLD",
    "FEEDBACK_LAGS",
    "feedback_statistic",
    "loop_statistic",
    "causal_holds",
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
    if "M1" not in names or len(holds) == 1:
        return holds, []
    statistic = loop_statistic(signals["u_act"][:n_train], signals["x"][:n_train])
    if statistic < FEEDBACK_THRESHOLD:
        return holds, []
    causal = tuple(h for h in holds if h in CAUSAL_HOLDS)
    note = (
        f"M1 runs in a feedback loop: its input reacts to the position's noise (statistic "
        f"{statistic:.2f} >= {FEEDBACK_THRESHOLD}); only causal plants ({', '.join(causal)}) "
        "were tried (docs/gap.md, Closed loop)"
    )
    return causal, [note]
