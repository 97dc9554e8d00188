"""Unit tests of the effect catalogue's helpers (dtwin/gap/effects.py)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from dtwin.gap.effects import quantization_variance


def test_quantization_variance_is_continuous_across_the_closed_form_threshold():
    """Exact level sum just below σ = 2q, Sheppard's σ² + q²/12 from there: they agree."""
    s = np.random.default_rng(0).normal(scale=3.0, size=20_000)
    sigma_below = 0.1 * (2.0 - 1e-9)
    below = quantization_variance(s, 0.1, sigma_below)
    at = quantization_variance(s, 0.1, 0.2)
    assert at == pytest.approx(0.2**2 + 0.1**2 / 12, rel=1e-15)
    assert below == pytest.approx(sigma_below**2 + 0.1**2 / 12, rel=1e-12)


def test_quantization_variance_matches_a_monte_carlo_quantizer():
    """Mean of Var(q·round((s + ε)/q) | s) against 4000 noise draws per sample."""
    rng = np.random.default_rng(1)
    s = rng.uniform(-1.0, 1.0, size=50)
    step, sigma = 0.2, 0.07
    draws = step * np.round((s[:, None] + sigma * rng.standard_normal((50, 4000))) / step)
    assert quantization_variance(s, step, sigma) == pytest.approx(
        draws.var(axis=1).mean(), rel=0.05
    )


@pytest.mark.parametrize("noise_std", [1e-3, 1e3, 1e11, 1e150])
def test_quantization_variance_memory_does_not_grow_with_the_noise_to_step_ratio(noise_std):
    """A spike that inflates σ once asked for an array of shape (T, 2·5σ/q): now O(T)."""
    s = np.random.default_rng(2).normal(size=100_000)
    tracemalloc.start()
    value = quantization_variance(s, 1e-3, noise_std)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert np.isfinite(value) and value > 0
    assert peak < 50 * 2**20, f"peak {peak / 2**20:.1f} MB"


def test_bias_drift_is_a_line_at_zero_curvature_and_settles_or_accelerates_otherwise():
    from dtwin.gap.effects import bias_drift

    t = np.linspace(0.0, 20.0, 401)
    assert np.array_equal(bias_drift(t, 0.3, 0.0), 0.3 * t)
    settling = bias_drift(t, 0.3, 0.5)
    assert settling[-1] == pytest.approx(0.3 / 0.5 * (1 - np.exp(-10.0)))
    assert np.all(np.diff(settling) > 0) and np.all(np.diff(settling, 2) < 0)
    accelerating = bias_drift(t, 0.3, -0.05)
    assert np.all(np.diff(accelerating, 2) > 0)
    # the initial rate is `rate` whatever the curvature
    for curvature in (0.5, 1e-12, -0.05):
        assert (bias_drift(t[:2], 0.3, curvature)[1] / t[1]) == pytest.approx(0.3, rel=0.03)
