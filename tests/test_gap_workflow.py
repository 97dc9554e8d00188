"""The gap rules build their DAG (a Snakemake dry run on a copy in a temporary folder)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_gap_rules_dry_run(tmp_path):
    for part in ("dtwin", "scripts", "config", "workflow"):
        shutil.copytree(ROOT / part, tmp_path / part, ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "workflow/envs").mkdir(exist_ok=True)
    (tmp_path / "workflow/envs/dtwin.yaml").write_text("name: dtwin\ndependencies: [python=3.11]\n")
    (tmp_path / "Snakefile").write_text(
        'configfile: "config/gap.yaml"\n\n\ninclude: "workflow/rules/gap.smk"\n'
    )
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "--cores",
            "2",
            "-n",
            "gap_benchmark",
            "--configfile",
            "config/gap.yaml",
            "config/gap_full.yaml",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "gap_diagnose" in done.stdout
    assert "140" in done.stdout  # 14 case types x 10 cases (the full-benchmark override)
