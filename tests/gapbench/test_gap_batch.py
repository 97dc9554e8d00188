"""Benchmark cases on disk: a case folder and its diagnosis, as the gap rules write them."""

from __future__ import annotations

import json

import yaml

from dtwin.gapbench.batch import diagnose_case_folder, write_case_folder
from tests.conftest import paper_twin

BENCHMARK = {
    "effects": ["none", "coulomb_friction"],
    "first_seed": 1000,
    "miscalibration": 0.03,
    "noise_error": 0.10,
}
DIAGNOSE = {"train_frac": 0.5, "calibrate": False}


def test_a_benchmark_diagnosis_writes_the_json_and_report_but_no_figure(tmp_path):
    write_case_folder("coulomb_friction_00", BENCHMARK, paper_twin(), tmp_path / "case")
    assert sorted(p.name for p in (tmp_path / "case").iterdir()) == [
        "key.json",
        "recording.csv",
        "twin.yaml",
    ]
    key = json.loads((tmp_path / "case" / "key.json").read_text())
    assert key["case"] == "coulomb_friction_00" and key["seed"] == 2000
    assert "dt" in yaml.safe_load((tmp_path / "case" / "twin.yaml").read_text())["twin"]
    diagnose_case_folder(tmp_path / "case", DIAGNOSE, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["diagnosis.json", "report.md"]
    diagnosis = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert diagnosis["effect"] == "coulomb_friction"
    report = (tmp_path / "out" / "report.md").read_text()
    assert report.startswith("# Sim-to-real gap diagnosis") and "gap.png" not in report
