"""An FMU as a module of a twin table (docs/gap.md §An FMU as a module).

The test FMU (tests/twin/fmu/motor.c, FMI 2.0 Model Exchange and Co-Simulation) is compiled here
from source and cached by its hash. Its physics are the motor benchmark family's
(dtwin/gapbench/family_assets.py): the family's cases are generated and diagnosed against the
FMU twin and against the family's twin merged into one expression module with the same
equations (tests/twin/fmu/twins.py), and the two must give the same answers.
"""

from __future__ import annotations

import functools
import json
import shutil
import zipfile
from dataclasses import replace

import numpy as np
import pytest
import yaml

from dtwin.cli import main
from dtwin.gap.recording import recording_with_columns
from dtwin.gap.table_diagnose import diagnose_table
from dtwin.gapbench.families import generate_family_case
from dtwin.twin import _fmu_kernels
from dtwin.twin.fmu import FmuModel, FmuModelExchange, model_for
from dtwin.twin.simulate import UnitModel, units_of
from dtwin.twin.table import TwinTableError, table_from_mapping
from tests.twin.fmu.build import SOURCES, build_fmu, compiler
from tests.twin.fmu.twins import MODULE, expression_twin, fmu_twin, write_fmu_case

pytestmark = pytest.mark.skipif(
    compiler() is None, reason="no C compiler (cc or gcc): the test FMU is built from source"
)

#: Samples of a generated case: short enough for a test, long enough for the effects below.
N_SAMPLES = 1000
#: The motor's states, as the FMU and the merged expression module name them.
STATES = ("i", "w")


@pytest.fixture(scope="module")
def fmu_path():
    return build_fmu()


@functools.cache
def _case(effect: str, seed: int):
    """A bare motor case (``V`` in, ``w`` recorded) at full strength."""
    return generate_family_case(f"motor_bare_{effect}", seed, n_samples=N_SAMPLES, magnitude=1.0)


def _fmu_table(path, interface="model_exchange", **changes):
    """The FMU twin of a clean case, with module keys changed."""
    mapping = fmu_twin(_case("none", 2), path, interface)
    mapping["modules"][MODULE].update(changes)
    return mapping


def _diagnose(mapping, frame, **kwargs):
    table = table_from_mapping(mapping)
    recording = recording_with_columns(frame, (*table.signals, *table.exogenous))
    return diagnose_table(recording, table, **kwargs)


def test_an_fmu_module_reads_its_states_params_and_outputs(fmu_path):
    table = table_from_mapping(_fmu_table(fmu_path))
    module = table.module(MODULE)
    assert (module.inputs, module.outputs, module.states) == (("V",), ("w",), STATES)
    assert module.params == expression_twin(_case("none", 2))["modules"][MODULE]["params"]
    assert list(module.params) == ["R", "L", "Ke", "Kt", "J", "b"]
    assert module.output_states == {"w": "w"}
    spec = units_of(table, ["V", "w"])[0]
    assert isinstance(model_for(spec, table), FmuModelExchange)
    cs = table_from_mapping(_fmu_table(fmu_path, "co_simulation"))
    model = model_for(units_of(cs, ["V", "w"])[0], cs)
    assert type(model) is FmuModel and model.restart == "start values"
    assert not hasattr(model, "derivatives")


@pytest.mark.parametrize("interface", ["model_exchange", "co_simulation"])
def test_the_fmu_simulates_as_the_expression_module(fmu_path, interface):
    """Equal to rounding: Model Exchange runs the expression's arithmetic through dtwin's RK4,
    Co-Simulation its own RK4 with 8 steps per sample (compared at 8 sub-steps here)."""
    case = _case("none", 2)
    table = table_from_mapping(fmu_twin(case, fmu_path, interface))
    model = model_for(units_of(table, ["V", "w"])[0], table)
    expression = table_from_mapping(expression_twin(case))
    reference = UnitModel.from_spec(units_of(expression, ["V", "w"])[0])
    theta = list(expression.module(MODULE).params.values())
    u = np.array(case.recording[["V"]], dtype=float)  # writable: the loops are compiled for it
    spread = np.array([0.01, 1.0]) * case.recording["w"].std()  # i is about w/100 here
    rng = np.random.default_rng(0)
    starts = np.arange(0, len(u), 200)
    x0 = rng.normal(size=(len(starts), 2)) * spread
    for linear in (False, True):
        args = (u, theta, starts, starts + 200, x0, case.twin["dt"])
        y, states = model.simulate(*args, substeps=8, linear=[linear])
        y_ref, states_ref = reference.simulate(*args, substeps=8, linear=[linear])
        assert np.all(np.isfinite(y)) and np.std(y) > 0.1 * spread[1]
        if interface == "model_exchange":
            assert np.array_equal(y, y_ref) and np.array_equal(states, states_ref)
        else:  # the input's slope over a step is rounded differently: 1e-12 of the spread
            assert np.max(np.abs(y - y_ref)) <= 1e-12 * spread[1]
            assert np.all(np.max(np.abs(states - states_ref), axis=0) <= 1e-12 * spread)
    if interface == "model_exchange":
        point = (np.array([1.0, 20.0]), np.array([12.0]), theta)
        assert np.array_equal(model.derivatives(*point), reference.derivatives(*point))
    loop = _fmu_kernels.me_windows if interface == "model_exchange" else _fmu_kernels.cs_window
    compiled = len(loop.signatures)
    u.setflags(write=False)  # as a pandas frame's to_numpy() under copy-on-write
    again, _ = model.simulate(*args, substeps=8, linear=[True])
    assert np.array_equal(again, y) and len(loop.signatures) == compiled


@functools.cache
def _by_expression(effect: str, seed: int):
    """The expression twin's diagnosis of a case (shared by both interfaces' tests)."""
    case = _case(effect, seed)
    return _diagnose(expression_twin(case), case.recording)


#: Motor cases (effect, seed) at N_SAMPLES: none, an input effect, an output effect and a
#: parameter mismatch, each a seed (of 1-3) whose effect the expression twin names (a case both
#: twins read as none, or one the expression twin reads as a state effect, which an FMU is not
#: offered, would test nothing here).
AGREEMENT_CASES = [
    pytest.param("model_exchange", "none", 2, id="ME-none"),
    pytest.param("model_exchange", "input_deadzone", 3, id="ME-input_deadzone"),
    pytest.param("co_simulation", "input_deadzone", 3, id="CS-input_deadzone"),
    pytest.param("model_exchange", "output_scale_error", 2, id="ME-output_scale_error"),
    pytest.param("model_exchange", "parameter_mismatch", 3, id="ME-parameter_mismatch"),
]


@pytest.mark.parametrize(("interface", "effect", "seed"), AGREEMENT_CASES)
def test_the_fmu_and_the_expression_twin_agree_on_motor_cases(fmu_path, interface, effect, seed):
    """Same module, effect and signal; Model Exchange: every number equal (each simulation is
    equal bit for bit); Co-Simulation (the FMU's own RK4, 8 steps per sample, against the
    expression's sub-steps): each param within a quarter of the expression's 95 % interval,
    the gap before within 0.1 %."""
    case = _case(effect, seed)
    by_expression = _by_expression(effect, seed)
    by_fmu = _diagnose(fmu_twin(case, fmu_path, interface), case.recording)
    answer = (by_expression.module, by_expression.effect, by_expression.at)
    assert by_expression.effect in case.key["accepted_effects"]
    assert (by_fmu.module, by_fmu.effect, by_fmu.at) == answer
    assert by_fmu.params.keys() == by_expression.params.keys()
    if interface == "model_exchange":
        assert by_fmu.params == by_expression.params
        assert by_fmu.param_intervals == by_expression.param_intervals
        assert (by_fmu.gap_before, by_fmu.gap_after) == (by_expression.gap_before,
                                                         by_expression.gap_after)  # fmt: skip
    else:
        for name, value in by_expression.params.items():
            low, high = by_expression.param_intervals[name]
            assert abs(by_fmu.params[name] - value) <= 0.25 * (high - low), name
        assert by_fmu.gap_before == pytest.approx(by_expression.gap_before, rel=1e-3)
    if by_fmu.effect != "none":
        assert "FMU internals are closed: no state effects" in " ".join(by_fmu.notes)
        assert not any(c["effect"].startswith("state") for c in by_fmu.candidates)


def test_an_fmu_that_cannot_restart_runs_once_per_part(fmu_path):
    case = _case("input_deadzone", 3)
    table = table_from_mapping(fmu_twin(case, fmu_path, "co_simulation"))
    info = table.module(MODULE).fmu
    closed = replace(info, restart="none", states=(), output_states={})
    module = replace(table.module(MODULE), fmu=closed, states=(), output_states={})
    table = replace(table, modules=(module,))
    result = diagnose_table(recording_with_columns(case.recording, ("V", "w")), table)
    assert result.units[MODULE].window == N_SAMPLES
    assert "one run from the FMU's own start values" in " ".join(result.notes)
    assert (result.effect, result.at) == ("input_deadzone", "V")


#: A valid FMI 3.0 description (refused: dtwin drives FMI 2.0 FMUs only).
FMI3_DESCRIPTION = b"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="motor" instantiationToken="{dtwin-motor-3}">
  <ModelExchange modelIdentifier="motor"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="V" valueReference="1" causality="input" start="0"/>
    <Float64 name="w" valueReference="2" causality="output"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="2"/></ModelStructure>
</fmiModelDescription>"""


def _zip(path, files: dict[str, bytes]):
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in files.items():
            archive.writestr(name, data)
    return path


@pytest.mark.parametrize(
    ("change", "key", "words"),
    [
        ({"fmu": "missing.fmu"}, "fmu", "no such file 'missing.fmu'"),
        ({"fmu": "text.fmu"}, "fmu", "is not an FMU (not a zip archive)"),
        ({"fmu": "empty.fmu"}, "fmu", "has no modelDescription.xml"),
        ({"fmu": "nobinary.fmu"}, "fmu", "has no binary for this platform"),
        ({"fmu": "badxml.fmu"}, "fmu", "modelDescription.xml:"),
        ({"fmu": "fmi3.fmu"}, "fmu", "'fmi3.fmu' is FMI 3.0; an FMU module must be FMI 2.0"),
        ({"inputs": {"V": "F"}}, "inputs.V", "'F' is not an input of the FMU"),
        ({"outputs": {"w": "s"}}, "outputs.w", "'s' is not an output of the FMU"),
        ({"outputs": {"w": "V"}}, "outputs.w", "'V' is not an output of the FMU (it is input"),
        ({"params": {"tau_m": 0.1}}, "params.tau_m",
         "'tau_m' is not a tunable parameter of the FMU (it is calculatedParameter"),
        ({"params": {"w": 0.0}}, "params.w", "'w' is not a tunable parameter"),
        ({"params": {"J": 0.0}}, "fmu",
         "failed to initialise: motor: inertia J must be > 0 (got 0)"),
        ({"interface": "scheme"}, "interface", "must be model_exchange or co_simulation"),
        ({"states": ["w"]}, "states", "an FMU module takes no 'states'"),
        ({"outputs": {}}, "outputs", "an FMU module needs outputs"),
    ],
)  # fmt: skip
def test_a_bad_fmu_is_one_line_naming_module_and_key(fmu_path, tmp_path, change, key, words):
    (tmp_path / "text.fmu").write_text("not a zip")
    _zip(tmp_path / "empty.fmu", {"readme.txt": b"x"})
    _zip(tmp_path / "nobinary.fmu", {"modelDescription.xml": SOURCES[1].read_bytes()})
    _zip(tmp_path / "badxml.fmu", {"modelDescription.xml": b"<fmiModelDescription"})
    _zip(tmp_path / "fmi3.fmu", {"modelDescription.xml": FMI3_DESCRIPTION})
    shutil.copy(fmu_path, tmp_path / "motor.fmu")
    mapping = _fmu_table("motor.fmu", **change)
    with pytest.raises(TwinTableError) as caught:
        table_from_mapping(mapping, base_dir=tmp_path)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"twin file: module '{MODULE}': {key}: ")
    assert words in message


def test_the_cli_diagnoses_an_fmu_twin_relative_to_its_file(fmu_path, tmp_path, capsys,
                                                             monkeypatch):  # fmt: skip
    twin_file = write_fmu_case(_case("none", 2), fmu_path, tmp_path / "case")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert main(["diagnose", "case/recording.csv", "--twin", "case/twin.yaml", "--out",
                 str(out)]) == 0  # fmt: skip
    answer = json.loads((out / "diagnosis.json").read_text())
    assert answer["effect"] == "none"
    assert any("is an FMU (motor.fmu, Model Exchange)" in note for note in answer["notes"])
    capsys.readouterr()
    twin = yaml.safe_load(twin_file.read_text())
    twin["modules"][MODULE]["params"]["J"] = 0.0
    (twin_file.parent / "bad.yaml").write_text(yaml.safe_dump(twin))
    bad_out = tmp_path / "bad_out"
    assert main(["diagnose", "case/recording.csv", "--twin", "case/bad.yaml", "--out",
                 str(bad_out)]) == 2  # fmt: skip
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "motor: inertia J must be > 0 (got 0)" in error
    assert not bad_out.exists()


def test_an_fmu_joined_to_a_module_by_an_unrecorded_signal_is_refused(fmu_path):
    mapping = _fmu_table(fmu_path, inputs={"q": "V"})
    mapping["modules"] = {"drive": {"block": "lag", "inputs": ["V"], "outputs": ["q"],
                                    "params": {"tau": 0.01}}, **mapping["modules"]}  # fmt: skip
    table = table_from_mapping(mapping)
    spec = units_of(table, ["V", "w"])[0]
    assert spec.modules == ("drive", MODULE)
    words = r"an FMU module is diagnosed on its own.*signal\(s\) q join it to module\(s\) drive"
    with pytest.raises(ValueError, match=rf"module '{MODULE}': {words}: record them"):
        model_for(spec, table)
    assert isinstance(model_for(units_of(table, ["V", "q", "w"])[1], table), FmuModelExchange)


def test_the_fmu_loops_compile_for_stand_ins():
    """``make venv`` warms the numba cache with stand-in functions of the FMI signatures."""
    _fmu_kernels.warm_up()
