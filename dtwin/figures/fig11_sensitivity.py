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
from dtwin.figures._fig11_claims import GRID, sweep_claim_numbers, sweep_claims
from dtwin.figures._style import BAND_COLOR, PHYSICS_COLOR, SURROGATE_COLOR, apply_style
from dtwin.reference.sweep_crosscheck import crosscheck_r_sweep_inputs
from dtwin.sensitivity_sweep import alpha_trends

__all__ = ["plot_sensitivity", "fig11_sensitivity", "sweep_claim_numbers"]

#: Relative spread of e1's RMSE across configurations that still counts as "identical".
E1_IDENTICAL_RTOL = 1e-12

_METHOD_TITLES = {
    "code": "code: Viterbi state means, κ 0.6, rate 5e-4 (r_notes.md §7C)",
    "paper": "paper §4.3 values: posterior-weighted means, κ 0.8, rate 0.05",
}


def _facet_values(frame: pd.DataFrame, m_a: float, m_b: float) -> pd.DataFrame:
    return frame[(frame["m_A"] == m_a) & (frame["m_B"] == m_b)].sort_values("alpha")


def _draw_facet(
    ax: Any,
    curves: Sequence[tuple[pd.DataFrame | None, str]],
    m_a: float,
    m_b: float,
    ours_label: str,
) -> dict[str, Any]:
    """Draw one (m_A, m_B) facet: ours with its interval, ours on R's signals, R's re-run.

    ``curves`` is ``[(ours, label), (ours on R's signals or None, …), (R or None, …)]``;
    returns the legend handles drawn.
    """
    (ours, _), (on_r, on_r_label), (r_sweep, r_label) = curves
    facet = _facet_values(ours, m_a, m_b)
    handles: dict[str, Any] = {}
    handles[ours_label] = ax.errorbar(
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
    if on_r is not None and not on_r.empty:
        facet_r = _facet_values(on_r, m_a, m_b)
        (handles[on_r_label],) = ax.plot(
            facet_r["alpha"],
            facet_r["drmse_e1_mean"],
            color=SURROGATE_COLOR,
            marker="D",
            ms=3.5,
            lw=1.0,
            ls="--",
        )
    if r_sweep is not None:
        facet_rr = _facet_values(r_sweep, m_a, m_b)
        (handles[r_label],) = ax.plot(
            facet_rr["alpha"],
            facet_rr["drmse_e1_pct"],
            color=BAND_COLOR,
            marker="s",
            mfc="none",
            ms=5,
            lw=0,
        )
    return handles


def _label_facet(ax: Any, i: int, j: int, shape: tuple[int, int], m_a: float, m_b: float) -> None:
    """Column titles, row labels, the x label and the shared y label of facet (i, j)."""
    n_rows, n_cols = shape
    if i == 0:
        ax.set_title(f"Sensor B ×{m_b:g}", fontsize=9)
    if j == n_cols - 1:
        ax.yaxis.set_label_position("right")
        ax.set_ylabel(f"Sensor A ×{m_a:g}", rotation=270, labelpad=12)
    if i == n_rows - 1:
        ax.set_xlabel("fusion weight α")
    if j == 0 and i == n_rows // 2:
        ax.text(
            -0.32 if n_cols > 1 else -0.2,
            0.5,
            "ΔRMSE$_{e1}$ (%)",
            rotation=90,
            va="center",
            ha="center",
            transform=ax.transAxes,
        )


def _y_limits(summary: pd.DataFrame, r_sweep: pd.DataFrame | None) -> tuple[float, float]:
    values = summary[["drmse_e1_lo", "drmse_e1_hi"]].to_numpy().ravel()
    if r_sweep is not None:
        values = np.concatenate([values, r_sweep["drmse_e1_pct"].to_numpy()])
    low, high = float(np.nanmin(values)), float(np.nanmax(values))
    pad = 0.06 * max(high - low, 1.0)
    return low - pad, high + pad


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
    y_limits = _y_limits(summary, r_sweep)
    ours_label = (
        "ours (numpy draws)"
        if n_rep == 1
        else (f"ours: mean of {n_rep} replicates, {interval:.0%} interval")
    )
    handles: dict[str, Any] = {}
    for panel, method in zip(panels, methods, strict=True):
        axes = panel.subplots(len(mults_a), len(mults_b), sharex=True, sharey=True, squeeze=False)
        curves = [
            (summary[(summary["source"] == "ours") & (summary["method"] == method)], ""),
            (
                summary[(summary["source"] == "r_signals") & (summary["method"] == method)],
                "our HMM on R's exact signals",
            ),
            (
                r_sweep if method == "code" else None,
                "R re-run (1 EM start per configuration)",
            ),
        ]
        for i, m_a in enumerate(mults_a):
            for j, m_b in enumerate(mults_b):
                ax = axes[i, j]
                handles.update(_draw_facet(ax, curves, m_a, m_b, ours_label))
                ax.set_ylim(*y_limits)
                ax.set_xticks(alphas)
                ax.axhline(0, color="#999999", lw=0.5)
                _label_facet(ax, i, j, axes.shape, m_a, m_b)
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
            part = part[[*GRID, *columns]].rename(columns=columns)
            wide = part if wide is None else wide.merge(part, on=GRID, how="outer")
    if r_sweep is not None:
        r_part = r_sweep[[*GRID, "drmse_e1_pct", "dmae_e1_pct", "dl2_pct"]].rename(
            columns={
                "drmse_e1_pct": "r_rerun_drmse_e1_pct",
                "dmae_e1_pct": "r_rerun_dmae_e1_pct",
                "dl2_pct": "r_rerun_dl2_pct",
            }
        )
        wide = wide.merge(r_part, on=GRID, how="left")
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
            means = part[GRID].assign(value=part["drmse_e1_mean"])
            numbers[m][source] = sweep_claim_numbers(means, slopes)
    r_means = r_sweep[GRID].assign(value=r_sweep["drmse_e1_pct"])
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
        *sweep_claims(numbers[method], grid["alpha"], grid),
    ]
    crosscheck_metrics = None
    if (summary["source"] == "r_signals").any():
        crosscheck = crosscheck_r_sweep_inputs(summary, r_sweep)
        checks += crosscheck.checks
        crosscheck_metrics = crosscheck.metrics
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
