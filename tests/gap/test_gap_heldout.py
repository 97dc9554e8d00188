"""`--heldout` (docs/gap.md §Interface) and the rig family's integrating closed-loop plant."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

from dtwin._validation import DtwinValueError
from dtwin.cli import main
from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
from dtwin.gapbench.rigs import generate_rig_case


def _plant_csv(path, n=600, dt=0.01, columns=("t", "u_cmd", "u_act", "x"), seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    u_cmd = rng.normal(size=n)
    frame = pd.DataFrame(
        {"t": t, "u_cmd": u_cmd, "u_act": np.roll(u_cmd, 1), "x": np.sin(t) + 0.01 * t}
    )
    frame[list(columns)].to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dt": 0.02}, "held-out recording dt"),
        ({"columns": ("t", "u_act", "x")}, "held-out recording is missing column(s) u_cmd"),
        ({"columns": ("t", "u_cmd", "u_act")}, "held-out recording is missing column(s) x"),
        ({"n": 150}, "held-out recording must have at least 200 samples"),
    ],
)
def test_a_bad_heldout_file_gets_one_line(tmp_path, capsys, kwargs, message):
    train = _plant_csv(tmp_path / "train.csv")
    held = _plant_csv(tmp_path / "held.csv", **kwargs)
    (tmp_path / "twin.yaml").write_text(yaml.safe_dump({"dt": 0.01}))
    argv = ["diagnose", str(train), "--twin", str(tmp_path / "twin.yaml"), "--heldout", str(held)]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def clean_rig():
    """Rig case ``none``, seed 3 (6000 samples; about 3 CPU s to generate)."""
    return generate_rig_case("none", 3)


def test_heldout_scores_on_the_second_recording_only(clean_rig):
    case = clean_rig
    frame = case.recording
    half = len(frame) // 2
    train = recording_from_frame(frame.iloc[:half].reset_index(drop=True))
    held = recording_from_frame(frame.iloc[half:].reset_index(drop=True))
    result = diagnose(train, twin_from_mapping(case.twin), train_frac=0.7, heldout=held)
    # training: 70 % of the first recording; choosing: the rest of it; scoring: the second
    assert (result.n_train, result.n_choose) == (round(0.7 * half), half)
    assert result.n_samples == len(frame)


def test_heldout_needs_a_choosing_part(clean_rig):
    case = clean_rig
    train = recording_from_frame(case.recording.iloc[:600].reset_index(drop=True))
    held = recording_from_frame(case.recording.iloc[600:].reset_index(drop=True))
    # 95 % of 600 samples train: 30 are left to choose on, fewer than 50
    with pytest.raises(DtwinValueError, match="50 each for choosing and for scoring"):
        diagnose(train, twin_from_mapping(case.twin), train_frac=0.95, heldout=held)


@pytest.mark.slow
def test_integrating_plant_in_a_pd_loop_with_coulomb_friction():
    case = generate_rig_case("coulomb_friction", 0)
    assert case.key["integrating"] and case.key["closed_loop"]
    result = diagnose(recording_from_frame(case.recording), twin_from_mapping(case.twin))
    assert (result.module, result.effect) == ("M1", "coulomb_friction")
    assert result.params["Fc"] == pytest.approx(case.key["params"]["Fc"], rel=0.3)
    assert result.modules["M1"].horizon_samples is not None
