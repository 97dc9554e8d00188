"""Crosscheck of the Hungarian regime matching and its scores (paper §4.4) on R's Viterbi path.

No model is fitted: R's own path is mapped, so the figure's rule runs it (Fig. 7).
"""

from __future__ import annotations

from collections.abc import Mapping

import pandas as pd

from dtwin.artifacts import Check
from dtwin.fault_injection import REGIMES
from dtwin.reference.columns import R_VITERBI_COLUMN
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.regime_matching import classification_scores, hungarian_map

__all__ = ["crosscheck_hungarian"]


def crosscheck_hungarian(
    r_pipeline: pd.DataFrame, r_confusion: pd.DataFrame, r_scores: Mapping[str, float]
) -> CrosscheckResult:
    """Map R's Viterbi path with our Hungarian matching and compare with R's results.

    Parameters
    ----------
    r_pipeline : DataFrame
        ``faulted_pipeline_seed11_rerun.csv`` (``regime``, ``viterbi_state``).
    r_confusion : DataFrame
        :func:`dtwin.reference.loaders.load_r_confusion` (predicted × actual regime).
    r_scores : mapping
        :func:`dtwin.reference.loaders.load_r_classification` (``accuracy``, ``macro_f1``,
        ``kappa``).

    Returns
    -------
    CrosscheckResult
        Two ``crosscheck`` checks: the confusion matrix equals R's exactly; accuracy,
        macro-F1 and κ equal R's printed values (4 decimals). Metrics ``r_mapping`` (R's
        states → regimes) and ``r_scores`` (our scores of R's path).
    """
    regimes = r_pipeline["regime"].to_numpy(dtype=str)
    states = r_pipeline[R_VITERBI_COLUMN].to_numpy()
    mapping = hungarian_map(states, regimes, all_regimes=REGIMES)
    scores = classification_scores(mapping.predicted, regimes, labels=REGIMES)
    reference = r_confusion.loc[list(REGIMES), list(REGIMES)]
    ours = scores.confusion.loc[list(REGIMES), list(REGIMES)]
    observed = {"accuracy": scores.accuracy, "macro_f1": scores.macro_f1, "kappa": scores.kappa}
    expected = {key: r_scores[key] for key in observed}
    checks = [
        Check(
            id="hungarian_on_r_viterbi_gives_r_confusion",
            kind="crosscheck",
            statement=(
                "our Hungarian matching of R's Viterbi path (faulted_pipeline_seed11_rerun.csv) "
                "reproduces R's confusion matrix (hungarian_confusion_K4_diag.csv) exactly"
            ),
            expected=reference.to_dict(orient="index"),
            observed=ours.to_dict(orient="index"),
            passed=bool((ours.to_numpy() == reference.to_numpy()).all()),
        ),
        Check(
            id="scores_on_r_viterbi_equal_r",
            kind="crosscheck",
            statement=(
                "accuracy, macro-F1 and Cohen's kappa of R's mapped path equal R's printed "
                "values (classification_summary_K4.csv, 4 decimals)"
            ),
            expected=expected,
            observed=observed,
            passed=all(abs(observed[k] - expected[k]) <= 5e-5 for k in expected),
        ),
    ]
    metrics = {
        "r_mapping": {f"S{k}": v for k, v in mapping.mapping.items()},
        "r_scores": observed,
    }
    return CrosscheckResult(checks, metrics)
