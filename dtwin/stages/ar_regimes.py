"""Stage "ar_regimes" (paper §5, future work): the AR(1)-emission HMM on the fault features.

The paper's Gaussian HMM (i.i.d. emissions) chooses K = 8–9 by BIC on the fault features and
maps its K = 4 states to the four injected regimes. Its §5 names a switching autoregressive
emission as the natural extension for residuals this autocorrelated. This stage fits
:func:`dtwin.hmm_ar.fit_ar_hmm` to the same z-scored features (``results/faults/
residuals.csv`` → :func:`dtwin.fault_injection.regime_features`) for every K of a BIC sweep
(extended until its minimum is bracketed) and scores every K's Viterbi path against the
injected regimes (Hungarian, as Fig. 7). The Gaussian HMM stays the paper's default
everywhere else. Figure: :mod:`dtwin.figures.fig13_ar_hmm`. Config section: ``ar_hmm``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.config_sections import ArHmmSettings
from dtwin.fault_injection import REGIMES, regime_features
from dtwin.hmm import zscore
from dtwin.hmm_ar import ArHmmFit, ar_bic_by_k
from dtwin.regime_matching import classification_scores, hungarian_map

__all__ = ["score_ar_fit", "ar_regime_sweep"]

logger = logging.getLogger(__name__)


def score_ar_fit(fit: ArHmmFit, regimes: Any) -> dict[str, Any]:
    """Map the Viterbi states of ``fit`` to ``regimes`` by maximum overlap and score them.

    Returns ``accuracy``, ``macro_f1``, ``kappa`` (Eqs. (11)–(18); states beyond the number
    of regimes stay unmatched and count as errors) and ``mapping`` (state label ``S1 …`` →
    regime).
    """
    regimes = np.asarray(regimes, dtype=str)
    states = list(range(1, fit.n_states + 1))
    mapping = hungarian_map(fit.viterbi + 1, regimes, all_states=states, all_regimes=REGIMES)
    scores = classification_scores(mapping.predicted, regimes, labels=REGIMES)
    return {
        "accuracy": scores.accuracy,
        "macro_f1": scores.macro_f1,
        "kappa": scores.kappa,
        "mapping": {f"S{state}": regime for state, regime in mapping.mapping.items()},
    }


def _state_dynamics(fit: ArHmmFit, mapping: Mapping[str, str], columns: list[str]) -> dict:
    """Per mapped state: its regime, AR coefficients and innovation sds by feature."""
    return {
        f"S{k + 1}": {
            "regime": mapping[f"S{k + 1}"],
            "coefs": dict(zip(columns, fit.coefs[k].round(6).tolist(), strict=True)),
            "sds": dict(zip(columns, fit.sds[k].round(6).tolist(), strict=True)),
            "median_abs_coef": float(np.median(np.abs(fit.coefs[k]))),
            "occupancy": float(fit.smoothed[:, k].sum()),
        }
        for k in range(fit.n_states)
    }


def ar_regime_sweep(
    residuals: pd.DataFrame, ar_hmm: ArHmmSettings | Mapping[str, Any], n_states: int
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Fit the AR(1)-HMM for every K of the sweep to the fault features; score every K.

    Parameters
    ----------
    residuals : DataFrame
        The fault scenario's residuals: ``regime`` and ``e0 … e4`` (``results/faults/
        residuals.csv``).
    ar_hmm : ArHmmSettings or mapping
        The ``ar_hmm`` config section (:class:`dtwin.config_sections.ArHmmSettings`).
    n_states : int
        The paper's K (``hmm.n_states``, 4): the number of injected regimes, whose fit is
        described state by state.

    Returns
    -------
    (table, summary)
        ``table``: one row per K, the columns of :func:`dtwin.hmm.bic_row` (``n_params`` =
        ``(K−1) + K(K−1) + 3DK``) plus ``accuracy``, ``macro_f1``, ``kappa`` of that K's
        Viterbi path. ``summary``: settings, data size, ``k_star`` (BIC minimum),
        ``bracketed``, and at ``n_states`` the scores, mapping and per-state dynamics.
    """
    settings = ArHmmSettings.from_mapping(ar_hmm)
    if "regime" not in residuals:
        raise DtwinValueError(
            "residuals must have a 'regime' column (results/faults/residuals.csv)"
        )
    features = regime_features(residuals)
    regimes = residuals["regime"].to_numpy(dtype=str)
    X = zscore(features).values
    start = time.perf_counter()
    ks = sorted(set(settings.ks) | {int(n_states)})
    sweep = ar_bic_by_k(
        X,
        ks,
        n_restarts=settings.n_restarts,
        seed=settings.seed,
        k_max=settings.k_max,
        stop_after_rises=settings.stop_after_rises,
        max_iter=settings.max_iter,
        tol=settings.tol,
        var_floor=settings.var_floor,
        engine=settings.engine,
    )
    scores = {k: score_ar_fit(fit, regimes) for k, fit in sweep.fits.items()}
    table = sweep.table.copy()
    for key in ("accuracy", "macro_f1", "kappa"):
        table[key] = [scores[k][key] for k in table["K"]]
    k_star = int(table.loc[table["bic"].idxmin(), "K"])
    logger.info(
        "AR-HMM sweep K=%s in %.1f s; K*=%d",
        table["K"].tolist(),
        time.perf_counter() - start,
        k_star,
    )
    fit = sweep.fits[int(n_states)]
    summary = {
        "settings": settings.summary(),
        "dataset": "fault_features",
        "features": list(features.columns),
        "n_samples": len(X),
        "k_star": k_star,
        "bracketed": k_star < int(table["K"].max()) - 1,
        "n_states": int(n_states),
        "at_n_states": {
            **scores[int(n_states)],
            "log_likelihood": fit.log_likelihood,
            "states": _state_dynamics(
                fit, scores[int(n_states)]["mapping"], list(features.columns)
            ),
        },
        "at_k_star": scores[k_star],
    }
    return table, summary
