"""The parts of the Gaussian HMM that need no EM engine (paper §4.2, Eq. (26)).

Z-scoring of the residual features (R's ``scale``) and the free-parameter count of BIC live
here, numpy and pandas only, so the figures and crosschecks that need them do not import
hmmlearn and scikit-learn (~1.5 s per process); :mod:`dtwin.hmm` re-exports both. Arrays are
time-first ``(T, D)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinTypeError, DtwinValueError, require_finite_array

__all__ = ["ZScored", "n_hmm_params", "zscore"]


# --- z-scoring ------------------------------------------------------------------------------


@dataclass(frozen=True)
class ZScored:
    """Column-wise z-scored features (R's ``scale``: mean and sample sd, ``ddof=1``).

    Attributes
    ----------
    values : ndarray, shape (T, D)
        ``(features − mean) / sd``.
    mean, sd : ndarray, shape (D,)
        Column means and sample standard deviations, in the features' units.
    columns : tuple of str
        Column names (the DataFrame's columns, or ``"0"``, ``"1"``, … for arrays).
    """

    values: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    columns: tuple[str, ...]

    def transform(self, features: Any) -> np.ndarray:
        """Return new ``features`` (shape ``(T', D)``) scaled with this mean and sd."""
        array = require_finite_array("features", features, ndim=2)
        if array.shape[1] != len(self.mean):
            raise DtwinValueError(
                f"features must have {len(self.mean)} columns (got {array.shape[1]})"
            )
        return (array - self.mean) / self.sd

    def to_frame(self) -> pd.DataFrame:
        """Return :attr:`values` as a DataFrame with :attr:`columns`."""
        return pd.DataFrame(self.values, columns=list(self.columns))


def _column_label(columns: Sequence[str], index: int, named: bool) -> str:
    return f"column {columns[index]!r} (index {index})" if named else f"column {index}"


def zscore(features: Any) -> ZScored:
    """Return the column-wise z-scores of ``features`` (R's ``scale``).

    Parameters
    ----------
    features : array-like or DataFrame, shape (T, D)
        One row per sample, one column per feature; at least 2 rows.

    Returns
    -------
    ZScored
        Scaled values, the column means and sample standard deviations (``ddof=1``).

    Raises
    ------
    DtwinValueError
        If a column holds NaN/inf or has zero variance (the message names the column).

    Examples
    --------
    >>> z = zscore(np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0]]))
    >>> z.values[:, 0].tolist(), z.sd.tolist()
    ([-1.0, 0.0, 1.0], [1.0, 10.0])
    """
    named = isinstance(features, pd.DataFrame)
    if named:
        columns = tuple(str(c) for c in features.columns)
        raw = features.to_numpy()
    else:
        raw = features
    try:
        array = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as error:
        raise DtwinTypeError(f"features must be numeric (got {type(features).__name__})") from error
    if array.ndim != 2:
        raise DtwinValueError(f"features must be 2-dimensional (T, D) (got shape {array.shape})")
    if not named:
        columns = tuple(str(i) for i in range(array.shape[1]))
    if array.shape[0] < 2:
        raise DtwinValueError(f"features must have at least 2 rows (got {array.shape[0]})")
    bad = ~np.isfinite(array)
    for j in np.flatnonzero(bad.any(axis=0)):
        rows = np.flatnonzero(bad[:, j])
        raise DtwinValueError(
            f"features {_column_label(columns, j, named)} must be finite "
            f"(got {len(rows)} NaN/inf values, first at row {rows[0]})"
        )
    mean = array.mean(axis=0)
    sd = array.std(axis=0, ddof=1)
    for j in range(array.shape[1]):
        if sd[j] <= 1e-12 * max(1.0, abs(mean[j])):
            raise DtwinValueError(
                f"features {_column_label(columns, j, named)} must have non-zero variance "
                f"(got sd {sd[j]:.3g} around mean {mean[j]:.6g}); z-scoring would divide by zero"
            )
    return ZScored(values=(array - mean) / sd, mean=mean, sd=sd, columns=columns)


def n_hmm_params(n_states: int, n_features: int) -> int:
    """Return the free-parameter count ``(K−1) + K(K−1) + 2·D·K`` of a diagonal Gaussian HMM.

    Examples
    --------
    >>> n_hmm_params(4, 10)
    95
    """
    return (n_states - 1) + n_states * (n_states - 1) + 2 * n_features * n_states
