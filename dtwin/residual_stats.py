"""Is the twin's error structured? Residual ACF and Ljung–Box tests (paper §4.1, Fig. 3).

Tables with one column per residual channel and the white-noise band ``±1.96/√n`` the paper
draws. The sample ACF and the Ljung–Box statistic are statsmodels' (``acf(x, fft=False)``,
``acorr_ljungbox``) written out in numpy with the same operations, so a figure job does not load
statsmodels (~1 s per process); tests/concepts/test_residual_stats.py holds them equal to
statsmodels'.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy.special import chdtrc

from dtwin._ljung_box import ljung_box_statistic
from dtwin._validation import DtwinValueError, require_finite_array, require_min_length

__all__ = ["white_noise_band", "sample_acf", "ljung_box", "acf_table", "ljung_box_table"]


def white_noise_band(n_samples: int) -> float:
    """Return the 95 % white-noise band half-width ``1.96/√n`` of a sample ACF."""
    if n_samples < 1:
        raise DtwinValueError(f"n_samples must be >= 1 (got {n_samples})")
    return 1.96 / np.sqrt(n_samples)


def _channel(table: pd.DataFrame, name: str, nlags: int) -> np.ndarray:
    if name not in table.columns:
        raise DtwinValueError(f"residual table has no column {name!r}")
    values = require_finite_array(name, table[name].to_numpy())
    require_min_length(name, values, nlags + 2)
    if np.ptp(values) == 0:
        raise DtwinValueError(f"{name} is constant; its autocorrelation is undefined")
    return values


def sample_acf(values: np.ndarray, nlags: int) -> np.ndarray:
    """Return the sample ACF of ``values`` at lags ``0 … nlags``, shape ``(nlags + 1,)``.

    The autocovariance of the demeaned series divided by n (R's ``acf``, statsmodels'
    ``acf(x, fft=False)``), over its value at lag 0.

    Examples
    --------
    >>> sample_acf(np.array([1.0, 2.0, 3.0, 4.0]), 2).round(3).tolist()
    [1.0, 0.25, -0.3]
    """
    demeaned = values - values.mean()
    n = len(values)
    autocovariance = np.correlate(demeaned, demeaned, "full")[n - 1 :] / (n * np.ones(n))
    return autocovariance[: nlags + 1] / autocovariance[0]


def ljung_box(values: np.ndarray, lags: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Return the Ljung–Box Q statistic and its p-value at each of ``lags``.

    ``Q(h) = n (n + 2) Σ_{k=1..h} r_k² / (n − k)`` with ``r_k`` the sample ACF
    (:func:`sample_acf`, :func:`dtwin._ljung_box.ljung_box_statistic`); the p-value is the upper
    tail of a χ² with ``h`` degrees of freedom.
    """
    lags = np.asarray(lags, dtype=int)
    q = ljung_box_statistic(sample_acf(values, int(lags.max())), len(values))[lags - 1]
    return q, chdtrc(lags, q)


def acf_table(table: pd.DataFrame, channels: Sequence[str], nlags: int) -> pd.DataFrame:
    """Return the sample ACF of each channel for lags ``0 … nlags``.

    Parameters
    ----------
    table : DataFrame
        One row per sample; the channels as columns.
    channels : sequence of str
        Columns to analyse (e.g. ``e0 … e4``).
    nlags : int
        Largest lag.

    Returns
    -------
    DataFrame
        Column ``lag`` and one column per channel; the estimator divides by n (R's ``acf``).

    Examples
    --------
    >>> x = pd.DataFrame({"a": np.sin(np.arange(200) / 5.0)})
    >>> float(acf_table(x, ["a"], 3)["a"].iloc[0])
    1.0
    """
    result = pd.DataFrame({"lag": np.arange(nlags + 1)})
    for name in channels:
        result[name] = sample_acf(_channel(table, name, nlags), nlags)
    return result


def ljung_box_table(
    table: pd.DataFrame, channels: Sequence[str], lags: Sequence[int]
) -> pd.DataFrame:
    """Return Ljung–Box Q statistics and p-values per channel and lag.

    Returns
    -------
    DataFrame
        Columns ``channel``, ``lag``, ``lb_stat``, ``lb_pvalue``; a small p-value rejects
        "the residual is white noise up to that lag".
    """
    rows = []
    for name in channels:
        values = _channel(table, name, max(lags))
        stats, pvalues = ljung_box(values, lags)
        for lag, stat, pvalue in zip(lags, stats, pvalues, strict=True):
            rows.append(
                {
                    "channel": name,
                    "lag": int(lag),
                    "lb_stat": float(stat),
                    "lb_pvalue": float(pvalue),
                }
            )
    return pd.DataFrame(rows, columns=["channel", "lag", "lb_stat", "lb_pvalue"])
