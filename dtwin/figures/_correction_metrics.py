"""Our targeted-intervention metrics beside R's, shared by Figs. 5 and 6."""

from __future__ import annotations

from typing import Any

import pandas as pd

from dtwin.twin.wiring import RESIDUALS

__all__ = ["metrics_beside_r"]

#: Metric columns of the correction tables (ours and R's, loaded in our names).
METRIC_COLUMNS: tuple[str, ...] = (
    "rmse_before",
    "rmse_after",
    "mae_before",
    "mae_after",
    "drmse_pct",
    "dmae_pct",
)


def metrics_beside_r(metrics: pd.DataFrame, r_metrics: pd.DataFrame) -> dict[str, Any]:
    """Return our metrics per variant and channel beside R's (TargetedIntervention.R).

    Parameters
    ----------
    metrics : DataFrame
        ``results/correction/metrics.csv`` (``variant``, ``channel`` and the metrics).
    r_metrics : DataFrame
        :func:`dtwin.reference.loaders.load_r_correction_metrics` (R's table, our names).

    Returns
    -------
    dict
        ``ours`` (variant → channel → metrics), ``r`` (channel → metrics) and
        ``drmse_side_by_side`` (channel → our smoothed and causal reductions beside R's).
    """
    ours = {
        variant: group.drop(columns="variant").set_index("channel").to_dict(orient="index")
        for variant, group in metrics.groupby("variant", sort=False)
    }
    r_table = {
        row["channel"]: {key: row[key] for key in METRIC_COLUMNS}
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
