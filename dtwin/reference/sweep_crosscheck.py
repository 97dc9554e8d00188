"""Crosscheck of the sensitivity sweep's inputs (paper §5, Fig. 11) against R's re-run.

The sweep's ``r_signals`` source rebuilds R's 36 configurations from R's seed-11 signals;
before the HMM, its numbers must equal R's. No model is fitted here (the sweep jobs did the
work): the figure compares the finished summary with R's table.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dtwin.artifacts import Check
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["R_INPUT_RTOL", "crosscheck_r_sweep_inputs"]

#: Relative agreement of R's pre-correction numbers rebuilt from R's signals (CSV has 12 digits).
R_INPUT_RTOL = 1e-7

#: Our summary column → the column of R's sweep (in our names) it must equal.
_COMPARED = (("rmse_e1_before_mean", "rmse_e1_before"), ("l2_before_mean", "l2_before"))


def crosscheck_r_sweep_inputs(summary: pd.DataFrame, r_sweep: pd.DataFrame) -> CrosscheckResult:
    """Compare the pre-correction numbers of the ``r_signals`` runs with R's sweep table.

    Parameters
    ----------
    summary : DataFrame
        :func:`dtwin.sensitivity_sweep.summarize_sweep` (rows of source ``r_signals``, method
        ``code``, are compared).
    r_sweep : DataFrame
        :func:`dtwin.reference.loaders.load_r_sweep`.

    Returns
    -------
    CrosscheckResult
        One ``crosscheck``; metrics ``n_configurations_compared`` and ``max_rel_dev`` (per
        compared column of R's, ``None`` when nothing was compared).
    """
    rebuilt = summary[(summary["source"] == "r_signals") & (summary["method"] == "code")]
    joined = rebuilt.merge(r_sweep, on=["alpha", "m_A", "m_B"], suffixes=("", "_r"))
    deviations = {}
    for ours, theirs in _COMPARED:
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
    return CrosscheckResult(
        [check], {"n_configurations_compared": len(joined), "max_rel_dev": deviations}
    )
