"""dtwin.residual_stats computes statsmodels' sample ACF and Ljung–Box test, bit for bit.

The figure and draw jobs use dtwin's numpy version so they do not load statsmodels; these
tests hold it to statsmodels' ``acf(x, fft=False)`` and ``acorr_ljungbox`` on residual-like
series (random walks plus noise, an AR(1), white noise) of several lengths.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf

from dtwin.residual_stats import acf_table, ljung_box, ljung_box_table, sample_acf

LAGS = [1, 5, 10, 20]


def series(kind: str, n: int) -> np.ndarray:
    """A residual-like series: ``walk`` (random walk plus noise), ``ar1`` or ``white``."""
    rng = np.random.default_rng(n)
    noise = rng.normal(size=n)
    if kind == "walk":
        return 0.3 * np.cumsum(rng.normal(size=n)) + noise
    if kind == "ar1":
        out = np.zeros(n)
        for t in range(1, n):
            out[t] = 0.8 * out[t - 1] + noise[t]
        return out
    return noise


@pytest.mark.parametrize("n", [40, 1000, 6001])
@pytest.mark.parametrize("kind", ["walk", "ar1", "white"])
def test_acf_and_ljung_box_equal_statsmodels(kind, n):
    values = series(kind, n)
    np.testing.assert_array_equal(sample_acf(values, 30), acf(values, nlags=30, fft=False))
    stats, pvalues = ljung_box(values, LAGS)
    expected = acorr_ljungbox(values, lags=LAGS)
    np.testing.assert_array_equal(stats, expected["lb_stat"].to_numpy())
    np.testing.assert_array_equal(pvalues, expected["lb_pvalue"].to_numpy())


def test_tables_carry_the_same_numbers():
    table = pd.DataFrame({"e0": series("walk", 500), "e1": series("white", 500)})
    acfs = acf_table(table, ["e0", "e1"], 10)
    np.testing.assert_array_equal(acfs["e1"], acf(table["e1"], nlags=10, fft=False))
    lb = ljung_box_table(table, ["e0"], [5, 10])
    expected = acorr_ljungbox(table["e0"].to_numpy(), lags=[5, 10])
    np.testing.assert_array_equal(lb["lb_pvalue"], expected["lb_pvalue"].to_numpy())
    assert lb["lb_pvalue"].iloc[0] < 1e-6  # a random walk is far from white
