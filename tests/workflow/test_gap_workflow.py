"""The gap rules build their DAG from the main Snakefile (dry run on a temporary copy)."""

from __future__ import annotations

import shutil

import pytest

from tests.workflow.test_workflow import IGNORED, REPO, job_counts, snakemake

pytestmark = pytest.mark.slow  # Snakemake in a subprocess, as tests/workflow/test_workflow.py


def test_full_gap_benchmark_override_plans_ten_cases_per_effect(tmp_path):
    workdir = tmp_path / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)
    full = ["-n", "--cores", "2", "gap_benchmark", "--configfile", "config/gap_full.yaml"]
    # one case per chunk (--set-scatter gap=0): 14 case types of the paper asset, 4 of the
    # rig family, 5 of the harder rig family, 64 of the arms (a)-(g) and 12 of arm (h)
    # (dtwin/gapbench/arms.py) and 52 of the families of other physics, 10 each
    counts = job_counts(snakemake(workdir, *full, "--set-scatter", "gap=0").stdout)
    assert counts["gap_cases"] == counts["gap_diagnoses"] == 10 * (14 + 4 + 5 + 64 + 12 + 52)
    assert counts["gap_benchmark"] == 1
