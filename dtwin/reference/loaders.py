"""Loaders of the authors' R outputs (``config/reference/*.csv``) in our column names.

Every loader checks that the columns it needs are present and names the missing ones.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.reference.columns import (
    R_PHYSICS_COLUMNS,
    R_SURROGATE_COLUMNS,
    R_SWEEP_COLUMNS,
    R_THETA_MODULES,
)
from dtwin.wiring import RESIDUALS

__all__ = ["load_r_physics", "load_r_theta", "load_r_fault_scenario", "load_r_sweep"]


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

    gamma_columns = [f"gamma_S{k}" for k in range(1, 5)]
    raw = _read_csv(path, ["t", "regime", "viterbi_state", *RESIDUALS, *gamma_columns])
    mapping = hungarian_map(
        raw["viterbi_state"].to_numpy(), raw["regime"].to_numpy(), all_states=[1, 2, 3, 4]
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
