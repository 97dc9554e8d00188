"""An FMU as a module of a twin table (docs/gap.md §An FMU as a module).

The test FMU (tests/twin/fmu/oscillator.c, FMI 2.0 Model Exchange and Co-Simulation) is compiled
here from source and cached by its hash; its physics are the expression module :data:`EXPR`'s,
so the two twins must give the same answers on the same recordings.
"""

from __future__ import annotations

import json
import shutil
import zipfile

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from dtwin.cli import main
from dtwin.gap.recording import recording_with_columns
from dtwin.gap.table_diagnose import diagnose_table
from dtwin.twin.fmu import FmuModel, FmuModelExchange, model_for
from dtwin.twin.simulate import UnitModel, units_of
from dtwin.twin.table import TwinTableError, table_from_mapping
from tests.twin.fmu.build import SOURCES, build_fmu, compiler

pytestmark = pytest.mark.skipif(
    compiler() is None, reason="no C compiler (cc or gcc): the test FMU is built from source"
)

DT = 0.02
K, C = 4.0, 0.4
EXPR = {
    "dt": DT,
    "modules": {
        "osc": {
            "inputs": ["u"],
            "outputs": ["x"],
            "states": ["x", "w"],
            "params": {"k": K, "c": C},
            "derivatives": {"x": "w", "w": "u - c*w - k*x"},
        }
    },
    "noise": {"x": 0.01},
}


@pytest.fixture(scope="module")
def fmu_path():
    return build_fmu()


def _fmu_table(path, interface="model_exchange", **changes):
    module = {"fmu": str(path), "inputs": {"u": "u"}, "outputs": {"x": "x"},
              "params": {"k": K, "c": C}, "interface": interface, **changes}  # fmt: skip
    return {"dt": DT, "modules": {"osc": module}, "noise": {"x": 0.01}}


def _asset(n: int, seed: int, *, clip=None, dead=None) -> pd.DataFrame:
    """The oscillator integrated finely (solve_ivp); random input steps held over 2 s."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-2, 2, n // 100 + 1), 100)[:n]
    driven = u if dead is None else np.sign(u) * np.maximum(np.abs(u) - dead, 0)

    def rhs(t, s):
        return [s[1], driven[min(int(t / DT), n - 1)] - C * s[1] - K * s[0]]

    times = np.arange(n) * DT
    sol = solve_ivp(rhs, (0, times[-1]), [0.0, 0.0], t_eval=times, max_step=DT / 2, rtol=1e-9,
                    atol=1e-10)  # fmt: skip
    x = sol.y[0] + 0.01 * rng.standard_normal(n)
    if clip is not None:
        x = np.minimum(x, np.quantile(x, clip))
    return pd.DataFrame({"t": times, "u": u, "x": x})


def _diagnose(mapping, frame, **kwargs):
    table = table_from_mapping(mapping)
    recording = recording_with_columns(frame, (*table.signals, *table.exogenous))
    return diagnose_table(recording, table, **kwargs)


def test_an_fmu_module_reads_its_states_params_and_outputs(fmu_path):
    table = table_from_mapping(_fmu_table(fmu_path))
    module = table.module("osc")
    assert (module.inputs, module.outputs, module.states) == (("u",), ("x",), ("x", "w"))
    assert module.params == {"k": K, "c": C}
    assert module.output_states == {"x": "x"}
    spec = units_of(table, ["u", "x"])[0]
    assert isinstance(model_for(spec, table), FmuModelExchange)
    cs = table_from_mapping(_fmu_table(fmu_path, "co_simulation"))
    model = model_for(units_of(cs, ["u", "x"])[0], cs)
    assert type(model) is FmuModel and model.restart == "start values"
    assert not hasattr(model, "derivatives")


@pytest.mark.parametrize(("interface", "tolerance"), [("model_exchange", 0.0),
                                                      ("co_simulation", 1e-5)])  # fmt: skip
def test_the_fmu_simulates_as_the_expression_module(fmu_path, interface, tolerance):
    """Model Exchange runs the same RK4 arithmetic (equal bits); Co-Simulation its own RK4."""
    table = table_from_mapping(_fmu_table(fmu_path, interface))
    model = model_for(units_of(table, ["u", "x"])[0], table)
    expression = UnitModel.from_spec(units_of(table_from_mapping(EXPR), ["u", "x"])[0])
    rng = np.random.default_rng(0)
    n = 2000
    u = np.repeat(rng.normal(size=n // 50 + 1), 50)[:n, None]
    starts = np.arange(0, n, 400)
    x0 = rng.normal(size=(len(starts), 2))
    args = (u, [K, C], starts, starts + 400, x0, DT)
    y, states = model.simulate(*args, substeps=1, linear=[True])
    y_ref, states_ref = expression.simulate(*args, substeps=1, linear=[True])
    assert np.max(np.abs(y - y_ref)) <= tolerance
    assert np.max(np.abs(states - states_ref)) <= tolerance
    if interface == "model_exchange":
        point = (np.array([1.0, 2.0]), np.array([0.5]), [K, C])
        assert np.array_equal(model.derivatives(*point), expression.derivatives(*point))


@pytest.mark.parametrize(
    ("case", "interface", "effect", "at", "param", "truth"),
    [
        pytest.param(
            "clip", "model_exchange", "output_saturation", "x", "high", None, marks=pytest.mark.slow
        ),
        ("dead", "model_exchange", "input_deadzone", "u", "D", 0.5),
        pytest.param(
            "dead", "co_simulation", "input_deadzone", "u", "D", 0.5, marks=pytest.mark.slow
        ),
    ],
)
def test_the_fmu_and_the_expression_twin_name_the_same_effect(
    fmu_path, case, interface, effect, at, param, truth
):
    """Same effect at the same signal; params equal for Model Exchange, within 0.01 for CS."""
    frame = _asset(3000, 3, clip=0.85 if case == "clip" else None,
                   dead=0.5 if case == "dead" else None)  # fmt: skip
    by_fmu = _diagnose(_fmu_table(fmu_path, interface), frame)
    by_expression = _diagnose(EXPR, frame)
    for result in (by_fmu, by_expression):
        assert (result.module, result.effect, result.at) == ("osc", effect, at)
    tolerance = 1e-6 if interface == "model_exchange" else 0.01
    assert by_fmu.params[param] == pytest.approx(by_expression.params[param], abs=tolerance)
    if truth is not None:
        assert by_fmu.params[param] == pytest.approx(truth, abs=0.01)
    assert "FMU internals are closed: no state effects" in " ".join(by_fmu.notes)
    assert not any(c["effect"].startswith("state") for c in by_fmu.candidates)


def test_an_fmu_that_cannot_restart_runs_once_per_part(fmu_path, monkeypatch):
    frame = _asset(2000, 4, dead=0.5)
    table = table_from_mapping(_fmu_table(fmu_path, "co_simulation"))
    info = table.module("osc").fmu
    from dataclasses import replace

    closed = replace(info, restart="none", states=(), output_states={})
    module = replace(table.module("osc"), fmu=closed, states=(), output_states={})
    table = replace(table, modules=(module,))
    result = diagnose_table(recording_with_columns(frame, ("u", "x")), table)
    assert result.units["osc"].window == len(frame)
    assert "one run from the FMU's own start values" in " ".join(result.notes)
    assert (result.effect, result.at) == ("input_deadzone", "u")


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
        ({"inputs": {"u": "F"}}, "inputs.u", "'F' is not an input of the FMU"),
        ({"outputs": {"x": "s"}}, "outputs.x", "'s' is not an output of the FMU"),
        ({"outputs": {"x": "u"}}, "outputs.x", "'u' is not an output of the FMU (it is input"),
        ({"params": {"omega0": 2.0}}, "params.omega0",
         "'omega0' is not a tunable parameter of the FMU (it is calculatedParameter"),
        ({"params": {"x": 0.0}}, "params.x", "'x' is not a tunable parameter"),
        ({"params": {"m": 0.0}}, "fmu",
         "failed to initialise: oscillator: mass m must be > 0 (got 0)"),
        ({"interface": "scheme"}, "interface", "must be model_exchange or co_simulation"),
        ({"states": ["x"]}, "states", "an FMU module takes no 'states'"),
        ({"outputs": {}}, "outputs", "an FMU module needs outputs"),
    ],
)  # fmt: skip
def test_a_bad_fmu_is_one_line_naming_module_and_key(fmu_path, tmp_path, change, key, words):
    (tmp_path / "text.fmu").write_text("not a zip")
    _zip(tmp_path / "empty.fmu", {"readme.txt": b"x"})
    _zip(tmp_path / "nobinary.fmu", {"modelDescription.xml": SOURCES[1].read_bytes()})
    _zip(tmp_path / "badxml.fmu", {"modelDescription.xml": b"<fmiModelDescription"})
    shutil.copy(fmu_path, tmp_path / "osc.fmu")
    mapping = _fmu_table("osc.fmu")
    mapping["modules"]["osc"].update(change)
    with pytest.raises(TwinTableError) as caught:
        table_from_mapping(mapping, base_dir=tmp_path)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"twin file: module 'osc': {key}: ")
    assert words in message


def test_the_cli_diagnoses_an_fmu_twin_relative_to_its_file(fmu_path, tmp_path, capsys,
                                                             monkeypatch):  # fmt: skip
    folder = tmp_path / "twin"
    (folder / "models").mkdir(parents=True)
    shutil.copy(fmu_path, folder / "models" / "oscillator.fmu")
    frame = _asset(3000, 3, dead=0.5)
    frame.to_csv(tmp_path / "rec.csv", index=False)
    twin = _fmu_table("models/oscillator.fmu")
    (folder / "twin.yaml").write_text(yaml.safe_dump(twin))
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert main(["diagnose", "rec.csv", "--twin", "twin/twin.yaml", "--out", str(out)]) == 0
    answer = json.loads((out / "diagnosis.json").read_text())
    assert (answer["module"], answer["effect"], answer["at"]) == ("osc", "input_deadzone", "u")
    assert any("FMU internals are closed" in note for note in answer["notes"])
    capsys.readouterr()
    twin["modules"]["osc"]["params"]["m"] = 0.0
    (folder / "bad.yaml").write_text(yaml.safe_dump(twin))
    bad_out = tmp_path / "bad_out"
    assert main(["diagnose", "rec.csv", "--twin", "twin/bad.yaml", "--out", str(bad_out)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "mass m must be > 0" in error
    assert not bad_out.exists()


def test_an_fmu_joined_to_a_module_by_an_unrecorded_signal_is_refused(fmu_path):
    mapping = _fmu_table(fmu_path, inputs={"q": "u"})
    mapping["modules"] = {"pump": {"block": "lag", "inputs": ["u"], "outputs": ["q"],
                                   "params": {"tau": 0.5}}, **mapping["modules"]}  # fmt: skip
    table = table_from_mapping(mapping)
    spec = units_of(table, ["u", "x"])[0]
    assert spec.modules == ("pump", "osc")
    with pytest.raises(ValueError, match=r"module 'osc': an FMU module is diagnosed on its own.*"
                       r"signal\(s\) q join it to module\(s\) pump: record them"):  # fmt: skip
        model_for(spec, table)
    assert isinstance(model_for(units_of(table, ["u", "q", "x"])[1], table), FmuModelExchange)


def test_the_fmu_loops_compile_for_stand_ins():
    """``make venv`` warms the numba cache with stand-in functions of the FMI signatures."""
    from dtwin.twin import _fmu_kernels

    _fmu_kernels.warm_up()
