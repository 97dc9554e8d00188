"""Crosscheck of the targeted intervention (paper §4.3) on R's faulted signals and posteriors.

Run by rule ``targeted_intervention`` (``results/correction/crosscheck.json``), reported by
Fig. 5.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.artifacts import Check
from dtwin.reference.columns import R_CORRECTION_METRICS
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.reference.loaders import load_r_faulted_twin
from dtwin.stages.correction import correct_twin

__all__ = ["crosscheck_correction"]


def crosscheck_correction(
    r_pipeline_path: str | os.PathLike,
    r_metrics: pd.DataFrame,
    twin: Mapping[str, Any],
    correction: Mapping[str, Any],
    rtol: float = 1e-6,
) -> CrosscheckResult:
    """Run our correction on R's faulted signals and posteriors; compare with R's table.

    Parameters
    ----------
    r_pipeline_path : path
        ``faulted_pipeline_seed11_rerun.csv``: R's physics, faulted surrogate streams and
        smoothed posteriors ``gamma_S1 … gamma_S4``.
    r_metrics : DataFrame
        :func:`dtwin.reference.loaders.load_r_correction_metrics`.
    twin, correction : mapping
        As :func:`dtwin.stages.correction.targeted_intervention`.
    rtol : float, default 1e-6
        Allowed relative deviation of every number of the table.

    Returns
    -------
    CrosscheckResult
        One ``crosscheck``; metrics: the largest relative deviation per metric column.
    """
    physics, surrogate, gamma = load_r_faulted_twin(r_pipeline_path)
    result = correct_twin(surrogate, physics, gamma, twin, correction)
    ours = result.metrics.set_index("channel").loc[list(r_metrics["channel"])]
    deviations = {
        column: float(
            np.max(
                np.abs(ours[column].to_numpy() - r_metrics[column].to_numpy())
                / np.abs(r_metrics[column].to_numpy())
            )
        )
        for column in R_CORRECTION_METRICS
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
    return CrosscheckResult([check], deviations)
