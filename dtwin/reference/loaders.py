"""Loaders of the authors' R outputs (``config/reference/*.csv``) in our column names.

Every loader checks that the columns it needs are present and names the missing ones.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.reference.columns import (
    R_BIC_FEATURE_COLUMNS,
    R_BIC_NOMINAL_COLUMNS,
    R_CLASSIFICATION_METRICS,
    R_CONFUSION_PREFIX,
    R_CORRECTION_METRICS,
    R_FAULTED_SURROGATE_COLUMNS,
    R_GAMMA_COLUMNS,
    R_MCDA_COUNT_COLUMNS,
    R_MCDA_TIMELINE_COLUMNS,
    R_MCDA_VERSION,
    R_N_STATES,
    R_PHYSICS_COLUMNS,
    R_SURROGATE_COLUMNS,
    R_SWEEP_COLUMNS,
    R_THETA_MODULES,
    R_VITERBI_COLUMN,
)
from dtwin.twin.wiring import RESIDUALS

__all__ = [
    "load_r_physics",
    "load_r_faulted_twin",
    "load_r_theta",
    "load_r_fault_scenario",
    "load_r_sweep",
    "load_r_correction_metrics",
    "load_r_confusion",
    "load_r_classification",
    "load_r_bic",
    "load_r_mcda_timeline",
    "load_r_mcda_counts",
]


def _read_csv(path: str | os.PathLike, required: list[str]) -> pd.DataFrame:
    table = pd.read_csv(path)
    missing = [column for column in required if column not in table.columns]
    if missing:
        raise DtwinValueError(f"{path} is missing column(s): {', '.join(missing)}")
    return table


def load_r_physics(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return R's physics signals and unfaulted surrogate signals in our column names.

    Returns
    -------
    (physics, surrogate) : tuple of DataFrame
        ``physics`` has columns ``t`` and the pipeline signals; ``surrogate`` has ``t`` and
        ``u_act, x, y_A, y_B`` (R's ARX rollouts, before any fault).
    """
    raw = _read_csv(path, [*R_PHYSICS_COLUMNS.values(), *R_SURROGATE_COLUMNS.values()])
    physics = pd.DataFrame({ours: raw[theirs] for ours, theirs in R_PHYSICS_COLUMNS.items()})
    surrogate = pd.DataFrame({"t": raw["t"]})
    for ours, theirs in R_SURROGATE_COLUMNS.items():
        surrogate[ours] = raw[theirs]
    return physics, surrogate


def load_r_faulted_twin(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame, np.ndarray]:
    """Return R's physics, its faulted surrogate streams and its smoothed state posteriors.

    Returns
    -------
    (physics, surrogate, gamma)
        ``physics`` as :func:`load_r_physics`; ``surrogate``: ``u_act, x, y_A, y_B`` of the
        fault scenario (R's faulted streams); ``gamma``: array (T, 4), R's smoothed
        posteriors ``gamma_S1 … gamma_S4`` of its fault-scenario HMM.
    """
    raw = _read_csv(
        path,
        [*R_PHYSICS_COLUMNS.values(), *R_FAULTED_SURROGATE_COLUMNS.values(), *R_GAMMA_COLUMNS],
    )
    physics = pd.DataFrame({ours: raw[theirs] for ours, theirs in R_PHYSICS_COLUMNS.items()})
    surrogate = pd.DataFrame(
        {ours: raw[theirs] for ours, theirs in R_FAULTED_SURROGATE_COLUMNS.items()}
    )
    return physics, surrogate, raw[list(R_GAMMA_COLUMNS)].to_numpy()


def load_r_theta(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Return R's fitted ARX coefficients per module (our module names), ``[a…, b…]``."""
    raw = _read_csv(path, ["module", "theta"])
    return {
        R_THETA_MODULES[label]: np.array([float(v) for v in str(text).split(";")])
        for label, text in zip(raw["module"], raw["theta"], strict=True)
    }


def load_r_fault_scenario(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return R's faulted residuals and its Hungarian-mapped regime posteriors.

    Returns
    -------
    (residuals, posteriors) : tuple of DataFrame
        ``residuals``: ``t, regime, e0 … e4`` (R's fault scenario, seed 11);
        ``posteriors``: ``p_<regime>`` per step, R's smoothed state posteriors ``gamma_S1…S4``
        summed per regime through the Hungarian map of R's Viterbi path (rows sum to 1).
    """
    from dtwin.fault_injection import REGIMES
    from dtwin.regime_matching import hungarian_map, mapped_posteriors

    gamma_columns = list(R_GAMMA_COLUMNS)
    raw = _read_csv(path, ["t", "regime", R_VITERBI_COLUMN, *RESIDUALS, *gamma_columns])
    mapping = hungarian_map(
        raw[R_VITERBI_COLUMN].to_numpy(),
        raw["regime"].to_numpy(),
        all_states=list(range(1, R_N_STATES + 1)),
    )
    probs = mapped_posteriors(raw[gamma_columns].to_numpy(), mapping)
    posteriors = pd.DataFrame({f"p_{regime}": probs[regime] for regime in REGIMES})
    return raw[["t", "regime", *RESIDUALS]].copy(), posteriors


def load_r_sweep(path: str | os.PathLike) -> pd.DataFrame:
    """Return R's 36-run sweep (``RobustnessAnalysis.R`` re-run) in our column names.

    Returns
    -------
    DataFrame
        Columns ``alpha, m_A, m_B`` and the scores of
        :class:`dtwin.sensitivity_sweep.CorrectionScore` (R's ``code`` correction, one EM start
        per configuration).
    """
    raw = _read_csv(path, list(R_SWEEP_COLUMNS))
    return raw[list(R_SWEEP_COLUMNS)].rename(columns=R_SWEEP_COLUMNS)


def load_r_correction_metrics(path: str | os.PathLike) -> pd.DataFrame:
    """Return R's targeted-intervention table (``TargetedIntervention.R``) in our names.

    Returns
    -------
    DataFrame
        ``channel`` (``e0 … e4``) and the columns of :data:`R_CORRECTION_METRICS` (RMSE and
        MAE before/after, and their reductions in %), in that order.
    """
    raw = _read_csv(path, ["channel", *R_CORRECTION_METRICS.values()])
    table = pd.DataFrame({"channel": raw["channel"]})
    for ours, theirs in R_CORRECTION_METRICS.items():
        table[ours] = raw[theirs]
    return table


def load_r_confusion(path: str | os.PathLike) -> pd.DataFrame:
    """Return R's Hungarian confusion matrix: index predicted regime, columns actual regime."""
    raw = pd.read_csv(path, index_col=0)
    return raw.rename(columns=lambda c: c.removeprefix(R_CONFUSION_PREFIX))


def load_r_classification(path: str | os.PathLike) -> dict[str, float]:
    """Return R's ``accuracy``, ``macro_f1`` and ``kappa`` (``classification_summary_K4.csv``)."""
    raw = _read_csv(path, ["metric", "value"])
    values = dict(zip(raw["metric"], raw["value"], strict=True))
    return {ours: values[theirs] for ours, theirs in R_CLASSIFICATION_METRICS.items()}


def load_r_bic(
    nominal_path: str | os.PathLike,
    features_path: str | os.PathLike,
    nominal_log_likelihood: Mapping[int | str, float] | None = None,
) -> dict[str, pd.DataFrame]:
    """Return R's BIC by K per data set (r_notes.md §6 (a) and (b)).

    Parameters
    ----------
    nominal_path, features_path : path
        ``bic_vs_K_6ch_nofault_singlefit_rerun.csv`` and
        ``bic_vs_K_10feat_faulted_multistart5.csv``.
    nominal_log_likelihood : mapping of K to float, optional
        R's nominal log-likelihood by K, which its CSV lacks (``r_numbers.yaml``,
        ``bic_nominal_log_likelihood``); added as a column where given.

    Returns
    -------
    dict of str to DataFrame
        ``nominal_residuals``: columns ``K``, ``bic`` (and ``log_likelihood`` where given;
        NaN at a K it lacks); ``fault_features``: ``K``, ``bic``, ``log_likelihood`` (the
        published diagonal-covariance runs).
    """
    tables = {}
    for name, path, columns in (
        ("nominal_residuals", nominal_path, R_BIC_NOMINAL_COLUMNS),
        ("fault_features", features_path, R_BIC_FEATURE_COLUMNS),
    ):
        raw = _read_csv(path, list(columns.values()))
        tables[name] = pd.DataFrame({ours: raw[theirs] for ours, theirs in columns.items()})
    if nominal_log_likelihood is not None:
        by_k = {int(k): float(v) for k, v in nominal_log_likelihood.items()}
        nominal = tables["nominal_residuals"]
        nominal["log_likelihood"] = [by_k.get(int(k), np.nan) for k in nominal["K"]]
    return tables


def load_r_mcda_timeline(path: str | os.PathLike) -> pd.DataFrame:
    """Return R's RMCDA 0.3.1 timeline: ``best`` (raw TOPSIS best) and ``action`` (final)."""
    raw = _read_csv(path, list(R_MCDA_TIMELINE_COLUMNS.values()))
    return pd.DataFrame({ours: raw[theirs] for ours, theirs in R_MCDA_TIMELINE_COLUMNS.items()})


def load_r_mcda_counts(path: str | os.PathLike) -> pd.DataFrame:
    """Return R's RMCDA 0.3.1 action counts after the hysteresis, per regime.

    Returns
    -------
    DataFrame
        Index ``regime``, one integer column per action (0 where R never chose it).
    """
    version, stage, regime, action, count = R_MCDA_COUNT_COLUMNS
    raw = _read_csv(path, list(R_MCDA_COUNT_COLUMNS))
    rows = raw[(raw[version].astype(str) == R_MCDA_VERSION) & (raw[stage] == "hysteresis")]
    table = rows[rows[regime] != "ALL"].pivot(index=regime, columns=action, values=count)
    return table.fillna(0).astype(int)
