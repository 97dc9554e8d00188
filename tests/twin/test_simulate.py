"""A unit's simulation over windows: a batch and a chain give each run's own bits."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.twin.simulate import UnitModel, units_of, window_rows
from dtwin.twin.table import table_from_mapping

#: Every opcode: functions, powers, min/max, time; a state that can run away (NaN or inf).
TWIN = {
    "dt": 0.05,
    "modules": {
        "m": {
            "inputs": ["u", "v"],
            "outputs": ["x", "z"],
            "states": ["x", "w", "q"],
            "params": {"k": 4.0, "c": 0.6, "a": 0.3},
            "derivatives": {
                "x": "w",
                "w": "u - c*w - k*x + a*tanh(w/0.01) - 0.1*x**3 + sin(t)",
                "q": "a*sqrt(max(q, 0)) - min(v, 1)*q/(1 + abs(x)) + exp(-x**2)*sign(w)"
                " + log(1 + x**2) - abs(q)**1.5 + q**2",
            },
            "equations": {"z": "x + 0.5*w - cos(q)/2 + tan(0.1*x)"},
        }
    },
}


def _model_and_inputs(n: int, seed: int):
    table = table_from_mapping(TWIN)
    model = UnitModel.from_spec(units_of(table, ["u", "v", "x", "z"])[0])
    rng = np.random.default_rng(seed)
    u = np.column_stack([np.repeat(rng.uniform(-2, 2, n // 50 + 1), 50)[:n], rng.uniform(0, 2, n)])
    return model, u, rng


@pytest.mark.parametrize("substeps", [1, 3])
def test_a_batch_gives_each_member_the_bits_of_its_own_run(substeps):
    model, u, rng = _model_and_inputs(1200, 0)
    starts, stops = np.array([0, 130, 400, 900]), np.array([100, 300, 561, 1199])  # unequal
    thetas = [[4.0, 0.6, 0.3], [4.1, 0.6, 0.3], [4.0, 0.7, 2.0]]
    x0 = rng.uniform(0, 1, (3, len(starts), 3))
    x0[2, 1, 2] = 40.0  # this member's window runs away
    scaled = u * [1.1, 1.0]
    bounds = [None, (np.array([-0.5, -np.inf, 0.0]), np.array([0.5, 2.0, np.inf])), None]
    y, states = model.simulate_batch(
        [u, scaled], [0, 1, 0], thetas, starts, stops, x0, 0.05, substeps=substeps,
        linear=[False, True], limits=bounds, t0=0.3,
    )  # fmt: skip
    rows = window_rows(starts, stops)
    assert not np.all(np.isfinite(y[2]))  # the run-away member is part of the check
    for b, (inputs, theta) in enumerate(zip([u, scaled, u], thetas, strict=True)):
        alone_y, alone_states = model.simulate(
            inputs, theta, starts, stops, x0[b], 0.05, substeps=substeps, linear=[False, True],
            limits=bounds[b], t0=0.3,
        )  # fmt: skip
        assert np.array_equal(alone_y[rows], y[b], equal_nan=True)
        assert np.array_equal(alone_states[rows], states[b], equal_nan=True)
        outside = np.setdiff1d(np.arange(len(u)), rows)
        assert np.all(np.isnan(alone_y[outside]))


def test_a_chain_runs_each_window_from_the_end_of_the_previous():
    model, u, _ = _model_and_inputs(600, 1)
    starts, stops = np.array([0, 150, 300, 450]), np.array([150, 300, 450, 600])
    theta = [4.0, 0.6, 0.3]
    x0 = np.array([0.2, 0.0, 0.5])
    values = np.array([[0.2], [-0.1], [0.3], [0.0]])  # x reset from the "recording"
    chained = model.simulate_chained(
        u, theta, starts, stops, x0, [0], values, 0.05, substeps=2, linear=[True, True]
    )
    assert not np.all(np.isfinite(chained))  # a window that runs away passes on its start
    state = x0.copy()
    for w, (a, b) in enumerate(zip(starts, stops, strict=True)):
        state[0] = values[w, 0]
        _, states = model.simulate(u, theta, [a], [b], state[None], 0.05, substeps=2)
        assert np.array_equal(states[a:b], chained[a:b], equal_nan=True)
        end = states[b - 1]
        state = np.where(np.isfinite(end), end, state)


def test_window_rows_lists_each_window_s_samples_in_turn():
    assert window_rows(np.array([3, 10]), np.array([5, 13])).tolist() == [3, 4, 10, 11, 12]


def test_a_disturbed_unit_adds_each_disturbance_to_its_state_s_derivative():
    """Driven with zeros it runs as the unit, bit for bit; ``w/dt`` held over one sample moves
    the disturbed state by about ``w`` (exactly for a pure integrator)."""
    model, u, rng = _model_and_inputs(600, 1)
    disturbed = model.disturbed(["m.q", "m.x"])
    assert disturbed.spec.inputs == ("u", "v", "_w_0", "_w_1")
    assert disturbed.param_names == model.param_names
    starts, stops = np.array([0, 300]), np.array([250, 600])
    x0 = rng.uniform(0, 1, (2, 3))
    theta = [4.0, 0.6, 0.3]
    kwargs = dict(substeps=2, linear=[False, True, False, False])
    y, states = model.simulate(u, theta, starts, stops, x0, 0.05, substeps=2, linear=[False, True])
    zeros = np.hstack([u, np.zeros((600, 2))])
    y0, states0 = disturbed.simulate(zeros, theta, starts, stops, x0, 0.05, **kwargs)
    assert np.array_equal(y, y0, equal_nan=True) and np.array_equal(states, states0, equal_nan=True)
    kick = zeros.copy()
    kick[100, 3] = 1e-3 / 0.05  # x moves by 1e-3 over sample 100 (its derivative is w)
    _, kicked = disturbed.simulate(kick, theta, starts, stops, x0, 0.05, **kwargs)
    assert kicked[101, 0] - states0[101, 0] == pytest.approx(1e-3, rel=0.02)
    assert np.array_equal(kicked[:101], states0[:101], equal_nan=True)
    with pytest.raises(ValueError, match=r"states m\.h are not the unit's"):
        model.disturbed(["m.h"])
