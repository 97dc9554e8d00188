"""The diagnoser's exact plant (dtwin.exact_plant) against the continuous solution.

docs/gap.md §Modules: zero- and first-order hold discretisations must match the continuous
mass-spring-damper at 3, 10 and 150 samples per period, damping ratios 0.005–1, and k = 0; the
band-limited hold must match its response to a sinusoid below the Nyquist frequency.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dtwin.exact_plant import (
    EXACT_HOLDS,
    exact_plant_response,
    free_response_basis,
    hold_matrices,
)
from dtwin.modules import BANDLIMITED, FOH, ZOH

#: The holds with a piecewise-polynomial input between samples (a continuous reference exists
#: sample by sample).
PIECEWISE_HOLDS = (ZOH, FOH)


def _continuous(u, m, c, k, dt, hold, x0=0.3, v0=-0.2):
    """Integrate m·ẍ = u(t) − c·ẋ − k·x sample by sample at tolerance 1e-13."""

    def between(j):
        if hold == ZOH:
            return lambda s: u[j]
        return lambda s: u[j] + (u[j + 1] - u[j]) * s / dt

    state = np.array([x0, v0])
    xs = [x0]
    for j in range(len(u) - 1):
        force = between(j)
        sol = solve_ivp(
            lambda s, y, f=force: [y[1], (f(s) - c * y[1] - k * y[0]) / m],
            (0.0, dt),
            state,
            rtol=1e-13,
            atol=1e-15,
            method="DOP853",
        )
        state = sol.y[:, -1]
        xs.append(state[0])
    return np.array(xs)


@pytest.mark.parametrize("samples_per_period", [3, 10, 150])
@pytest.mark.parametrize("hold", PIECEWISE_HOLDS)
@pytest.mark.parametrize("zeta", [0.005, 1.0])
def test_exact_discretisation_matches_the_continuous_plant(samples_per_period, hold, zeta):
    m, period = 2.0, 0.5
    omega = 2 * np.pi / period
    k, c = m * omega**2, 2 * zeta * m * omega
    dt = period / samples_per_period
    rng = np.random.default_rng(samples_per_period)
    u = rng.normal(size=60) * k
    x = exact_plant_response(
        u,
        m,
        c,
        k,
        dt,
        windows=[(0, 60)],
        x_start=np.full(60, 0.3),
        v_start=np.full(60, -0.2),
        hold=hold,
    )
    reference = _continuous(u, m, c, k, dt, hold)
    assert np.max(np.abs(x - reference)) < 1e-9 * np.max(np.abs(reference))


@pytest.mark.parametrize("hold", PIECEWISE_HOLDS)
def test_integrating_plant_and_windows_restart_from_the_given_state(hold):
    m, c, k, dt = 95.0, 200.0, 0.0, 1e-3
    rng = np.random.default_rng(1)
    u = rng.normal(size=400) * 50
    x_start = rng.normal(size=400)
    v_start = rng.normal(size=400)
    windows = [(0, 150), (150, 300), (300, 400)]
    x = exact_plant_response(
        u, m, c, k, dt, windows=windows, x_start=x_start, v_start=v_start, hold=hold
    )
    for start, stop in windows:
        reference = _continuous(u[start:stop], m, c, k, dt, hold, x_start[start], v_start[start])
        assert np.max(np.abs(x[start:stop] - reference)) < 1e-9 * np.max(np.abs(reference))


@pytest.mark.parametrize("hold", EXACT_HOLDS)
def test_force_loop_equals_the_linear_filter_for_a_zero_force(hold):
    rng = np.random.default_rng(2)
    u = rng.normal(size=300)
    start = dict(x_start=rng.normal(size=300), v_start=rng.normal(size=300))
    windows = [(0, 100), (100, 300)]
    linear = exact_plant_response(u, 1.0, 0.3, 40.0, 0.05, windows=windows, hold=hold, **start)
    looped = exact_plant_response(
        u, 1.0, 0.3, 40.0, 0.05, windows=windows, hold=hold, force=lambda x, v: 0.0, **start
    )
    np.testing.assert_allclose(looped, linear, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("k3", [30.0, -3e4])  # a stiffening spring; one that diverges
def test_one_window_float_loop_equals_the_lockstep_array_loop_bit_for_bit(k3):
    """A window run alone (Python floats) and beside another (numpy arrays): the same bits."""
    rng = np.random.default_rng(5)
    u = np.sign(np.sin(np.arange(400) * 0.05)) + 0.1 * rng.normal(size=400)
    start = dict(x_start=rng.normal(size=400) * 0.1, v_start=rng.normal(size=400))

    def cubic(x, v):
        offset = x - 0.02
        return k3 * offset * offset * offset

    common = dict(hold=FOH, force=cubic, **start)
    together = exact_plant_response(
        u, 1.3, 0.3, 40.0, 0.01, windows=[(0, 200), (200, 400)], **common
    )
    first = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=[(0, 200)], **common)
    second = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=[(200, 400)], **common)
    assert together[:200].tobytes() == first[:200].tobytes()
    assert together[200:].tobytes() == second[200:].tobytes()
    assert np.isinf(together).any() == (k3 < 0)


def test_first_order_hold_uses_the_same_sample_input():
    """Only the first-order hold lets u[k] act on x[k] (a band-limited input's same-sample term)."""
    u = np.zeros(5)
    u[2] = 1.0
    kwargs = dict(windows=[(0, 5)], x_start=np.zeros(5), v_start=np.zeros(5))
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=FOH, **kwargs)[2] > 0
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=ZOH, **kwargs)[2] == 0
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=BANDLIMITED, **kwargs)[1] != 0


def test_free_response_basis_is_the_first_row_of_the_matrix_powers():
    step = hold_matrices(0.3, 40.0, 0.05, FOH)
    power, rows = np.eye(2), []
    for _ in range(7):
        rows.append(power[0])
        power = step.a @ power
    np.testing.assert_allclose(free_response_basis(step, 7), np.array(rows), atol=1e-14)


@pytest.mark.parametrize("samples_per_period", [3, 10, 150])
@pytest.mark.parametrize("input_per_nyquist", [0.1, 0.6])
def test_bandlimited_hold_matches_the_steady_response_to_a_sinusoid(
    samples_per_period, input_per_nyquist
):
    """A sinusoid below the Nyquist frequency: the response is ``Re(H(iω)·e^{iωt})`` exactly.

    Measured (ζ = 0.05): the band-limited hold errs by ≤ 7e-4 of the amplitude up to 0.6 of the
    Nyquist frequency; the first-order hold by 1.2–46 %.
    """
    m, period, zeta = 2.0, 0.5, 0.05
    omega_n = 2 * np.pi / period
    k, c = m * omega_n**2, 2 * zeta * m * omega_n
    dt = period / samples_per_period
    omega = input_per_nyquist * np.pi / dt
    t = np.arange(600) * dt
    gain = 1.0 / (k - m * omega**2 + 1j * c * omega)
    exact = gain * np.exp(1j * omega * t)
    start = dict(x_start=exact.real, v_start=(1j * omega * exact).real)
    window = slice(100, 500)  # the input is known 8 samples beyond the window on both sides

    def error(hold):
        x = exact_plant_response(
            np.cos(omega * t), m, c, k, dt, windows=[(100, 500)], hold=hold, **start
        )
        return np.max(np.abs(x[window] - exact.real[window])) / abs(gain)

    assert error(BANDLIMITED) < 1e-3
    assert error(BANDLIMITED) < error(FOH) / 10


@pytest.mark.parametrize(("samples_per_period", "seed"), [(5, 3), (500, 9)])
def test_calibration_recovers_a_rigs_parameters_and_offset(samples_per_period, seed):
    """A linear rig (open loop, volts-like units, offsets) from scratch: m, c, k, u_offset to 2 %.

    Measured: within 0.4 % at 5 samples per period (band-limited hold chosen) and 500 (first-order).
    """
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
    from dtwin.gap.rigs import generate_rig_case

    case = generate_rig_case("none", seed, samples_per_period=samples_per_period, n_samples=4000)
    recording = recording_from_frame(case.recording)
    twin = twin_from_mapping(case.twin, dt=recording.dt)
    used = diagnose(recording, twin, calibrate=True).modules["M1"].lin_used
    for name in ("m", "c", "k"):
        assert used[name] == pytest.approx(case.key["plant"][name], rel=0.02), name
    assert used["u_offset"] == pytest.approx(case.key["u_offset"], rel=0.02)
