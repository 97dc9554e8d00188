"""The candidate effects of a twin table's unit: their maps on simulated outputs."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.gap.table_effects import (
    _shift,
    bipolar,
    lattice_of,
    quantizer_mean,
    soft_saturation,
)


def test_a_delay_shifts_each_window_of_a_capped_fit_within_that_window():
    """Windows that are not adjacent are NaN between them: no window reads across the gap."""
    dt = 0.1
    first, second = np.arange(5.0), 10.0 + np.arange(4.0)
    values = np.concatenate([first, [np.nan] * 3, second])
    shifted = _shift(values, 1.5 * dt, dt)
    gap = slice(5, 8)
    assert np.isnan(shifted[gap]).all()
    assert np.isfinite(np.delete(shifted, np.arange(5, 8))).all()
    # each window's first value held before it, then a linear interpolation 1.5 samples back
    np.testing.assert_allclose(shifted[:5], [0.0, 0.0, 0.5, 1.5, 2.5])
    np.testing.assert_allclose(shifted[8:], [10.0, 10.0, 10.5, 11.5])


def test_a_delay_of_whole_samples_on_a_finite_record_is_a_plain_shift():
    values = np.column_stack([np.arange(6.0), -np.arange(6.0)])
    shifted = _shift(values, 0.2, 0.1)
    np.testing.assert_allclose(shifted[2:], values[:4])
    np.testing.assert_allclose(shifted[:2], values[[0, 0]])


@pytest.mark.parametrize("sigma", [0.1, 0.3])
def test_a_quantizer_s_expected_output_is_the_mean_of_its_noisy_values(sigma):
    """Against a Monte Carlo mean of a truncating quantizer (shift -q/2) after Gaussian noise."""
    q, c, b = 0.5, 0.1, -0.25
    y = np.linspace(-1.0, 1.0, 41)
    noise = sigma * np.random.default_rng(7).standard_normal((20000, 1))
    sampled = np.mean(c + q * np.round((y + b + noise - c) / q), axis=0)
    np.testing.assert_allclose(quantizer_mean(y, q, c, b, sigma), sampled, atol=0.01)


def test_a_quantizer_s_expected_output_is_a_staircase_without_noise_and_a_line_with_much():
    q, c = 0.2, 0.0
    y = np.array([0.03, 0.25, 0.47, -0.33])  # away from the staircase's edges
    np.testing.assert_allclose(
        quantizer_mean(y, q, c, 0.0, 0.05 * q), [0.0, 0.2, 0.4, -0.4], atol=1e-3
    )
    np.testing.assert_allclose(quantizer_mean(y, q, c, 0.01, q), y + 0.01, atol=1e-6)


def test_a_soft_saturation_is_linear_below_its_limit_and_a_clip_as_its_knee_sharpens():
    u = np.array([-1e6, -3.0, -0.2, 0.0, 0.1, 0.9, 1.0, 2.0, 1e300])
    hard = soft_saturation(u, 1.0, 200.0)
    np.testing.assert_allclose(hard, np.clip(u, -1.0, 1.0), atol=4e-3)
    round_knee = soft_saturation(u, 1.0, 2.0)
    np.testing.assert_allclose(round_knee[[2, 4]], u[[2, 4]], rtol=0.03)  # linear well below U
    assert np.all(np.abs(round_knee) <= 1.0 + 1e-12) and np.all(np.isfinite(round_knee))
    assert round_knee[6] == pytest.approx(2**-0.5)


def test_a_slew_limited_input_moves_at_most_its_step_and_restarts_after_a_gap():
    from dtwin.twin._kernels import slew_limited

    u = np.array([0.0, 3.0, 3.0, 3.0, np.nan, 5.0, 0.0])
    np.testing.assert_array_equal(slew_limited(u, 1.0), [0.0, 1.0, 2.0, 3.0, np.nan, 5.0, 4.0])


def test_a_lag_resting_on_a_few_plateaus_is_not_a_lattice_but_a_blurred_quantizer_is():
    # a first-order lag driven by three input levels, with little noise: nearly all its time
    # on three plateaus, which a coarse step fits, but its ramps visit every value between
    rng = np.random.default_rng(4)
    levels = np.repeat(rng.choice([1.1, 13.0, 27.4], size=30), 100)
    y = np.zeros(len(levels))
    for k in range(1, len(y)):
        y[k] = y[k - 1] + 0.3 * (levels[k] - y[k - 1])
    y += 0.01 * rng.standard_normal(len(y))
    assert lattice_of(y)[2] < 0.9
    # a quantizer of step 0.5 before noise of 4 % of its step: values near its lattice only
    walk = np.cumsum(rng.standard_normal(3000)) * 0.15
    blurred = 0.5 * np.round(walk / 0.5) + 0.02 * rng.standard_normal(3000)
    q, _, concentration = lattice_of(blurred)
    assert q == pytest.approx(0.5, rel=0.03)
    assert concentration >= 0.9


def test_an_input_is_bipolar_when_it_reaches_a_tenth_of_its_reach_on_both_sides():
    """Only then may a dead zone's widths differ by direction (its skew is fitted)."""
    assert bipolar(np.array([-3.0, 0.0, 12.0]))
    assert not bipolar(np.array([-1.0, 0.0, 12.0]))  # one twelfth below zero
    assert not bipolar(np.array([0.0, 2.0, 5.0]))
    assert not bipolar(np.array([np.nan, 0.0, 0.0]))
