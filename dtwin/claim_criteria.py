"""The paper's claims of Figs. 2–6 and 10 as criteria: one public function per claim.

Each figure judges its claims with these functions, and the claims across random draws
(:mod:`dtwin.stages.draw_claims`) judge every draw with the same functions, so a claim's reading
is written once. The fault scenario's claims (Figs. 7, 8) are in
:mod:`dtwin.fault_claim_criteria`. This module imports only numpy and pandas, so a figure that
reads it loads nothing heavy and a draw job that reads it imports no figure.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.twin.wiring import RESIDUALS

__all__ = [
    "RMSE_RATIO",
    "rmse_like_r",
    "strongly_autocorrelated",
    "not_white",
    "all_structured",
    "PERSISTENCE_DWELL_S",
    "persistence_floor",
    "regimes_are_persistent",
    "PAPER_LOWERED",
    "VISIBLE_PCT",
    "lowered_in_m1_m2b_m3_m4",
    "REDUCED_PCT",
    "residual_spread",
    "tightened",
    "MCDA_CLAIMS",
    "action_share",
    "regime_spans",
    "dynamics_off_window",
]

#: Fig. 2, "general agreement with noticeable discrepancies": every module's held-out RMSE within
#: this factor of R's (r_numbers.yaml nominal_rmse_test_half), i.e. discrepancies of R's size.
RMSE_RATIO = 1.5

#: Fig. 4, "persistent": every state's expected dwell dt/(1 − A_kk) is at least this long (s),
#: the lag within which Fig. 7 requires a regime's posterior to rise (``ONSET_LAG_S``), so a
#: shorter state could not carry a regime (A_kk >= 0.96 at dt = 0.02 s).
PERSISTENCE_DWELL_S = 0.5

#: Fig. 5: residuals the paper says the correction visibly lowers (§4.3: M1, M2b, M3, M4).
PAPER_LOWERED: tuple[str, ...] = ("e1", "e2b", "e3", "e4")

#: Fig. 5: "visibly lowered" = RMSE down by more than this many percent.
VISIBLE_PCT = 1.0

#: Fig. 6: variance or RMSE "reduced" when it falls by more than this many percent.
REDUCED_PCT = 1.0

#: Fig. 10's claims: (regime, action) pairs that must be the regime's most frequent action.
MCDA_CLAIMS: tuple[tuple[str, str], ...] = (
    ("DynamicsOff", "ReidentifyPlant"),
    ("Drift", "BiasCorrect"),
)


def rmse_like_r(rmse: Mapping[str, float], r_rmse: Mapping[str, float]) -> bool:
    """Return True when every residual's RMSE is within a factor :data:`RMSE_RATIO` of R's.

    Examples
    --------
    >>> rmse_like_r({"e1": 1.4}, {"e1": 1.0}), rmse_like_r({"e1": 1.6}, {"e1": 1.0})
    (True, False)
    """
    return all(1 / RMSE_RATIO <= rmse[e] / r_rmse[e] <= RMSE_RATIO for e in r_rmse)


def strongly_autocorrelated(lag1: float, strong: float) -> bool:
    """Fig. 3: a residual decays slowly when its lag-1 ACF exceeds ``strong`` (config ``acf``)."""
    return bool(lag1 > strong)


def not_white(max_p: float, alpha: float) -> bool:
    """Fig. 3: a residual is not white when Ljung–Box rejects at every tested lag (max p < α)."""
    return bool(max_p < alpha)


def all_structured(max_p: Mapping[str, float], alpha: float) -> bool:
    """Fig. 3 caption: every residual is structured (:func:`not_white` for each channel)."""
    return all(not_white(p, alpha) for p in max_p.values())


def persistence_floor(dt: float) -> float:
    """Fig. 4: the smallest self-transition A_kk whose expected dwell dt/(1 − A_kk) is long enough.

    Examples
    --------
    >>> round(persistence_floor(0.01), 6)
    0.98
    """
    return 1 - dt / PERSISTENCE_DWELL_S


def regimes_are_persistent(self_prob: np.ndarray, dt: float) -> bool:
    """Fig. 4: every state's self-transition probability reaches :func:`persistence_floor`."""
    return bool(np.all(np.asarray(self_prob) >= persistence_floor(dt)))


def lowered_in_m1_m2b_m3_m4(drmse: Mapping[str, float]) -> bool:
    """Fig. 5: RMSE down by more than :data:`VISIBLE_PCT` % in each residual of the paper's list."""
    return all(drmse[e] > VISIBLE_PCT for e in PAPER_LOWERED)


def residual_spread(residuals: pd.DataFrame) -> dict[str, Any]:
    """Fig. 6: sd, RMSE and median of each residual before and after the (smoothed) correction.

    Parameters
    ----------
    residuals : DataFrame
        ``<e>_before`` and ``<e>_smoothed`` per residual e0…e4 (``results/correction/
        residuals.csv``).

    Returns
    -------
    dict
        Per residual: ``sd_before``, ``sd_after``, ``dsd_pct`` (%), ``rmse_before``,
        ``rmse_after``, ``drmse_pct`` (%; None when the value before is 0), ``median_before``,
        ``median_after``.
    """
    out = {}
    for e in RESIDUALS:
        before = residuals[f"{e}_before"].to_numpy()
        after = residuals[f"{e}_smoothed"].to_numpy()
        sd_b, sd_a = float(before.std()), float(after.std())
        rmse_b, rmse_a = float(np.sqrt(np.mean(before**2))), float(np.sqrt(np.mean(after**2)))
        out[e] = {
            "sd_before": sd_b,
            "sd_after": sd_a,
            "dsd_pct": 100 * (sd_b - sd_a) / sd_b if sd_b > 0 else None,
            "rmse_before": rmse_b,
            "rmse_after": rmse_a,
            "drmse_pct": 100 * (rmse_b - rmse_a) / rmse_b if rmse_b > 0 else None,
            "median_before": float(np.median(before)),
            "median_after": float(np.median(after)),
        }
    return out


def tightened(entry: Mapping[str, Any]) -> bool:
    """Fig. 6: sd and RMSE both down by more than :data:`REDUCED_PCT` % (one residual_spread entry).

    Examples
    --------
    >>> tightened({"dsd_pct": 5.0, "drmse_pct": 2.0})
    True
    >>> tightened({"dsd_pct": 5.0, "drmse_pct": None})
    False
    """
    return all(
        entry[key] is not None and entry[key] > REDUCED_PCT for key in ("dsd_pct", "drmse_pct")
    )


def action_share(counts: pd.DataFrame, regime: str, action: str) -> tuple[float, bool]:
    """Fig. 10: the share of ``regime``'s steps that take ``action``, and whether it is the mode.

    Parameters
    ----------
    counts : DataFrame
        Steps per regime (index) and action (columns).

    Returns
    -------
    tuple of (float, bool)
        The share in [0, 1] (0 for an absent regime) and whether ``action`` is the regime's most
        frequent action (the claim of :data:`MCDA_CLAIMS`).
    """
    row = counts.loc[regime] if regime in counts.index else pd.Series(dtype=float)
    share = float(row.get(action, 0) / row.sum()) if row.sum() else 0.0
    return share, bool(row.sum() and row.idxmax() == action)


def regime_spans(t: Any, regimes: Any) -> list[tuple[str, float, float]]:
    """Return the runs of equal regime labels as ``(regime, start, end)`` in seconds.

    ``end`` is the start of the next run, or the last sample plus one sample period.

    Examples
    --------
    >>> regime_spans([0.0, 0.5, 1.0, 1.5], ["a", "a", "b", "b"])
    [('a', 0.0, 1.0), ('b', 1.0, 2.0)]
    """
    t = np.asarray(t, dtype=float)
    labels = np.asarray(regimes, dtype=str)
    step = float(t[1] - t[0]) if len(t) > 1 else 1.0
    starts = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    ends = np.r_[starts[1:], len(t)]
    return [
        (str(labels[i]), float(t[i]), float(t[j]) if j < len(t) else float(t[-1] + step))
        for i, j in zip(starts, ends, strict=True)
    ]


def dynamics_off_window(
    physics_x: np.ndarray, e1: np.ndarray, regimes: np.ndarray
) -> dict[str, float]:
    """Return what a regime-mean correction can remove from e1 in the DynamicsOff window.

    The number that explains Figs. 5 and 12's e1 result across draws.

    Parameters
    ----------
    physics_x : array, shape (T,)
        Physics position x, m.
    e1 : array, shape (T,)
        Faulted plant residual (surrogate − physics), m.
    regimes : array of str, shape (T,)
        Scheduled regime per sample.

    Returns
    -------
    dict
        ``mean_x`` (m): the window's mean of x (DynamicsOff scales the surrogate x by 0.8, so
        e1 ≈ −0.2·x there); ``mean_e1`` (m); ``e1_mean_share``: mean(e1)² / mean(e1²) in the
        window, the share of e1's energy a constant offset carries. NaN without the window.

    Examples
    --------
    >>> dynamics_off_window([1.0, 2.0], [0.1, 0.1], ["DynamicsOff", "DynamicsOff"])
    {'mean_x': 1.5, 'mean_e1': 0.1, 'e1_mean_share': 1.0}
    """
    inside = np.asarray(regimes) == "DynamicsOff"
    if not inside.any():
        nan = float("nan")
        return {"mean_x": nan, "mean_e1": nan, "e1_mean_share": nan}
    window = np.asarray(e1, dtype=float)[inside]
    energy = float(np.mean(window**2))
    mean = float(window.mean())
    return {
        "mean_x": float(np.mean(np.asarray(physics_x, dtype=float)[inside])),
        "mean_e1": mean,
        "e1_mean_share": float(round(mean**2 / energy, 12)) if energy > 0 else float("nan"),
    }
