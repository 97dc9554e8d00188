"""Paper Fig. 10: TOPSIS-selected action over time, over the true regimes."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from dtwin.artifacts import Check, FigureArtifact, validity_finite
from dtwin.figures._style import PHYSICS_COLOR, apply_style, regime_spans, shade_regimes
from dtwin.mcda import ACTIONS, NO_ACTION
from dtwin.reference.columns import R_MCDA_VERSION
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["fig10_mcda_actions", "plot_mcda_actions"]

ACTION_ORDER = [NO_ACTION, *(a.name for a in ACTIONS)]


def plot_mcda_actions(timeline: pd.DataFrame) -> Figure:
    """Actions over time (top) and decision confidence (bottom), true regimes shaded.

    ``timeline`` has columns ``t`` (s), ``regime``, ``action``, ``confidence``, ``gate``.
    """
    apply_style()
    figure, (ax_action, ax_conf) = plt.subplots(
        2, 1, figsize=(11, 6), sharex=True, height_ratios=[3, 1.2]
    )
    t = timeline["t"].to_numpy()
    regimes = timeline["regime"].to_numpy()
    spans = regime_spans(t, regimes)
    for ax in (ax_action, ax_conf):
        shade_regimes(ax, spans, alpha=0.15)
    for regime, start, end in spans:
        ax_action.text(
            (start + end) / 2,
            1.01,
            regime,
            transform=ax_action.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=8,
        )
    levels = {name: index for index, name in enumerate(ACTION_ORDER)}
    y = timeline["action"].map(levels).to_numpy()
    ax_action.scatter(
        t, y, s=6, color=PHYSICS_COLOR, zorder=3, label="selected (after dwell/margin)"
    )
    best = timeline["best"].map(levels).to_numpy()
    ax_action.scatter(
        t, best + 0.18, s=2, color="#999999", zorder=2, label="raw TOPSIS best / gate"
    )
    ax_action.set_yticks(range(len(ACTION_ORDER)), ACTION_ORDER)
    ax_action.set_ylim(-0.6, len(ACTION_ORDER) - 0.4)
    ax_action.set_ylabel("action")
    ax_action.legend(loc="lower right", fontsize=8, frameon=True)
    ax_action.set_title("TOPSIS-selected action over the true regimes (paper Fig. 10)", pad=16)
    ax_conf.plot(t, timeline["confidence"], color=PHYSICS_COLOR, lw=0.8)
    ax_conf.set_ylabel("confidence\n(best − 2nd)")
    ax_conf.set_xlabel("time (s)")
    figure.tight_layout()
    return figure


def _mostly(counts: pd.DataFrame, regime: str, action: str) -> tuple[float, bool]:
    row = counts.loc[regime] if regime in counts.index else pd.Series(dtype=float)
    share = float(row.get(action, 0) / row.sum()) if row.sum() else 0.0
    return share, bool(row.sum() and row.idxmax() == action)


def fig10_mcda_actions(
    timeline: pd.DataFrame,
    mcda: Mapping[str, Any],
    dt: float,
    r_table: pd.DataFrame,
    crosscheck: CrosscheckResult,
) -> FigureArtifact:
    """Paper Fig. 10 with action counts per regime, the limitation fixes, and the R crosscheck.

    Parameters
    ----------
    timeline : DataFrame
        ``results/mcda/actions.csv``.
    mcda : mapping
        The ``mcda`` config section (dwell and weights).
    dt : float
        Sample time, s.
    r_table : DataFrame
        R's RMCDA 0.3.1 counts per regime and action
        (:func:`dtwin.reference.loaders.load_r_mcda_counts`).
    crosscheck : CrosscheckResult
        ``results/mcda/crosscheck.json`` (legacy mode on R's inputs vs R's timeline).
    """
    figure = plot_mcda_actions(timeline)
    counts = pd.crosstab(timeline["regime"], timeline["action"])
    actions = timeline["action"].to_numpy()
    after_action = np.flatnonzero(actions != NO_ACTION)
    returns = int(np.sum((actions[1:] == NO_ACTION) & (actions[:-1] != NO_ACTION)))
    checks = [
        validity_finite("scores_finite", "TOPSIS closeness scores", timeline.filter(like="score_")),
        Check(
            id="one_action_per_step",
            kind="validity",
            statement="every step has exactly one known action",
            expected=sorted(ACTION_ORDER),
            observed=sorted(set(actions)),
            passed=set(actions) <= set(ACTION_ORDER) and len(actions) == len(timeline),
        ),
    ]
    for regime, action in (("DynamicsOff", "ReidentifyPlant"), ("Drift", "BiasCorrect")):
        share, is_mode = _mostly(counts, regime, action)
        r_share, _ = _mostly(r_table, regime, action)
        r_words = f"R with RMCDA {R_MCDA_VERSION}: {r_share:.1%}"
        checks.append(
            Check(
                id=f"{regime}_mostly_{action}",
                kind="claim",
                statement=f"paper §5: {regime} steps are mostly {action} ({r_words})",
                expected=f"{action} is the most frequent action in {regime}",
                observed=round(share, 4),
                passed=is_mode,
                reference=round(r_share, 4),
            )
        )
    checks += [
        Check(
            id="noaction_reachable_after_action",
            kind="validity",
            statement="fix of a paper limitation: once the dwell has elapsed, a gated step is "
            "NoAction even after an action (in R it could never return)",
            expected="0 gated steps past the dwell that keep an action",
            observed=_gate_violations(timeline, round(mcda["min_dwell_sec"] / dt)),
            passed=_gate_violations(timeline, round(mcda["min_dwell_sec"] / dt)) == 0,
        ),
        *crosscheck.checks,
    ]
    metrics = {
        "counts_per_action": timeline["action"].value_counts().sort_index().to_dict(),
        "counts_per_regime": {r: row[row > 0].to_dict() for r, row in counts.iterrows()},
        "r_031_counts_per_regime": {r: row[row > 0].to_dict() for r, row in r_table.iterrows()},
        "n_degenerate_steps": int(timeline["degenerate"].sum()),
        "degenerate_rule": "an all-zero criterion column is normalised to 0 (no information); "
        "R set NaN scores to 0 and gave the step to the first action",
        "n_switches": int(np.sum(actions[1:] != actions[:-1])),
        "n_returns_to_noaction": returns,
        "first_action_step": int(after_action[0]) if len(after_action) else None,
        "n_gated_steps": int(timeline["gate"].sum()),
        "confidence_median": float(timeline["confidence"].median()),
        "weights": dict(mcda["weights"]),
    }
    return FigureArtifact("fig10_mcda_actions", figure, metrics, checks)


def _gate_violations(timeline: pd.DataFrame, dwell: int) -> int:
    """Gated steps, more than ``dwell`` steps after the last switch, that keep an action."""
    actions = timeline["action"].to_numpy()
    gate = timeline["gate"].to_numpy(dtype=bool)
    since_switch, violations = 0, 0
    for step in range(1, len(actions)):
        since_switch = 0 if actions[step] != actions[step - 1] else since_switch + 1
        if gate[step] and actions[step] != NO_ACTION and since_switch > dwell:
            violations += 1
    return violations
