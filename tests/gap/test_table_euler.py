"""Discrete modules of a twin table: ``discretisation: euler`` and ``zoh`` step once per sample.

The paper's chain written as a table (``paper_table`` with the paper simulator's ``euler``) is
the paper's simulator: its plant the same bits, its lags exact to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.physics import actuator_lpf, plant_msd, sensor_first_order
from dtwin.twin.paper_chain import paper_table
from dtwin.twin.paper_modules import ZOH, plant_response
from dtwin.twin.simulate import UnitModel, units_of, window_rows
from dtwin.twin.table import TwinTableError, table_from_mapping
from tests.conftest import paper_twin

#: The paper's twin (config/config.yaml), noise-free, stepped as the paper's simulator steps.
SECTIONS = {
    **{k: v for k, v in paper_twin().items() if k != "noise"},
    "discretisation": "euler",
}
DT = SECTIONS["dt"]


def _command(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-2.0, 2.0, n // 40 + 1), 40)[:n] + 0.2 * rng.standard_normal(n)


def _paper_signals(u_cmd: np.ndarray, accel_noise=None) -> dict[str, np.ndarray]:
    plant, a, b = SECTIONS["plant"], SECTIONS["sensor_A"], SECTIONS["sensor_B"]
    u_act = actuator_lpf(u_cmd, SECTIONS["actuator"]["tau"], DT)
    moved = plant_msd(u_act, plant["m"], plant["c"], plant["k"], DT, accel_noise)
    return {
        "u_cmd": u_cmd, "u_act": u_act, "x": moved.x, "v": moved.v,
        "y_A": sensor_first_order(moved.x, a["tau"], DT, a["bias"]),
        "y_B": sensor_first_order(moved.x, b["tau"], DT, b["bias"]),
    }  # fmt: skip


def _run(unit, signals, n, extra=None, model=None):
    model = model or UnitModel.from_spec(unit)
    columns = [signals[s] if s in signals else extra[s] for s in model.spec.inputs]
    inputs = np.column_stack(columns) if columns else np.zeros((n, 0))
    x0 = np.zeros((1, len(unit.states)))
    y, _ = model.simulate(inputs, list(unit.params.values()), [0], [n], x0, DT)
    return {o: y[:, i] for i, o in enumerate(unit.outputs)}


def test_paper_table_steps_the_plant_by_euler_and_the_lags_exactly():
    table = paper_table(SECTIONS)
    steps = {m.name: m.discretisation for m in table.modules}
    assert steps == {"M0": "zoh", "M1": "euler", "M2a": "zoh", "M2b": "zoh",
                     "M3": "continuous", "M4": "continuous"}  # fmt: skip
    silent = paper_table({k: v for k, v in SECTIONS.items() if k != "discretisation"})
    assert {m.discretisation for m in silent.modules} == {"continuous"}


def test_the_paper_chain_as_a_table_is_the_paper_simulator():
    n = 3000
    signals = _paper_signals(_command(n, 1))
    table = paper_table(SECTIONS)
    # every internal signal recorded: one module per unit
    units = units_of(table, list(signals))
    out = {o: y for unit in units for o, y in _run(unit, signals, n).items()}
    assert np.array_equal(out["x"], signals["x"]) and np.array_equal(out["v"], signals["v"])
    for name in ("u_act", "y_A", "y_B"):
        scale = np.max(np.abs(signals[name]))
        assert np.max(np.abs(out[name] - signals[name])) <= 1e-12 * scale, name
    # only the command and the sensors recorded: the whole chain is one unit
    (unit,) = units_of(table, ["u_cmd", "y_A", "y_B"])
    assert unit.modules == ("M0", "M1", "M2a", "M2b", "M4")  # M4 reads the unrecorded x, v
    out = _run(unit, signals, n)
    for name in ("y_A", "y_B"):
        scale = np.max(np.abs(signals[name]))
        assert np.max(np.abs(out[name] - signals[name])) <= 1e-12 * scale, name
    # a continuous plant is not the Euler one (the error is the discretisation's)
    continuous = paper_table({**SECTIONS, "discretisation": "zoh"})
    (unit,) = [u for u in units_of(continuous, list(signals)) if u.modules == ("M1",)]
    x = _run(unit, signals, n)["x"]
    assert np.max(np.abs(x - signals["x"])) > 1e-3 * np.max(np.abs(signals["x"]))


def test_an_euler_plant_s_process_noise_is_the_paper_s_acceleration_noise():
    n = 2000
    xi = np.random.default_rng(3).standard_normal(n) * 0.04
    xi[0] = 0.0
    signals = _paper_signals(_command(n, 2), accel_noise=xi)
    (unit,) = [u for u in units_of(paper_table(SECTIONS), list(signals)) if u.modules == ("M1",)]
    model = UnitModel.from_spec(unit).disturbed(["M1.v"])
    w = np.zeros(n)
    w[:-1] = xi[1:]  # held over sample k: the paper's ξ of step k + 1
    out = _run(unit, signals, n, {"_w_0": w}, model)
    assert np.max(np.abs(out["v"] - signals["v"])) <= 1e-12 * np.max(np.abs(signals["v"]))
    assert np.max(np.abs(out["x"] - signals["x"])) <= 1e-12 * np.max(np.abs(signals["x"]))


def test_a_candidate_term_in_an_euler_plant_is_the_paper_plant_s_force():
    n = 2000
    u = _command(n, 4)
    k3 = 2.5
    paper = plant_response(u, 1.0, 0.4, 4.0, DT, force=lambda x, v: k3 * x**3)
    table = table_from_mapping({"dt": DT, "modules": {"M1": {
        "block": "mass_spring_damper", "inputs": ["u_act"], "outputs": ["x", "v"],
        "params": {"m": 1.0, "c": 0.4, "k": 4.0}, "discretisation": "euler"}}})  # fmt: skip
    (unit,) = units_of(table, ["u_act", "x", "v"])
    model = UnitModel.from_spec(unit)
    text = next(a.text for a in model.assignments if a.target == "d/M1.v")
    variant = model.variant({"d/M1.v": f"({text}) - _e_k3*x**3/m"}, extra=("_e_k3",))
    inputs = u[:, None]
    y, _ = variant.simulate(inputs, [1.0, 0.4, 4.0, k3], [0], [n], np.zeros((1, 2)), DT)
    assert np.max(np.abs(y[:, 0] - paper.x)) <= 1e-12 * np.max(np.abs(paper.x))
    assert np.max(np.abs(y[:, 0] - plant_response(u, 1.0, 0.4, 4.0, DT).x)) > 1e-3


def test_a_zoh_mass_spring_damper_is_the_exact_zero_order_hold():
    n = 2000
    u = _command(n, 5)
    for dt in (0.02, 0.5):  # 0.5 s: a coarse sample, the exponential scaled and squared
        exact = plant_response(u, 2.0, 0.7, 30.0, dt, x0=0.1, v0=-0.2, discretisation=ZOH)
        table = table_from_mapping({"dt": dt, "modules": {"p": {
            "block": "mass_spring_damper", "inputs": ["f"], "outputs": ["x", "v"],
            "params": {"m": 2.0, "c": 0.7, "k": 30.0}, "discretisation": "zoh"}}})  # fmt: skip
        (unit,) = units_of(table, ["f", "x", "v"])
        y, _ = UnitModel.from_spec(unit).simulate(
            u[:, None], [2.0, 0.7, 30.0], [0], [n], np.array([[0.1, -0.2]]), dt
        )
        for i, name in enumerate(("x", "v")):
            truth = getattr(exact, name)
            assert np.max(np.abs(y[:, i] - truth)) <= 1e-12 * np.max(np.abs(truth)), (dt, name)


def test_a_batch_of_discrete_runs_gives_each_member_the_bits_of_its_own_run():
    table = paper_table(SECTIONS)
    (unit,) = units_of(table, ["u_cmd", "y_A", "y_B"])
    model = UnitModel.from_spec(unit)
    n = 900
    u = _command(n, 6)[:, None]
    starts, stops = np.array([0, 200, 500]), np.array([150, 420, 899])
    theta = np.array(list(unit.params.values()))
    thetas = [theta, theta * 1.05, theta * 0.9]
    x0 = np.random.default_rng(7).uniform(-0.5, 0.5, (3, 3, len(unit.states)))
    y, _ = model.simulate_batch([u], [0, 0, 0], thetas, starts, stops, x0, DT)
    rows = window_rows(starts, stops)
    for b in range(3):
        alone, _ = model.simulate(u, thetas[b], starts, stops, x0[b], DT)
        assert np.array_equal(alone[rows], y[b])


def _module(**extra):
    return {"dt": DT, "modules": {"tank": {
        "inputs": ["q"], "outputs": ["h"], "states": ["h"], "params": {"a": 0.3},
        "derivatives": {"h": "q - a*h"}, **extra}}}  # fmt: skip


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"discretisation": "rk4"}, "twin file: module 'tank': discretisation: must be one of "
                                    "continuous, euler, zoh (got 'rk4')"),
        ({"discretisation": True}, "twin file: module 'tank': discretisation: must be one of "
                                   "continuous, euler, zoh (got true)"),
    ],
)  # fmt: skip
def test_an_unknown_discretisation_is_refused_in_one_line(entry, message):
    with pytest.raises(TwinTableError) as error:
        table_from_mapping(_module(**entry))
    assert str(error.value) == message and error.value.key == "discretisation"


def test_a_module_without_states_takes_no_discretisation():
    gain = {"block": "gain", "inputs": ["u"], "outputs": ["y"], "discretisation": "euler"}
    with pytest.raises(TwinTableError, match=r"module 'g': discretisation: the module has no "
                                             r"states to step \(got euler"):  # fmt: skip
        table_from_mapping({"modules": {"g": gain}})


def test_a_unit_joining_discrete_and_continuous_modules_is_refused():
    table = table_from_mapping({"dt": DT, "modules": {
        "pump": {"block": "lag", "inputs": ["u"], "outputs": ["q"], "params": {"tau": 0.5},
                 "discretisation": "zoh"},
        "tank": _module()["modules"]["tank"]}})  # fmt: skip
    with pytest.raises(TwinTableError) as error:
        units_of(table, ["u", "h"])
    text = str(error.value)
    assert text.startswith("twin file: module 'pump': discretisation: zoh is a discrete module's")
    assert "module(s) tank" in text and "signal(s) q" in text and "\n" not in text
    # recorded, the flow separates them: each unit steps by its own rule
    assert [u.stepping for u in units_of(table, ["u", "q", "h"])] == [{"pump.y": "zoh"}, {}]


def test_continuous_said_or_silent_gives_the_same_bits():
    n = 1500
    u = _command(n, 8)[:, None]
    runs = []
    for extra in ({}, {"discretisation": "continuous"}):
        (unit,) = units_of(table_from_mapping(_module(**extra)), ["q", "h"])
        y, _ = UnitModel.from_spec(unit).simulate(u, [0.3], [0], [n], np.zeros((1, 1)), DT,
                                                  substeps=2)  # fmt: skip
        runs.append(y)
    assert np.array_equal(runs[0], runs[1])


def test_a_spring_s_cubic_candidate_is_the_paper_s_cubic_spring_away_from_rest():
    """The ``cubic_stiffness`` term is centred on the spring's rest ``x = 0``, so at its ``k3``
    it is the force ``k3·x³`` however far the recording's mean lies from rest."""
    import pandas as pd

    from dtwin.gap.recording import recording_with_columns
    from dtwin.gap.results import GapSettings
    from dtwin.gap.table_diagnose import _prepare_unit, _split
    from dtwin.gap.table_effects import candidate_variants, twin_variant
    from dtwin.gap.table_fit import state_guess

    n, k3 = 3000, 2.0
    u = _command(n, 9) + 1.5  # x sits about 0.37 from rest
    plant = plant_response(u, 1.0, 0.4, 4.0, DT, force=lambda x, v: k3 * x**3)
    frame = pd.DataFrame({"t": np.arange(n) * DT, "u_act": u, "x": plant.x, "v": plant.v})
    table = table_from_mapping({"dt": DT, "modules": {"M1": {
        "block": "mass_spring_damper", "inputs": ["u_act"], "outputs": ["x", "v"],
        "params": {"m": 1.0, "c": 0.4, "k": 4.0}, "discretisation": "euler"}}})  # fmt: skip
    recording = recording_with_columns(frame, ["u_act", "x", "v"])
    (spec,) = units_of(table, list(recording.signals))
    data = _prepare_unit(spec, recording, table, _split(n, 0.5, 0.5), GapSettings(), False)
    guess = state_guess(data, dict(spec.params), twin_variant(data))
    assert abs(np.nanmean(guess[:, 0])) > 0.3
    variants = candidate_variants(data, guess, {"M1": "mass_spring_damper"}, calibrate=False)
    cubic = next(v for v in variants if v.name == "cubic_stiffness")
    _, per_theta, _, sigma = cubic.report
    theta = k3 / per_theta(1.0, sigma)
    y, _ = cubic.model.simulate(u[:, None], [1.0, 0.4, 4.0, theta], [0], [n],
                                np.zeros((1, 2)), DT)  # fmt: skip
    assert np.max(np.abs(y[:, 0] - plant.x)) <= 1e-9 * np.max(np.abs(plant.x))
