"""The measured EMPS axis (docs/gap.md §Example: EMPS), where its data are present.

The data are not in the repository: set DTWIN_EMPS_DIR or put the converted files in
``../shared/realdata/emps`` beside the repository (docs/gap.md §Example: EMPS says where to
download them). Without them the test is skipped,
saying where to put them.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from dtwin.gap import diagnose, read_recording, twin_discretisation, twin_from_mapping

ROOT = Path(__file__).resolve().parents[2]
EMPS = Path(os.environ.get("DTWIN_EMPS_DIR", ROOT.parent / "shared" / "realdata" / "emps"))
PUBLISHED_FC = 20.39  # N, Janot et al. 2019


@pytest.mark.slow
def test_emps_names_coulomb_friction_in_the_plant():
    if not (EMPS / "recording_train.csv").is_file():
        pytest.skip(
            f"EMPS data not found in {EMPS}: set DTWIN_EMPS_DIR or see docs/gap.md "
            "(Example: EMPS) for where to download it"
        )
    import yaml

    content = yaml.safe_load((EMPS / "twin.yaml").read_text())
    train = read_recording(EMPS / "recording_train.csv")
    result = diagnose(
        train,
        twin_from_mapping(content, dt=train.dt),
        train_frac=0.7,
        discretisation=twin_discretisation(content),
        heldout=read_recording(EMPS / "recording_pulses.csv"),
    )
    assert (result.module, result.effect) == ("M1", "coulomb_friction")
    assert abs(result.params["Fc"] / PUBLISHED_FC - 1) <= 0.30
    assert result.excess_shrink_pct >= 50 and result.own_shrink_pct >= 50


@pytest.mark.slow
def test_emps_written_as_a_user_s_table_names_coulomb_friction_in_the_axis():
    """The axis as a user would write it: one mass-spring-damper block, no spring, calibrated."""
    if not (EMPS / "recording_train.csv").is_file():
        pytest.skip(f"EMPS data not found in {EMPS}: set DTWIN_EMPS_DIR (docs/gap.md: EMPS)")
    from dtwin.gap.table_diagnose import diagnose_table
    from dtwin.twin.table import table_from_mapping

    table = table_from_mapping(
        {
            "dt": 0.001,
            "modules": {
                "axis": {
                    "block": "mass_spring_damper",
                    "inputs": ["u_act"],
                    "outputs": ["x"],
                    "params": {"m": 100.0, "c": 100.0, "k": 0.0},
                }
            },
        }
    )
    recording = read_recording(EMPS / "recording_train.csv", columns=("u_act", "x"))
    result = diagnose_table(recording, table, calibrate=True)
    assert (result.module, result.effect, result.at) == ("axis", "coulomb_friction", "axis.v")
    assert abs(result.params["Fc"] / PUBLISHED_FC - 1) <= 0.30
