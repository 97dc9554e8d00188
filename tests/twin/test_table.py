"""The twin table (dtwin/twin/table.py, blocks.py, paper_chain.py) and its YAML loader.

The issue's two-tank example, every bad-table rule with its one line, the strict YAML loader,
each built-in block's lowering checked against its law, algebraic loops, the paper's chain.
"""

from __future__ import annotations

import copy
import re
import time

import numpy as np
import pytest
import yaml

from dtwin._validation import DtwinValueError
from dtwin.gap.twin_file import is_table, load_twin_text, table_file
from dtwin.twin.blocks import BLOCKS, lower_block
from dtwin.twin.expressions import parse_expression
from dtwin.twin.paper_chain import paper_table
from dtwin.twin.table import TwinTableError, check_recorded, table_from_mapping
from tests.conftest import REPO

TWO_TANKS = """
dt: 4.0
discretisation: zoh
modules:
  pump:
    block: lag
    inputs: [u]
    outputs: [q]
    params: {tau: 8.0, gain: 0.05}
  tanks:
    inputs: [q]
    outputs: [level]
    states: [h1, h2]
    initial: {h1: 28.0}
    params: {a1: 0.04, a2: 0.03, offset: 0.0}
    derivatives:
      h1: "q - a1*sqrt(max(h1, 0))"
      h2: "a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))"
    equations:
      level: "h2 + offset"
noise: {level: 0.02}
"""


def two_tanks() -> dict:
    return load_twin_text(TWO_TANKS)


def test_the_two_tank_example_parses():
    table = table_from_mapping(two_tanks())
    assert [m.name for m in table.modules] == ["pump", "tanks"]
    assert table.dt == 4.0 and table.discretisation == "zoh"
    assert table.exogenous == ("u",) and table.signals == ("q", "level")
    assert table.noise == {"level": 0.02}
    pump, tanks = table.modules
    assert pump.block == "lag" and pump.linear and pump.source == "block lag"
    assert pump.states == ("y",) and pump.params == {"tau": 8.0, "gain": 0.05, "bias": 0.0}
    assert pump.derivatives == {"y": "(gain*u - y)/tau"} and pump.equations == {"q": "y + bias"}
    assert tanks.block is None and not tanks.linear and tanks.source == "equations"
    assert tanks.states == ("h1", "h2") and tanks.initial == {"h1": 28.0}
    assert tanks.params == {"a1": 0.04, "a2": 0.03, "offset": 0.0}
    assert tanks.equations == {"level": "h2 + offset"} and tanks.output_states == {}
    assert tanks.candidates is None
    assert table.producer("q") is pump and table.producer("u") is None
    assert table.module("tanks") is tanks
    check_recorded(table, ["u", "level"])


def test_modules_come_after_their_producers_in_declaration_order_otherwise():
    content = two_tanks()
    content["modules"] = dict(reversed(list(content["modules"].items())))
    content["modules"]["probe"] = {"block": "gain", "inputs": ["u"], "outputs": ["u2"]}
    table = table_from_mapping(content)
    assert [m.name for m in table.modules] == ["pump", "tanks", "probe"]


def test_an_output_named_like_a_state_is_that_state_and_dt_comes_from_the_recording():
    content = {"twin": {"modules": {"tank": {
        "inputs": ["q"], "outputs": ["h"], "states": ["h"], "params": {"a": 1e-5},
        "derivatives": {"h": "q - a*h"}, "candidates": ["state_limit"]}}}}  # fmt: skip
    table = table_from_mapping(content, dt=0.5)
    (tank,) = table.modules
    assert tank.output_states == {"h": "h"} and tank.equations == {}
    assert tank.candidates == ("state_limit",) and table.dt == 0.5 and table.noise == {}


def _with(path: str, value, base: str = TWO_TANKS) -> dict:
    """The two-tank content with ``value`` at ``path`` (``a/b/c``; ``None`` value deletes)."""
    content = load_twin_text(base)
    *parents, last = path.split("/")
    node = content
    for key in parents:
        node = node[key]
    if value is None:
        del node[last]
    else:
        node[last] = value
    return content


BAD = [
    # (path, value, expected message, after "twin file: ")
    ("extra", 1, "extra: unknown top-level key"),
    ("plant", {"m": 1}, "plant: a section of the paper's twin: shape"),
    ("modules", None, "modules: must be a non-empty mapping"),
    ("modules", {}, "modules: must be a non-empty mapping of module names (empty)"),
    ("modules", ["pump"], "modules: must be a non-empty mapping"),
    ("dt", -1.0, "dt: must be a finite number > 0 (got -1.0)"),
    ("dt", True, "dt: must be a number (got true)"),
    ("discretisation", "euler", "discretisation: must be zoh or foh (got 'euler'"),
    ("modules/2pump", {"block": "gain"}, "modules: '2pump' is not a valid name"),
    ("modules/pump", [1], "module 'pump': must be a mapping with keys among block"),
    ("modules/pump/colour", "red", "module 'pump': colour: unknown key (allowed: block"),
    ("modules/pump/block", "lagg", "module 'pump': block: unknown block 'lagg' (blocks: lag,"),
    ("modules/pump/states", ["y"], "module 'pump': states: a block module takes no 'states'"),
    ("modules/pump/inputs", "u", "module 'pump': inputs: must be a list of names, e.g. [u]"),
    ("modules/pump/inputs", ["u", 3], "module 'pump': inputs: 3 is not a name (got int)"),
    ("modules/pump/inputs", ["u-1"], "module 'pump': inputs: 'u-1' is not a valid name"),
    ("modules/pump/inputs", ["u", "u"], "module 'pump': inputs: 'u' is listed twice"),
    ("modules/pump/inputs", ["t"], "module 'pump': inputs: 't' is reserved (time)"),
    ("modules/pump/outputs", ["sqrt"], "module 'pump': outputs: 'sqrt' is reserved (a function)"),
    ("modules/pump/outputs", ["u"], "module 'pump': outputs: 'u' is also an input of the module"),
    ("modules/pump/inputs", ["u", "w"], "module 'pump': inputs: block 'lag' takes 1 input(s)"),
    ("modules/pump/params", {"gain": 1}, "module 'pump': params.tau: is required by block 'lag'"),
    ("modules/pump/params/tau", 0, "module 'pump': params.tau: must be > 0 (got 0)"),
    ("modules/pump/params/tau", True, "module 'pump': params.tau: must be a number (got true)"),
    ("modules/pump/params/tau", "1e-5x", "module 'pump': params.tau: must be a number (got str"),
    ("modules/pump/params/taux", 1, "module 'pump': params.taux: unknown param of block 'lag'"),
    ("modules/pump/params", 3, "module 'pump': params: must be a mapping of param names"),
    ("modules/pump/inputs", ["y"], "module 'pump': inputs: 'y' is also the name of a state of"),
    ("modules/tanks/outputs", [], "module 'tanks': outputs: an equations module needs at least"),
    ("modules/tanks/params/h1", 1.0, "module 'tanks': params.h1: 'h1' is also a state"),
    ("modules/tanks/params/q", 1.0, "module 'tanks': params.q: 'q' is also an input"),
    ("modules/tanks/states", ["h1", "h2", "q"], "module 'tanks': states: 'q' is also an input"),
    ("modules/tanks/states", ["h1", "h2", "h1"], "module 'tanks': states: 'h1' is listed twice"),
    ("modules/tanks/params/a1", float("inf"), "module 'tanks': params.a1: must be finite"),
    ("modules/tanks/params/a1", True, "module 'tanks': params.a1: must be a number (got true)"),
    ("modules/tanks/initial/h3", 1.0, "module 'tanks': initial.h3: 'h3' is not a state"),
    ("modules/tanks/initial/h1", "x", "module 'tanks': initial.h1: must be a number (got 'x')"),
    ("modules/tanks/derivatives/h2", None, "module 'tanks': derivatives: state 'h2' has no deriv"),
    ("modules/tanks/derivatives/h3", "1", "module 'tanks': derivatives.h3: 'h3' is not a state"),
    ("modules/tanks/derivatives/h1", True, "module 'tanks': derivatives.h1: must be an express"),
    ("modules/tanks/derivatives/h1", "q2 - h1", "module 'tanks': derivatives.h1: unknown name"),
    ("modules/tanks/derivatives/h1", "foo(h1)", "module 'tanks': derivatives.h1: unknown function"),
    ("modules/tanks/derivatives/h1", "h1 +", "module 'tanks': derivatives.h1: syntax error"),
    ("modules/tanks/derivatives/h1", "level", "module 'tanks': derivatives.h1: unknown name 'le"),
    ("modules/tanks/derivatives/h1", "q/a1 - 1/offset", "module 'tanks': derivatives.h1: "
     "'q/a1 - 1/offset' is not finite at the start (got -inf"),
    ("modules/tanks/equations/h2", "h2", "module 'tanks': equations.h2: 'h2' is a state"),
    ("modules/tanks/equations/lvl", "h2", "module 'tanks': equations.lvl: 'lvl' is not an output"),
    ("modules/tanks/equations", None, "module 'tanks': outputs: 'level' is neither a state nor"),
    ("modules/tanks/candidates", "all", "module 'tanks': candidates: must be a list of names"),
    ("modules/tanks/candidates", ["leak"], "module 'tanks': candidates: unknown effect 'leak'"),
    ("modules/u", {"block": "gain", "inputs": ["q"], "outputs": ["w"]}, "module 'pump': inputs: "
     "'u' is both a module and a signal"),
    ("modules/pump2", {"block": "gain", "inputs": ["u"], "outputs": ["q"]}, "module 'pump2': "
     "outputs: 'q' is also produced by module 'pump'"),
    ("noise/levl", 0.1, "noise.levl: 'levl' is neither an output signal nor a module"),
    ("noise/u", 0.1, "noise.u: 'u' is neither an output signal nor a module"),
    ("noise/level", 0.0, "noise.level: must be a finite number > 0 (got 0.0)"),
    ("noise/pump", "big", "noise.pump: must be a number (got 'big')"),
    ("noise", [0.1], "noise: must be a mapping of output signals or modules to numbers"),
    ("process_noise", {"tanks.h3": 0.1}, "process_noise.tanks.h3: 'tanks.h3' is neither "
     "<module>.<state> nor a module with states (states: pump.y, tanks.h1, tanks.h2)"),
    ("process_noise", {"level": 0.1}, "process_noise.level: 'level' is neither "
     "<module>.<state>"),
    ("process_noise", {"tanks.h1": -0.1}, "process_noise.tanks.h1: must be a finite number >= 0 "
     "(got -0.1)"),
    ("process_noise", {"tanks.h1": float("nan")}, "process_noise.tanks.h1: must be finite "
     "(got nan)"),
    ("process_noise", {"pump": True}, "process_noise.pump: must be a number (got true)"),
    ("process_noise", {"pump.y": "big"}, "process_noise.pump.y: must be a number (got 'big')"),
    ("process_noise", [0.1], "process_noise: must be a mapping of <module>.<state> or modules"),
]  # fmt: skip


@pytest.mark.parametrize(("path", "value", "message"), BAD, ids=[b[2][:48] for b in BAD])
def test_each_bad_table_gets_one_line_naming_module_key_and_token(path, value, message):
    with pytest.raises(TwinTableError) as caught:
        table_from_mapping(_with(path, value))
    text = str(caught.value)
    assert text.startswith("twin file: " + message), text
    assert "\n" not in text and caught.value.rule in text
    assert caught.value.token == "" or caught.value.token in text


def test_the_parser_error_keeps_its_token_and_the_module_and_key():
    with pytest.raises(TwinTableError) as caught:
        table_from_mapping(_with("modules/tanks/derivatives/h1", "q2 - h1"))
    error = caught.value
    assert (error.module, error.key, error.token) == ("tanks", "derivatives.h1", "q2")
    assert str(error) == "twin file: module 'tanks': derivatives.h1: unknown name 'q2'"


@pytest.mark.parametrize(
    ("text", "accepted"),
    [("log(h1)", True), ("1/(h2 - 1)", True), ("sqrt(a1 - 1)", False), ("1/(q - q)", False)],
)
def test_the_start_is_probed_at_declared_values_then_0_1_and_10(text, accepted):
    content = _with("modules/tanks/derivatives/h2", text)
    if accepted:
        table_from_mapping(content)
    else:
        with pytest.raises(TwinTableError, match=r"derivatives\.h2: .* is not finite at the start"):
            table_from_mapping(content)


def test_an_input_neither_recorded_nor_produced_is_refused_against_the_recording():
    table = table_from_mapping(two_tanks())
    with pytest.raises(TwinTableError) as caught:
        check_recorded(table, ["t", "level"])
    assert str(caught.value) == (
        "twin file: module 'pump': inputs: 'u' is neither a recording column nor produced by a "
        "module"
    )


def test_noise_by_module_expands_to_its_outputs_and_a_signal_entry_wins():
    table = table_from_mapping(_with("noise", {"tanks": 0.5, "pump": 0.1, "level": 0.02}))
    assert table.noise == {"q": 0.1, "level": 0.02}


def test_process_noise_by_module_expands_to_its_states_and_a_state_entry_wins():
    table = table_from_mapping(_with("process_noise", {"tanks": 0.5, "tanks.h2": 0.02}))
    assert table.process_noise == {"tanks.h1": 0.5, "tanks.h2": 0.02}
    # 0 takes a state out of its module's entry; the measurement noise is left as declared
    table = table_from_mapping(_with("process_noise", {"tanks": 0.5, "tanks.h1": 0, "pump": 1}))
    assert table.process_noise == {"pump.y": 1.0, "tanks.h2": 0.5}
    assert table.noise == {"level": 0.02}
    assert table_from_mapping(two_tanks()).process_noise == {}  # a table without the key


def test_process_noise_on_a_module_without_states_is_refused():
    content = two_tanks()
    content["modules"]["trim"] = {"block": "gain", "inputs": ["level"], "outputs": ["lv"]}
    content["process_noise"] = {"trim": 0.1}
    with pytest.raises(TwinTableError, match=r"^twin file: process_noise\.trim: 'trim' is neither"):
        table_from_mapping(content)


def test_a_missing_module_is_named():
    with pytest.raises(TwinTableError, match="no module 'tank' "):
        table_from_mapping(two_tanks()).module("tank")


# --- algebraic loops ---------------------------------------------------------------------------

LOOP = {
    "a": {"inputs": ["u", "b_out"], "outputs": ["a_out"], "equations": {"a_out": "u - b_out"}},
    "b": {"block": "gain", "inputs": ["a_out"], "outputs": ["b_out"], "params": {"gain": 0.5}},
}


def test_an_algebraic_loop_is_refused_naming_its_modules():
    with pytest.raises(TwinTableError) as caught:
        table_from_mapping({"modules": LOOP})
    assert str(caught.value) == (
        "twin file: module 'a': equations.a_out: algebraic loop through module(s) 'a', 'b' "
        "(signals b_out -> a_out -> b_out): a loop must pass through a state"
    )


def test_a_loop_through_a_state_is_accepted():
    modules = copy.deepcopy(LOOP)
    modules["b"] = {"block": "lag", "inputs": ["a_out"], "outputs": ["b_out"],
                    "params": {"tau": 2.0}}  # fmt: skip
    table = table_from_mapping({"modules": modules})
    assert [m.name for m in table.modules] == ["a", "b"] and table.exogenous == ("u",)


def test_a_state_space_feedthrough_is_algebraic_only_where_d_is_not_zero():
    ss = {"block": "state_space", "inputs": ["a_out"], "outputs": ["b_out"],
          "params": {"A": [[-1.0]], "B": [[1.0]], "C": [[1.0]]}}  # fmt: skip
    table_from_mapping({"modules": {**LOOP, "b": ss}})
    ss["params"]["D"] = [[0.2]]
    with pytest.raises(TwinTableError, match="algebraic loop through module"):
        table_from_mapping({"modules": {**LOOP, "b": ss}})


# --- blocks: each lowering against its law ------------------------------------------------------

rng = np.random.default_rng(3)
POINT = {"u": 0.7, "u2": -1.3, "x": 0.4, "v": -0.9, "y": 1.6, "t": 0.0}


def _lowered_values(block, inputs, outputs, params):
    """The lowered derivatives and equations, parsed and evaluated at POINT and the params."""
    low = lower_block(block, inputs, outputs, params)
    symbols = {*low.params, *low.states, *inputs, "t"}
    values = {**POINT, **low.params}
    values.update({s: float(rng.normal()) for s in low.states if s not in values})
    evaluate = {
        key: parse_expression(text, symbols).evaluate(values)
        for key, text in {**low.derivatives, **low.equations}.items()
    }
    return low, values, evaluate


def test_lag_lowers_to_its_law():
    _, p, out = _lowered_values("lag", ["u"], ["q"], {"tau": 8.0, "gain": 0.05, "bias": 0.3})
    assert out["y"] == pytest.approx((0.05 * p["u"] - p["y"]) / 8.0)
    assert out["q"] == pytest.approx(p["y"] + 0.3)


def test_mass_spring_damper_lowers_to_its_law():
    low, p, out = _lowered_values("mass_spring_damper", ["u"], ["pos", "vel"],
                                  {"m": 2.0, "c": 0.4, "k": 4.0})  # fmt: skip
    assert out["x"] == pytest.approx(p["v"])
    assert out["v"] == pytest.approx((p["u"] - 0.4 * p["v"] - 4.0 * p["x"]) / 2.0)
    assert low.output_states == {"pos": "x", "vel": "v"} and low.equations == {}
    only_x = lower_block("mass_spring_damper", ["u"], ["x"], {"m": 1, "c": 0, "k": 0})
    assert only_x.output_states == {"x": "x"}


def test_integrator_gain_and_weighted_sum_lower_to_their_laws():
    low, p, out = _lowered_values("integrator", ["u"], ["w"], {"gain": 2.5})
    assert out["y"] == pytest.approx(2.5 * p["u"]) and low.output_states == {"w": "y"}
    _, p, out = _lowered_values("gain", ["u"], ["w"], {"gain": -2.0, "bias": 0.25})
    assert out["w"] == pytest.approx(-2.0 * p["u"] + 0.25)
    low, p, out = _lowered_values("weighted_sum", ["u", "u2"], ["w"], {"weights": [0.6, 0.4]})
    assert low.params == {"w1": 0.6, "w2": 0.4}
    assert out["w"] == pytest.approx(0.6 * p["u"] + 0.4 * p["u2"])


def test_state_space_lowers_to_a_s_plus_b_u():
    a = rng.normal(size=(3, 3))
    b, c, d = rng.normal(size=(3, 2)), rng.normal(size=(2, 3)), np.array([[0.0, 0.5], [0, 0]])
    params = {"A": a.tolist(), "B": b.tolist(), "C": c.tolist(), "D": d.tolist()}
    low, p, out = _lowered_values("state_space", ["u", "u2"], ["o1", "o2"], params)
    assert low.states == ("s1", "s2", "s3")
    assert {"a11", "a33", "b32", "c23", "d12"} <= set(low.params) and "d11" not in low.params
    s, u = np.array([p[f"s{i}"] for i in (1, 2, 3)]), np.array([p["u"], p["u2"]])
    np.testing.assert_allclose([out[f"s{i}"] for i in (1, 2, 3)], a @ s + b @ u, rtol=1e-12)
    np.testing.assert_allclose([out["o1"], out["o2"]], c @ s + d @ u, rtol=1e-12)


def test_every_block_is_covered_by_a_lowering_test():
    assert set(BLOCKS) == {"lag", "mass_spring_damper", "integrator", "gain", "weighted_sum",
                           "state_space"}  # fmt: skip


@pytest.mark.parametrize(
    ("block", "inputs", "outputs", "params", "message"),
    [
        ("mass_spring_damper", ["f"], ["x"], {"m": 0, "c": 0, "k": 0}, "params.m: must be > 0"),
        ("mass_spring_damper", ["f"], ["x"], {"m": 1, "c": -1, "k": 0}, "params.c: must be >= 0"),
        ("mass_spring_damper", ["f"], ["x", "v", "a"], {"m": 1, "c": 0, "k": 0}, "outputs: block"),
        ("weighted_sum", ["a", "b"], ["y"], {"weights": [1.0]}, "params.weights: needs one"),
        ("weighted_sum", ["a"], ["y"], {}, "params.weights: is required"),
        ("state_space", ["u"], ["y"], {"A": [[1, 2]], "B": [[1]], "C": [[1]]}, "params.A: must be"),
        ("state_space", ["u"], ["y"], {"A": [[1]], "C": [[1]]}, "params.B: is required"),
        ("state_space", ["u"], ["y"], {"A": [[1]], "B": [[1, 2]], "C": [[1]]}, "params.B: must be"),
        ("state_space", ["u"], ["y"], {"A": [[1]], "B": [[1]], "C": [[1, 0]]}, "params.C: must be"),
        ("state_space", ["u"], ["y"], {"A": [[1], [1, 2]], "B": [[1]], "C": [[1]]},
         "params.A: rows"),
        ("state_space", ["u"], ["y"], {"A": [[1]], "B": [[1]], "C": [[1]], "D": [[1, 1]]},
         "params.D: must be 1×1"),
    ],
)  # fmt: skip
def test_block_param_rules(block, inputs, outputs, params, message):
    entry = {"block": block, "inputs": inputs, "outputs": outputs, "params": params}
    with pytest.raises(TwinTableError, match=re.escape(f"module 'm': {message}")):
        table_from_mapping({"modules": {"m": entry}})


# --- the YAML loader ------------------------------------------------------------------------------


def test_yaml_numbers_are_read_as_users_write_them():
    content = load_twin_text("a: 1e-5\nb: 2E3\nc: 1.0e5\nd: -3e+2\ne: true\nf: 1.5")
    assert content == {"a": 1e-5, "b": 2000.0, "c": 1e5, "d": -300.0, "e": True, "f": 1.5}
    assert yaml.safe_load("a: 1e-5") == {"a": "1e-5"}  # what the loader fixes


def test_yaml_duplicate_module_keys_are_refused_with_their_line():
    text = TWO_TANKS.replace("  tanks:", "  pump:")
    with pytest.raises(DtwinValueError, match=r"^twin file: line 10: duplicate key 'pump'$"):
        load_twin_text(text)


def test_a_billion_laughs_is_refused_within_a_second():
    lines = ['l0: &l0 "lol"'] + [
        f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, 10)
    ]
    start = time.perf_counter()
    with pytest.raises(DtwinValueError, match=r"line 2: aliases \('\*l0'\) are not allowed"):
        load_twin_text("\n".join(lines))
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x" * 1_000_001, "twin file is larger than 1 MB"),
        ("a: [1, 2", "twin file is not valid YAML: line 1, column 9: expected ',' or ']'"),
        ("a: " + "[" * 60 + "]" * 60, "twin file: line 1: nested more than 50 levels deep"),
        ("base: &b {x: 1}\nc:\n  <<: {y: 2}", "twin file: line 3: merge keys (<<) are not"),
    ],
)
def test_yaml_that_is_too_large_deep_or_broken_is_one_line(text, message):
    with pytest.raises(DtwinValueError) as caught:
        load_twin_text(text)
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)


def test_a_boolean_param_from_yaml_is_refused():
    with pytest.raises(TwinTableError, match=r"params.tau: must be a number \(got true\)"):
        table_file(load_twin_text(TWO_TANKS.replace("tau: 8.0", "tau: true")))


def test_is_table_tells_the_shapes_apart():
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    assert is_table(two_tanks()) and is_table({"twin": two_tanks()})
    assert not is_table(config) and not is_table({"twin": config["twin"]}) and not is_table(None)
    assert table_file({"twin": two_tanks()}, dt=9.0).dt == 4.0


# --- the paper's chain --------------------------------------------------------------------------


def test_the_paper_config_gives_the_six_module_table():
    sections = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["twin"]
    table = paper_table(sections)
    wiring = {m.name: (m.block, m.inputs, m.outputs) for m in table.modules}
    assert wiring == {
        "M0": ("lag", ("u_cmd",), ("u_act",)),
        "M1": ("mass_spring_damper", ("u_act",), ("x", "v")),
        "M2a": ("lag", ("x",), ("y_A",)),
        "M2b": ("lag", ("x",), ("y_B",)),
        "M3": ("weighted_sum", ("y_A", "y_B"), ("y_fused",)),
        "M4": ("weighted_sum", ("x", "v"), ("z",)),
    }
    assert list(wiring) == [m.name for m in table.modules] and table.exogenous == ("u_cmd",)
    assert table.module("M0").params == {"tau": 0.15, "gain": 1.0, "bias": 0.0}
    assert table.module("M1").params == {"m": 1.0, "c": 0.4, "k": 4.0}
    assert table.module("M1").output_states == {"x": "x", "v": "v"}
    assert table.module("M2b").params == {"tau": 0.25, "gain": 1.0, "bias": 0.01}
    assert table.module("M3").params == pytest.approx({"w1": 0.6, "w2": 0.4})
    assert table.module("M4").params == {"w1": 1.0, "w2": 0.2}
    # the sensors' noise is measurement noise; the plant's (m/s²) is held over a step in the
    # acceleration: dt times it on the velocity; the actuator's is a jump of its lag's state per
    # sample, which a disturbance held over the sample gives at (dt/τ)/(1 − exp(−dt/τ)) times it
    assert table.noise == {"y_A": 0.03, "y_B": 0.02}
    steps = 0.02 / 0.15
    assert table.process_noise == pytest.approx(
        {"M0.y": 0.005 * steps / (1 - np.exp(-steps)), "M1.v": 0.04 * 0.02}, rel=1e-12
    )
    assert table.dt == 0.02 and table.discretisation is None  # the config says euler


def test_the_paper_chain_s_process_noise_needs_dt():
    sections = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["twin"]
    del sections["dt"]
    with pytest.raises(TwinTableError, match=r"^twin file: dt: must be a number > 0 \(got None"):
        paper_table(sections)
    del sections["noise"]["actuator"], sections["noise"]["plant"]
    assert paper_table(sections).process_noise == {}


def test_the_paper_chain_needs_every_section():
    sections = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["twin"]
    del sections["plant"]
    with pytest.raises(TwinTableError, match=r"^twin file: plant: missing"):
        paper_table(sections)
