"""Paper Fig. 11: ΔRMSE_e1 % against the fusion weight α, faceted by sensor-noise multipliers.

Rows are Sensor A multipliers, columns Sensor B multipliers (as in the paper and R's figure).
One panel set per correction method (the configured one first): our mean over replicates with
its central interval, R's re-run (one EM start per configuration, ``code`` correction only)
and, when enabled, our HMM on R's own signals. The JSON puts every configuration's number
beside R's and checks the paper's claims about the sweep (§5) on ours and on R's numbers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from dtwin.artifacts import Check, FigureArtifact, validity_finite
from dtwin.figures._style import BAND_COLOR, PHYSICS_COLOR, SURROGATE_COLOR, apply_style
from dtwin.sensitivity_sweep import alpha_trends, bimodality_coefficient

__all__ = ["plot_sensitivity", "fig11_sensitivity", "sweep_claim_numbers"]

#: Paper §5: "ΔRMSE_e1 remaining in the ~23 %–40 % range", read with 3 percentage points slack.
PAPER_RANGE_PCT = (23.0, 40.0)
RANGE_SLACK_PCT = 3.0
#: Paper §5: balanced noise (m_A = m_B) "clustered around the mid-20 % to high-20 % range".
BALANCED_RANGE_PCT = (23.0, 30.0)
#: Midpoint of R's two modes (~24 % and ~40 %, r_notes.md §9): values below it are "low mode".
R_MODE_SPLIT_PCT = 32.0
#: Relative spread of e1's RMSE across configurations that still counts as "identical".
E1_IDENTICAL_RTOL = 1e-12
#: Relative agreement of R's pre-correction numbers rebuilt from R's signals (CSV has 12 digits).
R_INPUT_RTOL = 1e-7

_METHOD_TITLES = {
    "code": "code: Viterbi state means, κ 0.6, rate 5e-4 (r_notes.md §7C)",
    "paper": "paper §4.3 values: posterior-weighted means, κ 0.8, rate 0.05",
}
_GRID = ["alpha", "m_A", "m_B"]


def _facet_values(frame: pd.DataFrame, m_a: float, m_b: float) -> pd.DataFrame:
    return frame[(frame["m_A"] == m_a) & (frame["m_B"] == m_b)].sort_values("alpha")


def plot_sensitivity(
    summary: pd.DataFrame,
    r_sweep: pd.DataFrame | None,
    methods: Sequence[str],
    interval: float,
) -> Figure:
    """Draw the faceted sweep, one panel set per correction method.

    Parameters
    ----------
    summary : DataFrame
        From :func:`dtwin.sensitivity_sweep.summarize_sweep` (sources ``ours`` and optionally
        ``r_signals``).
    r_sweep : DataFrame or None
        R's re-run (:func:`dtwin.reference.loaders.load_r_sweep`), drawn on the ``code`` panels.
    methods : sequence of str
        Correction methods, one panel set each, left to right.
    interval : float
        Probability mass of the drawn interval (for the legend).
    """
    apply_style()
    mults_a = sorted(summary["m_A"].unique())
    mults_b = sorted(summary["m_B"].unique())
    alphas = sorted(summary["alpha"].unique())
    n_rep = int(summary["n_replicates"].max())
    width = max(2.4 * len(mults_b), 4.5)
    figure = plt.figure(figsize=(width * len(methods) + 0.6, 2.1 * len(mults_a) + 1.3))
    panels = np.atleast_1d(figure.subfigures(1, len(methods), wspace=0.04))
    values = summary[["drmse_e1_lo", "drmse_e1_hi"]].to_numpy().ravel()
    if r_sweep is not None:
        values = np.concatenate([values, r_sweep["drmse_e1_pct"].to_numpy()])
    low, high = float(np.nanmin(values)), float(np.nanmax(values))
    pad = 0.06 * max(high - low, 1.0)
    handles: dict[str, Any] = {}
    for panel, method in zip(panels, methods, strict=True):
        axes = panel.subplots(len(mults_a), len(mults_b), sharex=True, sharey=True, squeeze=False)
        ours = summary[(summary["source"] == "ours") & (summary["method"] == method)]
        on_r = summary[(summary["source"] == "r_signals") & (summary["method"] == method)]
        for i, m_a in enumerate(mults_a):
            for j, m_b in enumerate(mults_b):
                ax = axes[i, j]
                facet = _facet_values(ours, m_a, m_b)
                line = ax.errorbar(
                    facet["alpha"],
                    facet["drmse_e1_mean"],
                    yerr=[
                        facet["drmse_e1_mean"] - facet["drmse_e1_lo"],
                        facet["drmse_e1_hi"] - facet["drmse_e1_mean"],
                    ],
                    color=PHYSICS_COLOR,
                    marker="o",
                    ms=4,
                    lw=1.2,
                    capsize=2.5,
                )
                label = (
                    "ours (numpy draws)"
                    if n_rep == 1
                    else (f"ours: mean of {n_rep} replicates, {interval:.0%} interval")
                )
                handles[label] = line
                if not on_r.empty:
                    facet_r = _facet_values(on_r, m_a, m_b)
                    (line,) = ax.plot(
                        facet_r["alpha"],
                        facet_r["drmse_e1_mean"],
                        color=SURROGATE_COLOR,
                        marker="D",
                        ms=3.5,
                        lw=1.0,
                        ls="--",
                    )
                    handles["our HMM on R's exact signals"] = line
                if r_sweep is not None and method == "code":
                    facet_rr = _facet_values(r_sweep, m_a, m_b)
                    (line,) = ax.plot(
                        facet_rr["alpha"],
                        facet_rr["drmse_e1_pct"],
                        color=BAND_COLOR,
                        marker="s",
                        mfc="none",
                        ms=5,
                        lw=0,
                    )
                    handles["R re-run (1 EM start per configuration)"] = line
                ax.set_ylim(low - pad, high + pad)
                ax.set_xticks(alphas)
                ax.axhline(0, color="#999999", lw=0.5)
                if i == 0:
                    ax.set_title(f"Sensor B ×{m_b:g}", fontsize=9)
                if j == len(mults_b) - 1:
                    ax.yaxis.set_label_position("right")
                    ax.set_ylabel(f"Sensor A ×{m_a:g}", rotation=270, labelpad=12)
                if i == len(mults_a) - 1:
                    ax.set_xlabel("fusion weight α")
                if j == 0 and i == len(mults_a) // 2:
                    ax.text(
                        -0.32 if len(mults_b) > 1 else -0.2,
                        0.5,
                        "ΔRMSE$_{e1}$ (%)",
                        rotation=90,
                        va="center",
                        ha="center",
                        transform=ax.transAxes,
                    )
        panel.suptitle(_METHOD_TITLES.get(method, method), fontsize=10)
    figure.legend(
        list(handles.values()),
        list(handles),
        loc="lower center",
        ncol=len(handles),
        bbox_to_anchor=(0.5, -0.04),
    )
    figure.suptitle(
        "Sensitivity of the plant residual improvement to fusion and sensor noise (paper Fig. 11)",
        y=1.04,
    )
    return figure


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
        "argmax": {key: float(best[key]) for key in (*_GRID, "value")},
        "balanced_median": float(balanced.median()) if len(balanced) else None,
    }


def _claims(numbers: Mapping[str, dict], alphas: Sequence[float], grid: Mapping) -> list[Check]:
    """The paper's §5 claims, judged on ``numbers["ours"]``; R's (and ours on R's signals)
    beside it."""
    ours = numbers["ours"]
    lo, hi = PAPER_RANGE_PCT
    mults_a, mults_b = grid["m_A"], grid["m_B"]
    two_b = len(mults_b) > 1 and len(alphas) > 1
    median_alpha = float(np.median(alphas))

    def side(key: str) -> dict[str, Any]:
        return {source: values.get(key) for source, values in numbers.items()}

    def trend_ok(values: dict) -> bool:
        rows = values["slopes_B_noisiest"].values()
        return two_b and bool(rows) and all(row["median_slope"] > 0 for row in rows)

    def weaker_ok(values: dict) -> bool:
        noisy = [abs(r["median_slope"]) for r in values["slopes_B_noisiest"].values()]
        clean = [abs(r["median_slope"]) for r in values["slopes_B_cleanest"].values()]
        return two_b and bool(noisy) and float(np.mean(clean)) < float(np.mean(noisy))

    def argmax_ok(values: dict) -> bool:
        best = values["argmax"]
        return (
            len(mults_a) > 1
            and len(mults_b) > 1
            and best["m_A"] == max(mults_a)
            and best["m_B"] == min(mults_b)
            and best["alpha"] >= median_alpha
        )

    def balanced_ok(values: dict) -> bool:
        median = values["balanced_median"]
        return median is not None and BALANCED_RANGE_PCT[0] <= median <= BALANCED_RANGE_PCT[1]

    def judged(rule) -> dict[str, bool]:
        return {source: rule(values) for source, values in numbers.items()}

    return [
        Check(
            id="all_positive",
            kind="claim",
            statement="paper §5: the intervention produced consistently positive error "
            "reductions across all configurations",
            expected="min ΔRMSE_e1 > 0 % (ours; R's and ours-on-R's-signals beside it)",
            observed=side("min"),
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
            kind="claim",
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
        Check(
            id="alpha_trend_sensor_B_degraded",
            kind="claim",
            statement="paper §5: when Sensor B was degraded, improvements generally increased "
            "with α (least-squares slope of ΔRMSE_e1 on α within each replicate, noisiest-B "
            "column, per Sensor A row; the median over replicates, robust to a replicate whose "
            "EM fit fell into a worse local optimum, and the share of positive slopes)",
            expected="median slope > 0 in every Sensor A row",
            observed={**side("slopes_B_noisiest"), "passed_by_source": judged(trend_ok)},
            passed=trend_ok(ours),
        ),
        Check(
            id="alpha_dependence_weaker_sensor_B_clean",
            kind="claim",
            statement="paper §5: when Sensor B was cleaner, the dependence on α was weaker",
            expected="mean over Sensor A rows of |median slope|: cleanest-B column < noisiest-B",
            observed={**side("slopes_B_cleanest"), "passed_by_source": judged(weaker_ok)},
            passed=weaker_ok(ours),
        ),
        Check(
            id="largest_gain_high_A_low_B_noise",
            kind="claim",
            statement="paper §5: the largest gains occurred for high Sensor A noise with low "
            "Sensor B noise at moderate-to-large α",
            expected=f"best configuration at m_A = {max(mults_a):g}, m_B = {min(mults_b):g}, "
            f"α >= {median_alpha:g}",
            observed={**side("argmax"), "passed_by_source": judged(argmax_ok)},
            passed=argmax_ok(ours),
        ),
        Check(
            id="balanced_noise_mid_to_high_20s",
            kind="claim",
            statement="paper §5: in balanced cases (m_A = m_B) the improvement clustered around "
            "the mid-20 % to high-20 % range (median over those configurations)",
            expected=f"median in [{BALANCED_RANGE_PCT[0]:g}, {BALANCED_RANGE_PCT[1]:g}] %",
            observed={**side("balanced_median"), "passed_by_source": judged(balanced_ok)},
            passed=balanced_ok(ours),
        ),
    ]


def _r_input_check(summary: pd.DataFrame, r_sweep: pd.DataFrame) -> tuple[Check, dict]:
    rebuilt = summary[(summary["source"] == "r_signals") & (summary["method"] == "code")]
    joined = rebuilt.merge(r_sweep, on=_GRID, suffixes=("", "_r"))
    deviations = {}
    for ours, theirs in (
        ("rmse_e1_before_mean", "rmse_e1_before"),
        ("l2_before_mean", "l2_before"),
    ):
        rel = np.abs(joined[ours] - joined[theirs]) / np.abs(joined[theirs])
        deviations[theirs] = float(rel.max()) if len(rel) else None
    passed = len(joined) > 0 and all(
        d is not None and d <= R_INPUT_RTOL for d in deviations.values()
    )
    check = Check(
        id="r_inputs_rebuilt_exactly",
        kind="crosscheck",
        statement="R's sweep configurations rebuilt from R's seed-11 signals (sensor noise "
        "rescaled, fusion recomputed, our ARX refit and rollout) give R's pre-correction "
        "RMSE_e1 and six-channel L2 in every configuration, so the HMM sees R's exact inputs",
        expected=f"max relative deviation <= {R_INPUT_RTOL:g} over {len(joined)} configurations",
        observed=deviations,
        passed=bool(passed),
    )
    return check, {"n_configurations_compared": len(joined), "max_rel_dev": deviations}


def _config_table(
    summary: pd.DataFrame, r_sweep: pd.DataFrame | None, methods: Sequence[str]
) -> list[dict]:
    wide = None
    for source in ("ours", "r_signals"):
        for method in methods:
            part = summary[(summary["source"] == source) & (summary["method"] == method)]
            if part.empty:
                continue
            prefix = f"{source}_{method}"
            columns = {"drmse_e1_mean": f"{prefix}_drmse_e1_pct"}
            if source == "ours":
                columns.update(
                    {
                        "drmse_e1_lo": f"{prefix}_drmse_e1_lo",
                        "drmse_e1_hi": f"{prefix}_drmse_e1_hi",
                        "dmae_e1_mean": f"{prefix}_dmae_e1_pct",
                        "dl2_mean": f"{prefix}_dl2_pct",
                    }
                )
            part = part[[*_GRID, *columns]].rename(columns=columns)
            wide = part if wide is None else wide.merge(part, on=_GRID, how="outer")
    if r_sweep is not None:
        r_part = r_sweep[[*_GRID, "drmse_e1_pct", "dmae_e1_pct", "dl2_pct"]].rename(
            columns={
                "drmse_e1_pct": "r_rerun_drmse_e1_pct",
                "dmae_e1_pct": "r_rerun_dmae_e1_pct",
                "dl2_pct": "r_rerun_dl2_pct",
            }
        )
        wide = wide.merge(r_part, on=_GRID, how="left")
    return wide.sort_values(["m_B", "m_A", "alpha"]).to_dict(orient="records")


def fig11_sensitivity(
    table: pd.DataFrame,
    summary: pd.DataFrame,
    r_sweep: pd.DataFrame,
    sensitivity: Mapping[str, Any],
) -> FigureArtifact:
    """Paper Fig. 11 with every configuration beside R's, the §5 claims and the R crosscheck.

    Parameters
    ----------
    table : DataFrame
        Every run (:func:`dtwin.sensitivity_sweep.sweep_table`).
    summary : DataFrame
        :func:`dtwin.sensitivity_sweep.summarize_sweep` of ``table``.
    r_sweep : DataFrame
        R's re-run (:func:`dtwin.reference.loaders.load_r_sweep`).
    sensitivity : mapping
        The ``sensitivity`` config section (grid, ``correction.method``, ``interval``, ...).
    """
    method = sensitivity["correction"]["method"]
    methods = [method, *(m for m in ("code", "paper") if m != method)]
    interval = sensitivity["interval"]
    figure = plot_sensitivity(summary, r_sweep, methods, interval)
    trends = alpha_trends(table)
    numbers: dict[str, dict[str, dict]] = {}
    for m in methods:
        numbers[m] = {}
        for source in ("ours", "r_signals"):
            part = summary[(summary["source"] == source) & (summary["method"] == m)]
            if part.empty:
                continue
            slopes = trends[(trends["source"] == source) & (trends["method"] == m)]
            means = part[_GRID].assign(value=part["drmse_e1_mean"])
            numbers[m][source] = sweep_claim_numbers(means, slopes)
    r_means = r_sweep[_GRID].assign(value=r_sweep["drmse_e1_pct"])
    numbers["code"]["r_rerun"] = sweep_claim_numbers(r_means)
    grid = {
        "alpha": list(sensitivity["alphas"]),
        "m_A": list(sensitivity["sensor_A_mults"]),
        "m_B": list(sensitivity["sensor_B_mults"]),
    }
    ours_runs = table[table["source"] == "ours"]
    e1_spread = ours_runs.groupby("replicate")["rmse_e1_before"].agg(
        lambda v: float((v.max() - v.min()) / v.mean())
    )
    checks = [
        validity_finite(
            "scores_finite",
            "ΔRMSE_e1, ΔMAE_e1 and ΔL2 of every run",
            table[["drmse_e1_pct", "dmae_e1_pct", "dl2_pct"]],
        ),
        Check(
            id="e1_identical_across_configurations",
            kind="validity",
            statement="α and the sensor noise do not touch actuator and plant, so e1 is the "
            "same in every configuration of a replicate (as in R: RMSE_e1 0.004884585 in all "
            "36 runs) and only the HMM varies",
            expected=f"relative spread of RMSE_e1 before correction <= {E1_IDENTICAL_RTOL:g}",
            observed={f"replicate {r}": s for r, s in e1_spread.items()},
            passed=bool((e1_spread <= E1_IDENTICAL_RTOL).all()),
        ),
        *_claims(numbers[method], grid["alpha"], grid),
    ]
    crosscheck_metrics = None
    if (summary["source"] == "r_signals").any():
        check, crosscheck_metrics = _r_input_check(summary, r_sweep)
        checks.append(check)
    metrics = {
        "grid": {**grid, "n_replicates": int(sensitivity["n_replicates"])},
        "hmm": dict(sensitivity["hmm"]),
        "correction": dict(sensitivity["correction"]),
        "interval": interval,
        "n_runs": int(len(ours_runs) // len(methods)),
        "hmm_converged_frac": float(ours_runs["converged"].mean()),
        "drmse_e1_pct_stats": numbers,
        "configurations": _config_table(summary, r_sweep, methods),
        "alpha_slopes": trends.to_dict(orient="records"),
        "r_signals_crosscheck": crosscheck_metrics,
    }
    return FigureArtifact("fig11_sensitivity", figure, metrics, checks)
