"""The paper's §5 claims about the sensitivity sweep (Fig. 11), judged on configuration values.

Claim logic of :mod:`dtwin.figures.fig11_sensitivity`, kept apart from its drawing: the
numbers behind each claim (:func:`sweep_claim_numbers`) and the claims judged on them
(:func:`sweep_claims`), ours first and R's (and ours on R's signals) beside them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.artifacts import REPLICATES_METRIC, Check
from dtwin.sensitivity_sweep import alpha_trends, bimodality_coefficient

__all__ = [
    "PAPER_RANGE_PCT",
    "RANGE_SLACK_PCT",
    "BALANCED_RANGE_PCT",
    "R_MODE_SPLIT_PCT",
    "GRID",
    "sweep_claim_numbers",
    "sweep_claims",
    "REPLICATES_METRIC",
    "claims_across_replicates",
]

#: Paper §5: "ΔRMSE_e1 remaining in the ~23 %–40 % range", read with 3 percentage points slack.
PAPER_RANGE_PCT = (23.0, 40.0)
RANGE_SLACK_PCT = 3.0
#: Paper §5: balanced noise (m_A = m_B) "clustered around the mid-20 % to high-20 % range".
BALANCED_RANGE_PCT = (23.0, 30.0)
#: Midpoint of R's two modes (~24 % and ~40 %, r_notes.md §9): values below it are "low mode".
R_MODE_SPLIT_PCT = 32.0
#: Columns naming one configuration of the sweep.
GRID = ["alpha", "m_A", "m_B"]


def sweep_claim_numbers(means: pd.DataFrame, slopes: pd.DataFrame | None = None) -> dict:
    """Return the numbers behind the paper's sweep claims for one set of configuration values.

    Parameters
    ----------
    means : DataFrame
        Columns ``alpha, m_A, m_B, value`` (ΔRMSE_e1 % per configuration).
    slopes : DataFrame, optional
        From :func:`dtwin.sensitivity_sweep.alpha_trends` for these values (columns ``m_A, m_B,
        replicate, slope_pct_per_unit_alpha``); computed from ``means`` when omitted.

    Returns
    -------
    dict
        ``min, max, mean, median, bimodality_coefficient, n_low_mode`` (below
        :data:`R_MODE_SPLIT_PCT`), ``slopes_B_noisiest`` / ``slopes_B_cleanest`` (median and
        mean over replicates of the slope per m_A row, %/unit α, and the fraction of
        replicates with a positive slope),
        ``argmax`` (the best configuration) and ``balanced_median`` (median over m_A = m_B).
    """
    values = means["value"].to_numpy(dtype=float)
    if slopes is None:
        table = means.assign(drmse_e1_pct=means["value"], replicate=0, source="", method="")
        slopes = alpha_trends(table)
    b_max, b_min = means["m_B"].max(), means["m_B"].min()

    def row_slopes(m_b: float) -> dict[str, dict[str, float]]:
        rows = slopes[slopes["m_B"] == m_b]
        return {
            f"m_A={m_a:g}": {
                "median_slope": float(group["slope_pct_per_unit_alpha"].median()),
                "mean_slope": float(group["slope_pct_per_unit_alpha"].mean()),
                "frac_positive": float((group["slope_pct_per_unit_alpha"] > 0).mean()),
            }
            for m_a, group in rows.groupby("m_A", sort=True)
        }

    best = means.loc[means["value"].idxmax()]
    balanced = means[means["m_A"] == means["m_B"]]["value"]
    return {
        "n": int(values.size),
        "min": float(values.min()),
        "max": float(values.max()),
        "mean": float(values.mean()),
        "median": float(np.median(values)),
        "bimodality_coefficient": bimodality_coefficient(values),
        "n_low_mode": int((values < R_MODE_SPLIT_PCT).sum()),
        "slopes_B_noisiest": row_slopes(b_max),
        "slopes_B_cleanest": row_slopes(b_min),
        "argmax": {key: float(best[key]) for key in (*GRID, "value")},
        "balanced_median": float(balanced.median()) if len(balanced) else None,
    }


class _Rules:
    """Pass rules of the trend claims for one grid (each takes one source's numbers)."""

    def __init__(self, alphas: Sequence[float], grid: Mapping) -> None:
        self.mults_a, self.mults_b = grid["m_A"], grid["m_B"]
        self.two_b = len(self.mults_b) > 1 and len(alphas) > 1
        self.median_alpha = float(np.median(alphas))

    def trend(self, values: dict) -> bool:
        rows = values["slopes_B_noisiest"].values()
        return self.two_b and bool(rows) and all(row["median_slope"] > 0 for row in rows)

    def weaker(self, values: dict) -> bool:
        noisy = [abs(r["median_slope"]) for r in values["slopes_B_noisiest"].values()]
        clean = [abs(r["median_slope"]) for r in values["slopes_B_cleanest"].values()]
        return self.two_b and bool(noisy) and float(np.mean(clean)) < float(np.mean(noisy))

    def argmax(self, values: dict) -> bool:
        best = values["argmax"]
        return (
            len(self.mults_a) > 1
            and len(self.mults_b) > 1
            and best["m_A"] == max(self.mults_a)
            and best["m_B"] == min(self.mults_b)
            and best["alpha"] >= self.median_alpha
        )

    @staticmethod
    def balanced(values: dict) -> bool:
        median = values["balanced_median"]
        return median is not None and BALANCED_RANGE_PCT[0] <= median <= BALANCED_RANGE_PCT[1]


def _side(numbers: Mapping[str, dict], key: str) -> dict[str, Any]:
    return {source: values.get(key) for source, values in numbers.items()}


def _judged(numbers: Mapping[str, dict], rule) -> dict[str, bool]:
    return {source: rule(values) for source, values in numbers.items()}


def _level_claims(numbers: Mapping[str, dict]) -> list[Check]:
    """Claims on the level of ΔRMSE_e1: positive, in the paper's range, one mode."""
    ours = numbers["ours"]
    lo, hi = PAPER_RANGE_PCT
    return [
        Check(
            id="all_positive",
            kind="claim",
            statement="paper §5: the intervention produced consistently positive error "
            "reductions across all configurations",
            expected="min ΔRMSE_e1 > 0 % (ours; R's and ours-on-R's-signals beside it)",
            observed=_side(numbers, "min"),
            passed=ours["min"] > 0,
        ),
        Check(
            id="range_23_40",
            kind="claim",
            statement=f"paper §5: ΔRMSE_e1 remains in the ~{lo:g}–{hi:g} % range "
            f"(read with {RANGE_SLACK_PCT:g} percentage points slack); R's re-run: 23.28–41.85 %",
            expected=f"every configuration in [{lo - RANGE_SLACK_PCT:g}, "
            f"{hi + RANGE_SLACK_PCT:g}] %",
            observed={s: [v["min"], v["max"]] for s, v in numbers.items()},
            passed=lo - RANGE_SLACK_PCT <= ours["min"] and ours["max"] <= hi + RANGE_SLACK_PCT,
        ),
        Check(
            id="one_mode_with_restarts",
            kind="target",
            statement="r_notes.md §9: R's 36 values are bimodal (~24 % or ~40 %) because each "
            "configuration had one EM start and landed in one of two local optima; with several "
            "starts per fit ours should sit in one mode (Sarle's bimodality coefficient, > 5/9 "
            "suggesting two modes, is reported beside it)",
            expected=f"all configurations on one side of {R_MODE_SPLIT_PCT:g} % (the midpoint "
            "of R's modes)",
            observed={
                s: {
                    "n_low_mode": v["n_low_mode"],
                    "n": v["n"],
                    "bimodality_coefficient": v["bimodality_coefficient"],
                }
                for s, v in numbers.items()
            },
            passed=ours["n_low_mode"] in (0, ours["n"]),
        ),
    ]


def _shape_claims(numbers: Mapping[str, dict], rules: _Rules) -> list[Check]:
    """Claims on the shape of the sweep: α trends, the best configuration, balanced noise."""
    ours = numbers["ours"]
    return [
        Check(
            id="alpha_trend_sensor_B_degraded",
            kind="claim",
            statement="paper §5: when Sensor B was degraded, improvements generally increased "
            "with α (least-squares slope of ΔRMSE_e1 on α within each replicate, noisiest-B "
            "column, per Sensor A row; the median over replicates, robust to a replicate whose "
            "EM fit fell into a worse local optimum, and the share of positive slopes)",
            expected="median slope > 0 in every Sensor A row",
            observed={
                **_side(numbers, "slopes_B_noisiest"),
                "passed_by_source": _judged(numbers, rules.trend),
            },
            passed=rules.trend(ours),
        ),
        Check(
            id="alpha_dependence_weaker_sensor_B_clean",
            kind="claim",
            statement="paper §5: when Sensor B was cleaner, the dependence on α was weaker",
            expected="mean over Sensor A rows of |median slope|: cleanest-B column < noisiest-B",
            observed={
                **_side(numbers, "slopes_B_cleanest"),
                "passed_by_source": _judged(numbers, rules.weaker),
            },
            passed=rules.weaker(ours),
        ),
        Check(
            id="largest_gain_high_A_low_B_noise",
            kind="claim",
            statement="paper §5: the largest gains occurred for high Sensor A noise with low "
            "Sensor B noise at moderate-to-large α",
            expected=f"best configuration at m_A = {max(rules.mults_a):g}, "
            f"m_B = {min(rules.mults_b):g}, α >= {rules.median_alpha:g}",
            observed={
                **_side(numbers, "argmax"),
                "passed_by_source": _judged(numbers, rules.argmax),
            },
            passed=rules.argmax(ours),
        ),
        Check(
            id="balanced_noise_mid_to_high_20s",
            kind="claim",
            statement="paper §5: in balanced cases (m_A = m_B) the improvement clustered around "
            "the mid-20 % to high-20 % range (median over those configurations)",
            expected=f"median in [{BALANCED_RANGE_PCT[0]:g}, {BALANCED_RANGE_PCT[1]:g}] %",
            observed={
                **_side(numbers, "balanced_median"),
                "passed_by_source": _judged(numbers, rules.balanced),
            },
            passed=rules.balanced(ours),
        ),
    ]


def sweep_claims(
    numbers: Mapping[str, dict], alphas: Sequence[float], grid: Mapping
) -> list[Check]:
    """Return the paper's §5 claims, judged on ``numbers["ours"]``, R's numbers beside them.

    Parameters
    ----------
    numbers : mapping of source to dict
        :func:`sweep_claim_numbers` per source (``ours``, optionally ``r_signals`` and
        ``r_rerun``).
    alphas : sequence of float
        The grid's fusion weights.
    grid : mapping
        ``m_A`` and ``m_B``: the grid's sensor-noise multipliers.

    Returns
    -------
    list of Check
        Seven ``claim`` checks: three on the level of ΔRMSE_e1, four on the sweep's shape.
    """
    return [*_level_claims(numbers), *_shape_claims(numbers, _Rules(alphas, grid))]


def claims_across_replicates(
    table: pd.DataFrame, method: str, alphas: Sequence[float], grid: Mapping
) -> dict[str, Any]:
    """Return every sweep claim judged on each replicate's configuration values alone.

    Parameters
    ----------
    table : DataFrame
        Every run (:func:`dtwin.sensitivity_sweep.sweep_table`); only ``source = "ours"`` and
        ``method`` are read.
    method : str
        The correction method the figure's claims are judged on.
    alphas, grid
        As for :func:`sweep_claims`.

    Returns
    -------
    dict
        ``n_replicates``; ``replicate0_is_figure`` (True with one replicate: the figure then
        judges replicate 0's values, so its verdicts must equal replicate 0's); ``verdicts``:
        per claim id, one bool per replicate (replicate 0 first). Each replicate's claims see
        only its own 36 values and its own α-slopes (a claim that takes the median over
        replicates takes it over that replicate alone).

    Raises
    ------
    DtwinValueError
        If ``table`` has no run of ``method`` on our own simulation.
    """
    runs = table[(table["source"] == "ours") & (table["method"] == method)]
    if runs.empty:
        raise DtwinValueError(f"the sweep has no run of our own with correction {method!r}")
    trends = alpha_trends(runs)
    verdicts: dict[str, list[bool]] = {}
    replicates = sorted(int(r) for r in runs["replicate"].unique())
    for replicate in replicates:
        # the figure's order (summarize_sweep: α, m_A, m_B), so ties and sums fall alike
        part = runs[runs["replicate"] == replicate].sort_values(GRID)
        means = part[GRID].assign(value=part["drmse_e1_pct"]).reset_index(drop=True)
        numbers = sweep_claim_numbers(means, trends[trends["replicate"] == replicate])
        for check in sweep_claims({"ours": numbers}, alphas, grid):
            verdicts.setdefault(check.id, []).append(bool(check.passed))
    return {
        "n_replicates": len(replicates),
        "replicate0_is_figure": len(replicates) == 1,
        "verdicts": verdicts,
    }
