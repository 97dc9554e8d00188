"""The candidate effects of a twin table's unit: their maps on simulated outputs."""

from __future__ import annotations

import numpy as np

from dtwin.gap.table_effects import _shift


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
