"""The one Wilson interval (dtwin.proportions), used by the claims and the gap benchmark."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ndtri
from scipy.stats import norm

from dtwin._validation import DtwinValueError
from dtwin.proportions import wilson_interval


def test_wilson_interval_matches_a_hand_computation():
    # 8 of 10, z = 1.959964: centre (0.8 + 0.19207) / 1.38415 = 0.71674, half-width
    # 1.959964 * sqrt(0.016 + 0.0096036) / 1.38415 = 0.22658 (Wilson 1927)
    low, high = wilson_interval(8, 10)
    assert low == pytest.approx(0.49016, abs=1e-5) and high == pytest.approx(0.94332, abs=1e-5)


@pytest.mark.parametrize(("k", "n"), [(0, 5), (3, 3), (8, 10), (41, 57), (0, 1), (1, 1)])
def test_wilson_interval_matches_the_closed_form_and_holds_the_share(k, n):
    z = norm.ppf(0.975)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    low, high = wilson_interval(np.int64(k), np.int64(n))
    assert low == pytest.approx(max(0.0, centre - half), abs=1e-12)
    assert high == pytest.approx(min(1.0, centre + half), abs=1e-12)
    assert 0.0 <= low <= p <= high <= 1.0


def test_wilson_interval_is_exact_at_the_ends():
    """At k = 0 (k = n) the bound is exactly 0 (1), never a round-off 1e-17 past the share."""
    for n in range(1, 400):
        assert wilson_interval(0, n)[0] == 0.0 and wilson_interval(n, n)[1] == 1.0


def test_wilson_interval_agrees_with_statsmodels():
    from statsmodels.stats.proportion import proportion_confint

    for k, n, level in [(8, 10, 0.95), (3, 40, 0.9), (57, 60, 0.99), (0, 7, 0.8)]:
        low, high = proportion_confint(k, n, alpha=1 - level, method="wilson")
        ours = wilson_interval(k, n, level)
        assert ours == pytest.approx((max(0.0, low), min(1.0, high)), abs=1e-15)


def test_wilson_interval_of_no_trial_is_nan():
    assert all(np.isnan(wilson_interval(0, 0)))


@pytest.mark.parametrize(
    ("k", "n", "level", "match"),
    [
        (11, 10, 0.95, "k must be"),
        (1, -1, 0.95, "n must be"),
        (1, 2, 1.0, "level must be"),
        (0.5, 2, 0.95, "k must be an integer"),
        (True, 2, 0.95, "k must be an integer"),
    ],
)
def test_wilson_interval_names_the_bad_argument(k, n, level, match):
    with pytest.raises(DtwinValueError, match=match):
        wilson_interval(k, n, level)


def test_wilson_z_is_scipy_normal_quantile():
    """wilson_interval takes z from scipy.special.ndtri: norm.ppf's value, bit for bit."""
    for level in (0.5, 0.8, 0.9, 0.95, 0.99, 0.999):
        assert float(ndtri(0.5 + level / 2)) == float(norm.ppf(0.5 + level / 2))
