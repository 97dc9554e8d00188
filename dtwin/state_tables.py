"""Helpers over the state tables of the regime stages (no HMM import: cheap for figure rules).

A states table has ``t``, optionally ``regime``, ``state`` (Viterbi, 1 … K) and the posterior
columns ``gamma_S1 … gamma_SK`` (smoothed) and ``filtered_S1 … filtered_SK`` (filtered).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["state_labels", "posterior_matrix"]


def state_labels(n_states: int) -> list[str]:
    """Return the state labels ``S1 … SK`` (1-based, as R's ``viterbi_state`` and the paper)."""
    return [f"S{k}" for k in range(1, n_states + 1)]


def posterior_matrix(states: pd.DataFrame, prefix: str) -> np.ndarray:
    """Return the ``(T, K)`` posteriors ``<prefix>_S1 … <prefix>_SK`` of a states table."""
    columns = [c for c in states.columns if c.startswith(f"{prefix}_S")]
    columns.sort(key=lambda c: int(c.rsplit("_S", 1)[1]))
    return states[columns].to_numpy()
