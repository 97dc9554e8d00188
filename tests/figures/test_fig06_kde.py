"""Fig. 6's kernel density equals scipy.stats.gaussian_kde's (so its job need not load scipy.stats).

:func:`dtwin.figures.fig06_correction_distributions.kde_curve` sums the same Gaussian kernels
in the same order as scipy; only numpy's ``exp`` differs from the C library's in the last bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import gaussian_kde

from dtwin.figures.fig06_correction_distributions import bw_nrd0, kde_curve


@pytest.mark.parametrize("n", [2, 50, 4000])
@pytest.mark.parametrize("scale", [1e-4, 1.0, 300.0])
def test_kde_curve_equals_scipy(n, scale):
    rng = np.random.default_rng(n)
    values = rng.standard_t(3, size=n) * scale + 0.1 * scale
    grid = np.linspace(values.min() - scale, values.max() + scale, 512)
    sd = float(np.std(values, ddof=1))
    expected = gaussian_kde(values, bw_method=bw_nrd0(values) / sd)(grid)
    np.testing.assert_allclose(kde_curve(values, grid), expected, rtol=1e-13, atol=0)


def test_constant_values_give_zero_density():
    assert not kde_curve(np.full(10, 3.0), np.linspace(0.0, 6.0, 7)).any()
