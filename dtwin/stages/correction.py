"""Stage "correction" (paper §4.3; Figs. 5, 6): the targeted intervention on the fault scenario.

What the authors' ``TargetedIntervention.R`` does (r_notes.md §7A): the faulted surrogate
streams are corrected with the posterior-weighted state bias of the fault-scenario HMM
(:func:`dtwin.bias_correction.correct_bias`), and the residuals before and after are compared. Two
variants are computed:

- ``smoothed``: the paper's correction, with ``γ_t = P(S_t | e_1:T)`` (it looks ahead);
- ``filtered``: the same state means ``μ_kj`` (learned offline from the smoothed fit), but the
  bias at t uses only ``P(S_t | e_1:t)``, which is what a live twin can do.

Figures of this stage live in :mod:`dtwin.figures.fig05_correction_timeseries` and
:mod:`dtwin.figures.fig06_correction_distributions`. Config sections: ``correction`` and the
``dt``/``fusion``/``kpi`` keys of ``twin``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.artifacts import Check
from dtwin.bias_correction import BiasCorrection, correct_bias
from dtwin.reference.loaders import load_r_physics
from dtwin.stages._states import posterior_matrix
from dtwin.wiring import RESIDUALS

__all__ = [
    "VARIANTS",
    "correct_twin",
    "targeted_intervention",
    "R_METRIC_COLUMNS",
    "crosscheck_correction",
    "metrics_beside_r",
]

#: Correction variants: which posteriors weight the state means.
VARIANTS: tuple[str, ...] = ("smoothed", "filtered")

#: Our metric column → column of R's ``targeted_intervention_metrics_rerun.csv``.
R_METRIC_COLUMNS: dict[str, str] = {
    "rmse_before": "RMSE_Original",
    "rmse_after": "RMSE_Corrected",
    "mae_before": "MAE_Original",
    "mae_after": "MAE_Corrected",
    "drmse_pct": "dRMSE_pct",
    "dmae_pct": "dMAE_pct",
}


def correct_twin(
    surrogate: pd.DataFrame,
    physics: pd.DataFrame,
    posteriors: np.ndarray,
    twin: Mapping[str, Any],
    correction: Mapping[str, Any],
    state_means: np.ndarray | None = None,
) -> BiasCorrection:
    """:func:`dtwin.bias_correction.correct_bias` with the ``twin`` and ``correction`` sections."""
    return correct_bias(
        surrogate,
        physics,
        posteriors,
        alpha=twin["fusion"]["alpha"],
        w1=twin["kpi"]["w1"],
        w2=twin["kpi"]["w2"],
        dt=twin["dt"],
        kappa=correction["kappa"],
        ema_alpha=correction["ema_alpha"],
        rate_max=correction["rate_max"],
        state_means=state_means,
    )


def targeted_intervention(
    physics: pd.DataFrame,
    faulted: pd.DataFrame,
    states: pd.DataFrame,
    twin: Mapping[str, Any],
    correction: Mapping[str, Any],
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Correct the faulted twin with smoothed and with filtered posteriors (paper §4.3).

    Parameters
    ----------
    physics : DataFrame
        Physics signals (``t``, ``u_act``, ``x``, ``y_A``, ``y_B``, ``y_fused``, ``z``).
    faulted : DataFrame
        Faulted surrogate streams of the fault scenario (``t``, ``regime``, ``u_act``, ``x``,
        ``y_A``, ``y_B``).
    states : DataFrame
        The fault fit's states table (``gamma_S*`` smoothed, ``filtered_S*`` filtered).
    twin : mapping
        ``dt``, ``fusion``, ``kpi`` of the ``twin`` section.
    correction : mapping
        The ``correction`` section: ``kappa``, ``ema_alpha``, ``rate_max``.

    Returns
    -------
    (residuals, metrics)
        ``residuals``: ``t``, ``regime``, then ``<e>_before``, ``<e>_smoothed`` and
        ``<e>_filtered`` for every residual channel ``e`` (physical units);
        ``metrics``: one row per variant and channel with the columns of
        :attr:`dtwin.bias_correction.BiasCorrection.metrics` (``variant`` first).
    """
    smoothed = correct_twin(faulted, physics, posterior_matrix(states, "gamma"), twin, correction)
    filtered = correct_twin(
        faulted,
        physics,
        posterior_matrix(states, "filtered"),
        twin,
        correction,
        state_means=smoothed.state_means.to_numpy(),
    )
    residuals = pd.DataFrame({"t": faulted["t"].to_numpy(), "regime": faulted["regime"]})
    for e in RESIDUALS:
        residuals[f"{e}_before"] = smoothed.residuals_before[e].to_numpy()
        residuals[f"{e}_smoothed"] = smoothed.residuals_after[e].to_numpy()
        residuals[f"{e}_filtered"] = filtered.residuals_after[e].to_numpy()
    metrics = pd.concat(
        [
            result.metrics.assign(variant=variant)
            for variant, result in zip(VARIANTS, (smoothed, filtered), strict=True)
        ],
        ignore_index=True,
    )
    metrics = metrics[["variant", *(c for c in metrics.columns if c != "variant")]]
    return residuals, metrics


def crosscheck_correction(
    r_pipeline_path: str,
    r_metrics: pd.DataFrame,
    twin: Mapping[str, Any],
    correction: Mapping[str, Any],
    rtol: float = 1e-6,
) -> tuple[Check, dict[str, float]]:
    """Run our correction on R's faulted signals and posteriors; compare with R's table.

    Parameters
    ----------
    r_pipeline_path : path
        ``faulted_pipeline_seed11_rerun.csv``: R's physics, faulted surrogate streams and
        smoothed posteriors ``gamma_S1 … gamma_S4``.
    r_metrics : DataFrame
        ``targeted_intervention_metrics_rerun.csv``.
    twin, correction : mapping
        As :func:`targeted_intervention`.
    rtol : float, default 1e-6
        Allowed relative deviation of every number of the table.

    Returns
    -------
    (Check, deviations)
        A ``crosscheck`` and the largest relative deviation per metric column.
    """
    raw = pd.read_csv(r_pipeline_path)
    physics, _ = load_r_physics(r_pipeline_path)
    surrogate = pd.DataFrame(
        {
            "u_act": raw["u_act_A"],
            "x": raw["xpos_A_fault"],
            "y_A": raw["yA_A_fault"],
            "y_B": raw["yB_A_fault"],
        }
    )
    result = correct_twin(surrogate, physics, posterior_matrix(raw, "gamma"), twin, correction)
    ours = result.metrics.set_index("channel").loc[list(r_metrics["channel"])]
    deviations = {
        column: float(
            np.max(
                np.abs(ours[column].to_numpy() - r_metrics[r_column].to_numpy())
                / np.abs(r_metrics[r_column].to_numpy())
            )
        )
        for column, r_column in R_METRIC_COLUMNS.items()
    }
    check = Check(
        id="correction_on_r_signals_gives_r_table",
        kind="crosscheck",
        statement=(
            "our correction of R's faulted surrogate streams with R's smoothed posteriors "
            "reproduces R's RMSE/MAE table (targeted_intervention_metrics_rerun.csv)"
        ),
        expected=f"relative deviation <= {rtol:g} in every column",
        observed=deviations,
        passed=all(dev <= rtol for dev in deviations.values()),
    )
    return check, deviations


def metrics_beside_r(metrics: pd.DataFrame, r_metrics: pd.DataFrame) -> dict[str, Any]:
    """Return our metrics per variant and channel beside R's (TargetedIntervention.R)."""
    ours = {
        variant: group.drop(columns="variant").set_index("channel").to_dict(orient="index")
        for variant, group in metrics.groupby("variant", sort=False)
    }
    r_table = {
        row["channel"]: {ours_key: row[r_key] for ours_key, r_key in R_METRIC_COLUMNS.items()}
        for row in r_metrics.to_dict(orient="records")
    }
    smoothed = ours["smoothed"]
    side_by_side = {
        e: {
            "drmse_pct": smoothed[e]["drmse_pct"],
            "drmse_pct_causal": ours["filtered"][e]["drmse_pct"],
            "r_drmse_pct": r_table[e]["drmse_pct"],
            "dmae_pct": smoothed[e]["dmae_pct"],
            "r_dmae_pct": r_table[e]["dmae_pct"],
        }
        for e in RESIDUALS
    }
    return {"ours": ours, "r": r_table, "drmse_side_by_side": side_by_side}
