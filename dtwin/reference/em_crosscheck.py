"""Crosscheck of the HMM's EM fit (paper §4.2) against depmixS4 on R's own fault features.

Run by rule ``nominal_regimes`` (``results/regimes/crosscheck.json``), reported by Fig. 4.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from dtwin.artifacts import Check
from dtwin.fault_injection import regime_features
from dtwin.reference.columns import R_N_STATES
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.stages.regimes import fit_regimes

__all__ = ["crosscheck_r_loglik"]


def crosscheck_r_loglik(
    r_pipeline: pd.DataFrame,
    hmm: Mapping[str, Any],
    r_log_likelihood: float,
    n_states: int = R_N_STATES,
    atol: float = 1e-2,
) -> CrosscheckResult:
    """Fit our HMM to R's ten fault features and compare with depmixS4's best log-likelihood.

    Parameters
    ----------
    r_pipeline : DataFrame
        ``faulted_pipeline_seed11_rerun.csv`` (R's faulted residuals ``e0 … e4``).
    hmm : mapping
        The ``hmm`` section (starts and EM options; seed stream ``r_crosscheck_fit``).
    r_log_likelihood : float
        depmixS4's best log-likelihood on the same features (r_notes.md §11: −2115.852).
    n_states : int, default 4
        K of R's fit (whatever ``hmm.n_states`` says).
    atol : float, default 1e-2
        Allowed shortfall.

    Returns
    -------
    CrosscheckResult
        One ``crosscheck`` that our best start reaches ``r_log_likelihood − atol`` or better;
        metrics: our best and R's log-likelihood, our BIC, the number of starts reaching R's
        and every start's log-likelihood.
    """
    options = {**hmm, "n_states": n_states}
    _, fit = fit_regimes(regime_features(r_pipeline), options, "r_crosscheck_fit")
    check = Check(
        id="loglik_on_r_features_reaches_depmix",
        kind="crosscheck",
        statement=(
            f"our best of {hmm['n_restarts']} EM starts (K={n_states}) on R's ten "
            "z-scored fault features reaches depmixS4's best log-likelihood "
            "(r_notes.md §11) or better"
        ),
        expected=f">= {r_log_likelihood} - {atol:g}",
        observed=fit.log_likelihood,
        passed=bool(fit.log_likelihood >= r_log_likelihood - atol),
    )
    metrics = {
        "log_likelihood": fit.log_likelihood,
        "r_log_likelihood": r_log_likelihood,
        "bic": fit.bic,
        "n_starts_reaching_r": int(
            (fit.restarts["log_likelihood"] >= r_log_likelihood - atol).sum()
        ),
        "start_log_likelihoods": fit.restarts["log_likelihood"].tolist(),
    }
    return CrosscheckResult([check], metrics)
