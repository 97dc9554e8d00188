"""The Snakemake workflow, run through `python -m snakemake` on a copy in a temporary folder."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO

pytestmark = pytest.mark.slow

IGNORED = shutil.ignore_patterns(
    ".git",
    ".venv",
    ".snakemake",
    "results",
    "logs",
    "benchmarks",
    "*.png",
    "*.pdf",
    "*.json",
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    ".hypothesis",
    "*.egg-info",
)
ARTIFACTS = ("fig01_pipeline", "fig02_arx_vs_physics", "fig03_residual_acf", "fig11_sensitivity")
SWEEP = {"sensitivity_config", "fig11_sensitivity"}


def small_sweep(config: dict) -> None:
    """A 2 x 1 x 2 sweep grid (4 jobs) with 2 EM starts, for workflow tests."""
    sweep = config["sensitivity"]
    sweep.update(alphas=[0.2, 0.8], sensor_A_mults=[1.0], sensor_B_mults=[0.5, 1.5])
    sweep["hmm"]["n_restarts"] = 2


def snakemake(workdir: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(workdir), "MPLBACKEND": "Agg"}
    result = subprocess.run(
        [sys.executable, "-m", "snakemake", *args],
        cwd=workdir,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    if check and result.returncode != 0:
        raise AssertionError(
            f"snakemake {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}"
        )
    return result


def edit_config(workdir: Path, edit) -> None:
    path = workdir / "config" / "config.yaml"
    config = yaml.safe_load(path.read_text())
    edit(config)
    path.write_text(yaml.safe_dump(config, sort_keys=False))


def planned_jobs(workdir: Path, *targets: str) -> dict[str, int]:
    """Jobs per rule a dry run would execute (from the job-stats table), without `all`."""
    output = snakemake(workdir, "-n", "--cores", "1", *targets).stdout
    if "Nothing to be done" in output:
        return {}
    table = output.split("Job stats:")[1].split("total")[0]
    counts = dict(re.findall(r"^(\w+)\s+(\d+)\s*$", table, flags=re.MULTILINE))
    return {name: int(n) for name, n in counts.items() if name not in ("job", "all")}


def planned_rules(workdir: Path) -> set[str]:
    """Rules a dry run would execute, without `all`."""
    return set(planned_jobs(workdir))


@pytest.fixture(scope="module")
def workflow_copy(tmp_path_factory) -> Path:
    """A copy of the repository with a short run (8 s), after one complete `snakemake` run."""
    workdir = tmp_path_factory.mktemp("wf") / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)
    edit_config(workdir, lambda c: c["simulation"].update(T=8.0))
    edit_config(workdir, small_sweep)
    snakemake(workdir, "--cores", "2")
    return workdir


def test_every_artifact_is_produced_with_passing_validity_checks(workflow_copy):
    for artifact in ARTIFACTS:
        for ext in ("png", "pdf"):
            assert (workflow_copy / "paper_figures" / f"{artifact}.{ext}").stat().st_size > 1000
        payload = json.loads((workflow_copy / "paper_figures" / f"{artifact}.json").read_text())
        assert payload["artifact"] == artifact
        assert {c["kind"] for c in payload["checks"]} >= {"validity"}
        failed = [c["id"] for c in payload["checks"] if c["kind"] == "validity" and not c["passed"]]
        assert not failed
    fig02 = json.loads((workflow_copy / "paper_figures" / "fig02_arx_vs_physics.json").read_text())
    crosschecks = {c["id"]: c["passed"] for c in fig02["checks"] if c["kind"] == "crosscheck"}
    assert crosschecks == {"arx_theta_matches_r": True, "arx_rollout_matches_r": True}
    residuals = (workflow_copy / "results" / "residuals.csv").read_text().splitlines()
    assert residuals[0] == "t,e0,e1,e2a,e2b,e3,e4"
    assert len(residuals) == 1 + 400
    fig11 = json.loads((workflow_copy / "paper_figures" / "fig11_sensitivity.json").read_text())
    crosschecks = {c["id"]: c["passed"] for c in fig11["checks"] if c["kind"] == "crosscheck"}
    assert crosschecks == {"r_inputs_rebuilt_exactly": True}
    assert len(fig11["metrics"]["configurations"]) == 4
    runs = sorted(p.name for p in (workflow_copy / "results" / "sensitivity").glob("*.json"))
    assert runs == [
        f"alpha{a}_mA1.0_mB{b}_rep0.json" for a in ("0.2", "0.8") for b in ("0.5", "1.5")
    ]


def test_nothing_to_do_after_a_complete_run(workflow_copy):
    assert planned_rules(workflow_copy) == set()


def test_a_config_change_reruns_only_what_depends_on_it(workflow_copy):
    edit_config(workflow_copy, lambda c: c["acf"].update(nlags=20))
    assert planned_rules(workflow_copy) == {"fig03_residual_acf"}
    edit_config(workflow_copy, lambda c: c["acf"].update(nlags=30))
    edit_config(workflow_copy, lambda c: c["arx"].update(rollout_init="zeros"))
    assert planned_rules(workflow_copy) == {
        "residuals",
        "fig02_arx_vs_physics",
        "fig03_residual_acf",
        *SWEEP,
    }
    edit_config(workflow_copy, lambda c: c["arx"].update(rollout_init="physics"))
    edit_config(workflow_copy, lambda c: c["twin"]["plant"].update(k=4.5))
    assert planned_rules(workflow_copy) == {
        "simulate",
        "fit_surrogates",
        "residuals",
        "fig02_arx_vs_physics",
        "fig03_residual_acf",
        *SWEEP,
    }
    edit_config(workflow_copy, lambda c: c["twin"]["plant"].update(k=4.0))
    assert planned_rules(workflow_copy) == set()


def test_growing_the_sweep_grid_plans_only_the_new_configurations(workflow_copy):
    edit_config(workflow_copy, lambda c: c["sensitivity"]["alphas"].append(0.5))
    assert planned_jobs(workflow_copy) == {"sensitivity_config": 2, "fig11_sensitivity": 1}
    edit_config(workflow_copy, lambda c: c["sensitivity"]["alphas"].remove(0.5))
    edit_config(workflow_copy, lambda c: c["sensitivity"]["correction"].update(method="paper"))
    assert planned_jobs(workflow_copy) == {"fig11_sensitivity": 1}
    edit_config(workflow_copy, lambda c: c["sensitivity"]["correction"].update(method="code"))
    assert planned_rules(workflow_copy) == set()


def test_a_library_edit_reruns_the_rules_that_import_it(workflow_copy):
    module = workflow_copy / "dtwin" / "residual_stats.py"
    original = module.read_text()
    try:
        module.write_text(original + "\n# edited\n")
        assert planned_rules(workflow_copy) == {"fig03_residual_acf"}
        style = workflow_copy / "dtwin" / "figures" / "pipeline.py"
        style_text = style.read_text()
        style.write_text(style_text + "\n# edited\n")
        assert planned_rules(workflow_copy) == {"fig01_pipeline", "fig03_residual_acf"}
    finally:
        snakemake(workflow_copy, "--cores", "2")


def test_rerun_gives_byte_identical_tables_and_figures(workflow_copy):
    outputs = (
        sorted((workflow_copy / "results").glob("**/*.csv"))
        + sorted((workflow_copy / "results" / "sensitivity").glob("*.json"))
        + sorted((workflow_copy / "paper_figures").glob("fig*.*"))
    )
    before = {path.name: path.read_bytes() for path in outputs}
    snakemake(workflow_copy, "--cores", "2", "--forceall")
    after = {path.name: path.read_bytes() for path in outputs}
    changed = [name for name in before if before[name] != after[name]]
    assert not changed


def test_lint_is_clean(workflow_copy):
    result = snakemake(workflow_copy, "--lint")
    assert "Congratulations" in result.stdout + result.stderr


def test_sweep_dry_run_plans_one_job_per_configuration_and_replicate(tmp_path):
    workdir = tmp_path / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)

    def grid(config):
        config["sensitivity"].update(
            alphas=[0.2, 0.8], sensor_A_mults=[1.5], sensor_B_mults=[0.5], n_replicates=2
        )

    edit_config(workdir, grid)
    assert planned_jobs(workdir, "fig11_sensitivity") == {
        "sensitivity_config": 4,
        "fig11_sensitivity": 1,
    }


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda c: c["twin"]["fusion"].update(alpha=1.3), "twin.fusion.alpha"),
        (lambda c: c["twin"]["plant"].pop("k"), "twin.plant"),
        (lambda c: c["simulation"].update(seed="eleven"), "simulation.seed"),
        (lambda c: c["twin"]["actuator"].update(tau=-0.15), "twin.actuator.tau"),
        (lambda c: c["sensitivity"]["alphas"].append(1.2), "sensitivity.alphas.4"),
        (lambda c: c["sensitivity"]["correction"].update(method="text"), "sensitivity.correction"),
    ],
)
def test_malformed_config_stops_before_any_job_and_names_the_key(tmp_path, edit, key):
    workdir = tmp_path / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)
    edit_config(workdir, edit)
    result = snakemake(workdir, "--cores", "1", check=False)
    assert result.returncode != 0
    message = result.stdout + result.stderr
    assert "invalid configuration" in message
    assert key in message
    assert not (workdir / "results").exists()
