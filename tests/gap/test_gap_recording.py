"""Bad recordings and twin files: a clear one-line error, non-zero exit, no output folder."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.cli import main
from dtwin.gap import diagnose, twin_from_mapping
from dtwin.gap.recording import read_recording, recording_from_frame

TWIN = "twin:\n  dt: 0.02\n  plant: {m: 1.0, c: 0.4, k: 4.0}\n"


def _frame(n: int = 400, dt: float = 0.02) -> pd.DataFrame:
    t = np.arange(n) * dt
    u = np.sin(2 * np.pi * 0.3 * t) + 0.3 * np.sign(np.sin(2 * np.pi * 0.07 * t))
    return pd.DataFrame({"t": t, "u_act": u, "x": 0.2 * np.sin(2 * np.pi * 0.3 * t - 0.4)})


def _write(tmp_path, frame: pd.DataFrame | str, name: str = "rec.csv"):
    path = tmp_path / name
    if isinstance(frame, str):
        path.write_text(frame)
    else:
        frame.to_csv(path, index=False, float_format="%.10g")
    return path


def _cli_fails(tmp_path, recording, capsys, twin: str = TWIN) -> str:
    twin_path = tmp_path / "twin.yaml"
    twin_path.write_text(twin)
    out = tmp_path / "out"
    status = main(["diagnose", str(recording), "--twin", str(twin_path), "--out", str(out)])
    err = capsys.readouterr().err
    assert status != 0
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    return err


def test_missing_column(tmp_path, capsys):
    path = _write(tmp_path, _frame().drop(columns="t"))
    assert "missing column 't'" in _cli_fails(tmp_path, path, capsys)


def test_no_module_diagnosable(tmp_path, capsys):
    path = _write(tmp_path, _frame().drop(columns="x"))
    assert "no module whose input and output" in _cli_fails(tmp_path, path, capsys)


def test_non_numeric_value_names_the_row(tmp_path, capsys):
    frame = _frame().astype(object)
    frame.loc[6, "x"] = "abc"
    err = _cli_fails(tmp_path, _write(tmp_path, frame), capsys)
    assert "'x' must be numeric" in err and "row 7" in err


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_and_inf_name_the_rows(tmp_path, capsys, bad):
    frame = _frame()
    frame.loc[[10, 20], "u_act"] = bad
    err = _cli_fails(tmp_path, _write(tmp_path, frame), capsys)
    assert "NaN/inf" in err and "rows 11, 21" in err


def test_decreasing_time(tmp_path, capsys):
    frame = _frame()
    frame.loc[50, "t"] = frame.loc[48, "t"]
    assert "'t' must increase" in _cli_fails(tmp_path, _write(tmp_path, frame), capsys)


def test_jittery_time(tmp_path, capsys):
    frame = _frame()
    frame.loc[100, "t"] += 0.02 * 0.03
    assert "uniform step" in _cli_fails(tmp_path, _write(tmp_path, frame), capsys)


def test_rounded_timestamps_pass(tmp_path):
    n, dt = 600, 1 / 300
    t = np.arange(n) * dt
    text = "t,u_act,x\n" + "".join(
        f"{ti:.3f},{np.sin(ti):.6f},{np.cos(ti):.6f}\n" for ti in t
    )  # stamps rounded to 1 ms at 300 Hz: steps of 3 or 4 ms
    recording = read_recording(_write(tmp_path, text))
    assert abs(recording.dt - dt) < 1e-5


def test_dt_disagrees_with_twin(tmp_path, capsys):
    path = _write(tmp_path, _frame(dt=0.01))
    assert "disagrees with twin.dt" in _cli_fails(tmp_path, path, capsys)


def test_too_few_samples(tmp_path, capsys):
    path = _write(tmp_path, _frame(n=150))
    assert "at least 200 samples" in _cli_fails(tmp_path, path, capsys)


def test_constant_input(tmp_path, capsys):
    frame = _frame()
    frame["u_act"] = 0.7
    assert "must vary" in _cli_fails(tmp_path, _write(tmp_path, frame), capsys)


def test_bad_twin_file(tmp_path, capsys):
    path = _write(tmp_path, _frame())
    assert "twin.plant.m must be > 0" in _cli_fails(
        tmp_path, path, capsys, twin="dt: 0.02\nplant: {m: -1, c: 0.4, k: 4}\n"
    )
    assert "not valid YAML" in _cli_fails(tmp_path, path, capsys, twin="dt: [0.02\n")


def test_missing_file(tmp_path, capsys):
    assert "not found" in _cli_fails(tmp_path, tmp_path / "nope.csv", capsys)


def test_library_raises_project_errors():
    with pytest.raises(DtwinValueError, match="at least 200"):
        recording_from_frame(_frame(n=100))
    recording = recording_from_frame(_frame())
    with pytest.raises(DtwinValueError, match="disagrees"):
        diagnose(recording, twin_from_mapping({"dt": 0.05}))
