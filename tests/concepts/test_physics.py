"""The physical modules follow the paper's discrete equations exactly (paper §3.1)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from dtwin.command import make_command, n_steps_for
from dtwin.params import command_params_from_mapping
from dtwin.physics import (
    actuator_lpf,
    backward_velocity,
    plant_msd,
    sensor_first_order,
    simulate_physics,
)
from dtwin.twin.paper_modules import lag_coefficient, run_modules
from dtwin.twin.wiring import SIGNALS
from tests.conftest import REFERENCE


def test_noise_free_plant_is_the_exact_difference_equation():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(400)
    m, c, k, dt = 1.0, 0.4, 4.0, 0.02
    x = plant_msd(u, m, c, k, dt).x
    expected = np.zeros_like(x)
    for step in range(2, len(u)):
        expected[step] = (
            (2 - c * dt) * expected[step - 1]
            - (1 - c * dt + k * dt**2) * expected[step - 2]
            + dt**2 * u[step - 2]
        )
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12)


def test_plant_velocity_is_explicit_euler_with_old_velocity():
    u = np.ones(50)
    trajectory = plant_msd(u, 2.0, 0.5, 3.0, 0.1)
    x, v = trajectory.x, trajectory.v
    np.testing.assert_allclose(x[1:], x[:-1] + 0.1 * v[:-1])
    accel = (u[:-1] - 0.5 * v[:-1] - 3.0 * x[:-1]) / 2.0
    np.testing.assert_allclose(v[1:], v[:-1] + 0.1 * accel)
    assert x[0] == v[0] == x[1] == 0.0


def test_actuator_step_response_matches_closed_form():
    a = lag_coefficient(0.15, 0.02)
    y = actuator_lpf(np.ones(100), tau=0.15, dt=0.02)
    steps = np.arange(100)
    np.testing.assert_allclose(y, 1.0 - a**steps, atol=1e-13)


def test_sensor_lag_closed_form_bias_and_first_sample():
    a = lag_coefficient(0.25, 0.02)
    y = sensor_first_order(np.ones(60), tau=0.25, dt=0.02, bias=0.01)
    np.testing.assert_allclose(y, 1.0 - a ** np.arange(60) + 0.01, atol=1e-13)
    assert y[0] == pytest.approx(0.01)  # y_1 = bias (+ noise): the lag state starts at 0


def test_one_sample_input_delays():
    impulse = np.zeros(20)
    impulse[5] = 1.0
    u_act = actuator_lpf(impulse, 0.15, 0.02)
    assert np.flatnonzero(u_act)[0] == 6
    y = sensor_first_order(impulse, 0.08, 0.02)
    assert np.flatnonzero(y)[0] == 6
    x = plant_msd(impulse, 1.0, 0.4, 4.0, 0.02).x
    assert np.flatnonzero(x)[0] == 7  # force -> velocity (1 sample) -> position (1 more)


def test_backward_velocity():
    np.testing.assert_allclose(backward_velocity(np.array([0.0, 1.0, 3.0]), 0.5), [0.0, 2.0, 4.0])


def test_simulation_is_seeded_and_noise_levels_do_not_shift_the_stream(config, twin):
    command = command_params_from_mapping(config["command"])
    n = n_steps_for(config["simulation"]["T"], twin.dt)
    u = make_command(n, twin.dt, command, np.random.default_rng(5))
    first = simulate_physics(twin, u, np.random.default_rng(7))
    again = simulate_physics(twin, u, np.random.default_rng(7))
    pd.testing.assert_frame_equal(first, again)
    assert list(first.columns) == ["t", *SIGNALS]
    assert len(first) == n == 1000
    # Doubling sensor B's noise changes only y_B's noise, not the draws of the other modules.
    from dataclasses import replace

    louder = replace(twin, noise=replace(twin.noise, sensor_B=2 * twin.noise.sensor_B))
    other = simulate_physics(louder, u, np.random.default_rng(7))
    np.testing.assert_array_equal(first["y_A"], other["y_A"])
    np.testing.assert_allclose(
        other["y_B"] - first["y_B"], first["y_B"] - sensor_first_order(first["x"], 0.25, 0.02, 0.01)
    )


def test_command_deterministic_part_matches_r(config):
    """R's u_cmd minus our step-free command is piecewise constant, jumping every 125 samples."""
    r = pd.read_csv(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
    params = command_params_from_mapping({**config["command"], "step_std": 0.0})
    base = make_command(len(r), 0.02, params, np.random.default_rng(0))
    offsets = r["u_cmd"].to_numpy() - base
    jumps = np.flatnonzero(np.abs(np.diff(offsets)) > 1e-9) + 1
    assert set(jumps) <= set(range(125, 1000, 125))
    assert np.ptp(offsets[:125]) < 1e-9


# --- the module contract (dtwin.twin.paper_modules) -----------------------------------------------


def test_contract_follows_the_wiring_table_and_the_twin_sections():
    import dataclasses

    from dtwin.params import TwinParams
    from dtwin.twin.paper_modules import CONTRACTS, LINEAR_PARAMS
    from dtwin.twin.wiring import MODULES

    assert list(CONTRACTS) == [module.name for module in MODULES]
    hints = {f.name: f.type for f in dataclasses.fields(TwinParams)}
    for name, contract in CONTRACTS.items():
        assert contract.section in hints, name
        assert set(contract.dynamic_params) <= set(contract.params)
        assert LINEAR_PARAMS[name] == contract.params


def test_zoh_plant_matches_scipy_cont2discrete():
    from scipy.signal import cont2discrete

    from dtwin.twin.paper_modules import ZOH, plant_matrices

    m, c, k, dt = 1.3, 0.4, 4.0, 0.05
    a, b_force, _ = plant_matrices(m, c, k, dt, ZOH)
    ad, bd, *_ = cont2discrete(
        (np.array([[0, 1], [-k / m, -c / m]]), np.array([[0], [1 / m]]), np.eye(2), 0), dt
    )
    np.testing.assert_allclose(a, ad, rtol=1e-12)
    np.testing.assert_allclose(b_force, bd, rtol=1e-12)


def test_zoh_plant_step_response_is_exact_and_euler_is_the_papers():
    from dtwin.twin.paper_modules import EULER, ZOH, plant_response

    m, c, k, dt = 1.0, 0.4, 4.0, 0.02
    u = np.ones(3000)
    exact = plant_response(u, m, c, k, dt, discretisation=ZOH).x
    wn, zeta = math.sqrt(k / m), c / (2 * math.sqrt(k * m))
    wd = wn * math.sqrt(1 - zeta**2)
    t = dt * np.arange(3000)  # u[j-1] is held over [(j-1)·dt, j·dt]: the step starts at t = 0
    step = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
    np.testing.assert_allclose(exact, step / k, atol=1e-12)
    euler = plant_response(u, m, c, k, dt, discretisation=EULER).x
    np.testing.assert_array_equal(euler, plant_msd(u, m, c, k, dt).x)


def test_lag_coefficient_of_the_paper_time_constants_equals_numpy_exp():
    """The one lag pole (math.exp) gives the paper simulator the bits of its former numpy.exp."""
    for tau in (0.15, 0.08, 0.25):
        assert lag_coefficient(tau, 0.02) == float(np.exp(-0.02 / tau))


def test_the_chain_runner_runs_the_wiring_in_order_and_keeps_each_module_to_its_outputs():
    """physics, every generated asset and the diagnoser's chain run through run_modules."""
    seen = []

    def step(name, outputs):
        def run(signals):
            seen.append((name, sorted(signals)))
            return outputs

        return run

    written = run_modules(
        {
            "M3": step("M3", {"y_fused": np.zeros(2)}),  # listed first, runs after the sensors
            "M2a": step("M2a", {"y_A": np.ones(2)}),
            "M2b": step("M2b", None),  # cannot run: skipped
        },
        {"x": np.zeros(2), "y_B": np.zeros(2)},
    )
    assert [name for name, _ in seen] == ["M2a", "M2b", "M3"]
    assert "y_A" in seen[-1][1]  # a later module sees what an earlier one wrote
    assert list(written) == ["y_A", "y_fused"]
    with pytest.raises(ValueError, match="module M2a may write"):
        run_modules({"M2a": step("M2a", {"x": np.ones(2)})}, {"x": np.zeros(2)})
