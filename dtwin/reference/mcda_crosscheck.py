"""Crosscheck of the MCDA/TOPSIS selection (paper §5, Table 1) against R's RMCDA 0.3.1 run.

Run by rule ``mcda_actions`` (``results/mcda/crosscheck.json``), reported by Fig. 10.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.artifacts import Check
from dtwin.mcda import McdaSettings, run_mcda
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.reference.loaders import load_r_fault_scenario

__all__ = ["crosscheck_mcda_legacy"]


def crosscheck_mcda_legacy(
    r_pipeline_path: str | os.PathLike,
    r_timeline: pd.DataFrame,
    mcda: Mapping[str, Any],
    dt: float,
) -> CrosscheckResult:
    """Our selection in legacy mode on R's residuals and posteriors vs R's RMCDA 0.3.1 timeline.

    Parameters
    ----------
    r_pipeline_path : path
        ``faulted_pipeline_seed11_rerun.csv`` (R's residuals and posteriors).
    r_timeline : DataFrame
        :func:`dtwin.reference.loaders.load_r_mcda_timeline` (``best``, ``action``).
    mcda : mapping
        The ``mcda`` config section (R's quirks are switched on: ``legacy_r``).
    dt : float
        Sample time, s.

    Returns
    -------
    CrosscheckResult
        One ``crosscheck`` (every raw and final action agrees); metrics ``raw_agreement``
        and ``final_agreement`` (shares of the steps).
    """
    residuals, probs = load_r_fault_scenario(r_pipeline_path)
    settings = McdaSettings.from_mapping(mcda, legacy_r=True)
    legacy = run_mcda(residuals, probs, dt, settings).timeline
    raw = float(np.mean(legacy["best"].to_numpy() == r_timeline["best"].to_numpy()))
    final = float(np.mean(legacy["action"].to_numpy() == r_timeline["action"].to_numpy()))
    agreement = {"raw_agreement": raw, "final_agreement": final}
    check = Check(
        id="legacy_matches_r_031",
        kind="crosscheck",
        statement="with R's quirks switched back on (legacy_r), our selection on R's residuals and "
        "posteriors reproduces R's RMCDA 0.3.1 timeline",
        expected="100 % of raw and final actions agree",
        observed=agreement,
        passed=raw == 1.0 and final == 1.0,
    )
    return CrosscheckResult([check], dict(agreement))
