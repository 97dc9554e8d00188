"""Crosscheck of the BIC formula (paper §5, Eq. (26)) on R's own log-likelihoods.

No model is fitted (R's log-likelihoods are given), so the figure's rule runs it (Fig. 9).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import pandas as pd

from dtwin.artifacts import Check
from dtwin.hmm_basics import n_hmm_params
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["crosscheck_bic_formula"]

#: Features per data set of R's two BIC experiments (r_notes.md §6 (a) and (b)).
R_BIC_N_FEATURES: dict[str, int] = {"nominal_residuals": 6, "fault_features": 10}


def crosscheck_bic_formula(
    r_tables: Mapping[str, pd.DataFrame],
    r_nominal_log_likelihood: Mapping[int | str, float],
    n_samples: int = 1000,
    atol: float = 0.05,
) -> CrosscheckResult:
    """Turn R's log-likelihoods into BIC with our parameter count and compare with R's BIC.

    Parameters
    ----------
    r_tables : mapping of str to DataFrame
        :func:`dtwin.reference.loaders.load_r_bic` (``K``, ``bic``; the fault features also
        ``log_likelihood``).
    r_nominal_log_likelihood : mapping
        R's log-likelihood per K of the nominal run (``r_numbers.yaml``, not in its table).
    n_samples : int, default 1000
        Samples of R's runs (n of the BIC).
    atol : float, default 0.05
        Allowed absolute deviation (R prints 0.1 / 3-decimal log-likelihoods).

    Returns
    -------
    CrosscheckResult
        One ``crosscheck``; metrics: the largest absolute BIC deviation per data set.
    """
    features = r_tables["fault_features"]
    log_likelihoods = {
        "nominal_residuals": {int(k): v for k, v in r_nominal_log_likelihood.items()},
        "fault_features": dict(zip(features["K"], features["log_likelihood"], strict=True)),
    }
    formula_dev = {}
    for name, n_features in R_BIC_N_FEATURES.items():
        r, loglik = r_tables[name], log_likelihoods[name]
        ours = {
            int(k): -2 * loglik[int(k)] + n_hmm_params(int(k), n_features) * math.log(n_samples)
            for k in r["K"]
        }
        formula_dev[name] = float(
            max(abs(ours[int(k)] - b) for k, b in zip(r["K"], r["bic"], strict=True))
        )
    check = Check(
        id="bic_formula_matches_r",
        kind="crosscheck",
        statement=(
            "our parameter count p = (K-1) + K(K-1) + 2DK and BIC = -2 log L + p log n, "
            "applied to R's log-likelihoods (n = 1000), give R's printed BIC values"
        ),
        expected="max |deviation| <= 0.05 (R prints 0.1 / 3-decimal log-likelihoods)",
        observed=formula_dev,
        passed=all(dev <= atol for dev in formula_dev.values()),
    )
    return CrosscheckResult([check], formula_dev)
