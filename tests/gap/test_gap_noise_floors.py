"""The exact plant's process-noise floor over windows (docs/gap.md §Noise floors)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dtwin.gap.models import (
    held_noise_autocovariance,
    warmup_samples,
    window_error_covariance,
    window_noise_gain,
)
from dtwin.gap.noise import process_noise_floor
from dtwin.twin.exact import free_response_basis, hold_matrices

LIN = {"m": 1.0, "c": 0.4, "k": 4.0}
DT = 0.02
HORIZON = 300


def _window_errors(rng, n_windows, sigma_process, sigma_measurement, pole, hold="zoh"):
    """Return the scored errors of ``n_windows`` windows of an exact twin under both noises.

    The position's process noise is simulated through the zero-order hold of the plant (the
    acceleration noise held over each sample) from its stationary state; the measurement noise
    is AR(1); each window's initial state is fitted to its warm-up as the windows do.
    """
    step = hold_matrices(LIN["c"] / LIN["m"], LIN["k"] / LIN["m"], DT, "zoh")
    n = n_windows * HORIZON + 2000
    state, position = np.zeros(2), np.empty(n)
    drive = step.taps[0] * sigma_process
    for j, xi in enumerate(rng.standard_normal(n)):
        position[j] = state[0]
        state = step.a @ state + drive * xi
    noise = np.empty(n)
    noise[0] = rng.standard_normal()
    for j in range(1, n):
        noise[j] = pole * noise[j - 1] + math.sqrt(1 - pole * pole) * rng.standard_normal()
    total = position[2000:] + sigma_measurement * noise[2000:]
    warmup = warmup_samples(HORIZON)
    basis = free_response_basis(hold_matrices(LIN["c"], LIN["k"], DT, hold), HORIZON)
    carried = basis[warmup:] @ np.linalg.pinv(basis[:warmup])
    windows = total.reshape(n_windows, HORIZON)
    return windows[:, warmup:] - windows[:, :warmup] @ carried.T


def _groups(errors, pole, hold="zoh"):
    autocovariance = held_noise_autocovariance(LIN, DT, HORIZON)
    process = window_error_covariance(LIN, DT, hold, HORIZON, HORIZON, autocovariance)
    measurement = window_error_covariance(
        LIN, DT, hold, HORIZON, HORIZON, pole ** np.arange(HORIZON)
    )
    return [(errors, process, measurement)], autocovariance / autocovariance[0]


@pytest.mark.parametrize("pole", [0.0, 0.69])
def test_a_windows_error_covariance_has_the_window_noise_gain_on_its_diagonal(pole):
    covariance = window_error_covariance(LIN, DT, "foh", 200, 200, pole ** np.arange(200))
    gain = window_noise_gain(LIN, DT, "foh", 200, pole)
    assert covariance.shape == (200 - warmup_samples(200),) * 2
    assert np.mean(np.diag(covariance)) == pytest.approx(gain, rel=1e-9)


def test_the_held_noise_autocovariance_is_the_positions_stationary_variance():
    """A long simulation of the held acceleration noise has the stationary variance."""
    rng = np.random.default_rng(5)
    step = hold_matrices(0.4, 4.0, DT, "zoh")
    state, positions = np.zeros(2), []
    for xi in rng.standard_normal(200_000):
        state = step.a @ state + step.taps[0] * xi
        positions.append(state[0])
    autocovariance = held_noise_autocovariance(LIN, DT, 50)
    assert np.var(positions[1000:]) == pytest.approx(autocovariance[0], rel=0.05)
    assert held_noise_autocovariance({"m": 1.0, "c": 0.4, "k": 0.0}, DT, 50) is None


@pytest.mark.parametrize("seed", [1, 2])
def test_process_noise_is_read_beside_coloured_measurement_noise(seed):
    """The maximum-likelihood levels of both noises match the drawn ones (20 windows)."""
    rng = np.random.default_rng(seed)
    errors = _window_errors(rng, 20, sigma_process=0.04, sigma_measurement=0.003, pole=0.7)
    groups, acf = _groups(errors, 0.7)
    floor = process_noise_floor(groups, acf, 0.7, significance=0.01)
    assert floor is not None
    _, process, measurement = groups[0]
    expected_process = 0.04 * math.sqrt(np.mean(np.diag(process)))
    expected_measurement = 0.003 * math.sqrt(np.mean(np.diag(measurement)))
    assert floor.process == pytest.approx(expected_process, rel=0.25)
    assert floor.measurement == pytest.approx(expected_measurement, rel=0.15)
    assert floor.rms == pytest.approx(math.hypot(floor.process, floor.measurement))
    assert floor.rms == pytest.approx(np.sqrt(np.mean(errors**2)), rel=0.2)
    assert not floor.identified
    assert floor.acf[0] == pytest.approx(1.0)


def test_measurement_noise_alone_leaves_little_process_noise():
    rng = np.random.default_rng(3)
    errors = _window_errors(rng, 20, sigma_process=0.0, sigma_measurement=0.003, pole=0.7)
    groups, acf = _groups(errors, 0.7)
    floor = process_noise_floor(groups, acf, 0.7, significance=0.01)
    assert floor is None or floor.process < 0.2 * floor.measurement


@pytest.mark.parametrize("cycles", [10, 40])
def test_a_structured_error_beside_the_noise_is_no_noise_floor(cycles):
    """A force's response above the resonance (a sine of 10 or 40 cycles per window, half the
    noise's spread) leaves the innovations coloured: no process floor then (the spectral floor
    stays). Near the resonance (2.5 cycles) it passes for process noise, which the nested test
    then judges (docs/gap.md §Noise floors)."""
    rng = np.random.default_rng(4)
    errors = _window_errors(rng, 20, sigma_process=0.04, sigma_measurement=0.003, pole=0.7)
    scored = errors.shape[1]
    spread = np.sqrt(np.mean(errors**2))
    wave = np.sin(2 * np.pi * cycles * np.arange(scored) / scored)
    groups, acf = _groups(errors + 0.5 * spread * wave, 0.7)
    assert process_noise_floor(groups, acf, 0.7, significance=0.01) is None
    groups, acf = _groups(errors, 0.7)
    assert process_noise_floor(groups, acf, 0.7, significance=0.01) is not None
