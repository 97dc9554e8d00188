"""Is the twin's error structured? Residual ACF and Ljung–Box tests (paper §4.1, Fig. 3).

Thin wrappers over statsmodels that add dtwin's meaning: tables with one column per residual
channel and the white-noise band ``±1.96/√n`` the paper draws.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf

from dtwin._validation import DtwinValueError, require_finite_array, require_min_length

__all__ = ["white_noise_band", "acf_table", "ljung_box_table"]


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
        result[name] = acf(_channel(table, name, nlags), nlags=nlags, fft=False)
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
        result = acorr_ljungbox(values, lags=list(lags))
        for lag, stat, pvalue in zip(lags, result["lb_stat"], result["lb_pvalue"], strict=True):
            rows.append(
                {
                    "channel": name,
                    "lag": int(lag),
                    "lb_stat": float(stat),
                    "lb_pvalue": float(pvalue),
                }
            )
    return pd.DataFrame(rows, columns=["channel", "lag", "lb_stat", "lb_pvalue"])
