"""The Snakemake workflow, run through `python -m snakemake` on a copy in a temporary folder."""

from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
import yaml

from tests.conftest import REPO, paper_twin

pytestmark = pytest.mark.slow

_IGNORED_NAMES = shutil.ignore_patterns(
    ".git",
    ".venv",
    ".snakemake",
    "results",
    "logs",
    "benchmarks",
    "*.png",
    "*.pdf",
    "*.json",
    "*.html",
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    ".hypothesis",
    "*.egg-info",
)


def IGNORED(directory: str, names: list[str]) -> set[str]:
    """What a workflow copy leaves out; it keeps dtwin/__pycache__, numba's cache of the EM
    kernels (``make venv`` warms it; copytree keeps the sources' times, so it stays valid),
    so the jobs of a copy do not each compile the kernels."""
    ignored = _IGNORED_NAMES(directory, names)
    if Path(directory) == REPO / "dtwin":
        ignored.discard("__pycache__")
    return ignored


#: Every published artifact (workflow/artifacts.yaml, the list `rule all` is built from).
ARTIFACTS = tuple(
    name
    for names in yaml.safe_load((REPO / "workflow" / "artifacts.yaml").read_text()).values()
    for name in names
)
#: Every rule downstream of `fault_regimes`.
AFTER_FAULTS = {
    "fault_regimes",
    "fig07_fault_posteriors",
    "fig08_feature_separability",
    "targeted_intervention",
    "fig05_correction_timeseries",
    "fig06_correction_distributions",
    "bic_sweep_dataset",
    "bic_sweep",
    "fig09_bic",
    "mcda_actions",
    "fig10_mcda_actions",
    "ar_hmm_sweep",
    "fig13_ar_hmm",
    "claims",
}
#: Every rule downstream of `residuals` (its surrogate and residual tables).
AFTER_RESIDUALS = AFTER_FAULTS | {
    "residuals",
    "fig02_arx_vs_physics",
    "fig03_residual_acf",
    "nominal_regimes",
    "fig04_hmm_posteriors",
}
SWEEP = {"sweep_chunk", "fig11_sensitivity"}
#: The claims across random draws (they rerun the whole single-draw pipeline).
DRAWS = {"claims_draws", "bic_draws", "fig12_claims_across_draws"}
#: The gap benchmark: its cases are generated from config ``twin`` (the paper's nominal twin).
GAP = {"gap_cases", "gap_diagnoses", "gap_benchmark"}


def small_sweep(config: dict) -> None:
    """A 2 x 1 x 2 sweep grid (4 points: 2 chunks of two) with 2 EM starts, for workflow tests."""
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


#: What Snakemake 9 prints when a (dry) run has no job to execute (snakemake.common).
NOTHING_TO_DO = "Nothing to be done (all requested files are present and up to date)."


def job_counts(output: str) -> dict[str, int]:
    """Jobs per rule from the job-stats table a (dry) run prints.

    Returns ``{}`` only when Snakemake says there is nothing to be done; output that has
    neither that line nor a job-stats table whose rows add up to its total fails the test, so a
    changed or broken output can never read as "nothing to do".
    """
    if "Job stats:" not in output:
        if NOTHING_TO_DO in output:
            return {}
        raise AssertionError(f"dry-run output has no job stats and no {NOTHING_TO_DO!r}:\n{output}")
    table = output.split("Job stats:")[1]
    counts = {
        name: int(n)
        for name, n in re.findall(r"^(\w+)\s+(\d+)\s*$", table.split("total")[0], flags=re.M)
    }
    total = re.search(r"^total\s+(\d+)\s*$", table, flags=re.M)
    if not counts or total is None or sum(counts.values()) != int(total.group(1)):
        raise AssertionError(f"unreadable job-stats table:\n{output}")
    return counts


def dry_run(workdir: Path, *targets: str) -> str:
    """What `snakemake -n` prints (stdout and stderr: Snakemake logs to both)."""
    result = snakemake(workdir, "-n", "--cores", "1", *targets)
    return result.stdout + result.stderr


def planned_jobs(workdir: Path, *targets: str) -> dict[str, int]:
    """Jobs per rule a dry run would execute, without `all`."""
    counts = job_counts(dry_run(workdir, *targets))
    return {name: n for name, n in counts.items() if name != "all"}


def planned_rules(workdir: Path) -> set[str]:
    """Rules a dry run would execute, without `all`."""
    return set(job_counts(dry_run(workdir))) - {"all"}


def rule_benchmark_files(workdir: Path) -> list[Path]:
    """The rules' `benchmark:` files of a run in ``workdir``, relative to benchmarks/rules."""
    folder = workdir / "benchmarks" / "rules"
    return [p.relative_to(folder) for p in sorted(folder.rglob("*.tsv"))]


def planned_rules_of(workdir: Path, *options: str) -> set[str]:
    """Rules a dry run of the default target with ``options`` would execute, without `all`."""
    return set(job_counts(dry_run(workdir, *options))) - {"all"}


def test_job_counts_refuses_output_it_cannot_parse():
    """An empty or changed dry-run output fails; only Snakemake's own line means nothing to do."""
    rows = [
        "Job stats:",
        "job       count",
        "------  -------",
        "claims        1",
        "all           1",
    ]
    table = "\n".join([*rows, "total         2", ""])
    assert job_counts(f"Building DAG of jobs...\n{table}") == {"claims": 1, "all": 1}
    assert job_counts(f"Building DAG of jobs...\n{NOTHING_TO_DO}\n") == {}
    for broken in ("", "Error: something else", table.replace("total         2", "total 3")):
        with pytest.raises(AssertionError):
            job_counts(broken)


def shorten(config: dict) -> None:
    """An 8 s run, a 4-job sweep and a two-case gap benchmark: the whole DAG in about a minute."""
    config["simulation"]["T"] = 8.0
    small_sweep(config)
    config["gap"]["benchmark"].update(effects=["none", "coulomb_friction"], cases_per_effect=1)
    config["draws"].update(n_draws=2, chunk_size=2)
    config["draws"]["bic"].update(n_draws=2, n_restarts=2, max_restarts=2, chunk_size=2)
    config["bic"].update(n_restarts=4, max_restarts=4, k_max=10)
    config["ar_hmm"].update(n_restarts=2, k_max=10)


@pytest.fixture(scope="module")
def workflow_copy(tmp_path_factory) -> Path:
    """A copy of the repository with a short run (8 s), after one complete `snakemake` run."""
    workdir = tmp_path_factory.mktemp("wf") / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)
    edit_config(workdir, shorten)
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
    crosschecks = {}
    for artifact in ARTIFACTS:
        payload = json.loads((workflow_copy / "paper_figures" / f"{artifact}.json").read_text())
        crosschecks |= {
            c["id"]: c["passed"] for c in payload["checks"] if c["kind"] == "crosscheck"
        }
    assert crosschecks == {
        "arx_theta_matches_r": True,
        "arx_rollout_matches_r": True,
        "loglik_on_r_features_reaches_depmix": True,
        "correction_on_r_signals_gives_r_table": True,
        "hungarian_on_r_viterbi_gives_r_confusion": True,
        "scores_on_r_viterbi_equal_r": True,
        "bic_formula_matches_r": True,
        "legacy_matches_r_031": True,
        "r_inputs_rebuilt_exactly": True,
    }
    claims = (workflow_copy / "paper_figures" / "CLAIMS.md").read_text()
    assert "## Claims of the paper" in claims and "fig09_bic" in claims
    residuals = (workflow_copy / "results" / "residuals.csv").read_text().splitlines()
    assert residuals[0] == "t,e0,e1,e2a,e2b,e3,e4"
    assert len(residuals) == 1 + 400
    fig11 = json.loads((workflow_copy / "paper_figures" / "fig11_sensitivity.json").read_text())
    crosschecks = {c["id"]: c["passed"] for c in fig11["checks"] if c["kind"] == "crosscheck"}
    assert crosschecks == {"r_inputs_rebuilt_exactly": True}
    assert len(fig11["metrics"]["configurations"]) == 4
    chunks = workflow_copy / "results" / "sensitivity" / "chunks"
    assert sorted(p.name for p in chunks.glob("*.json")) == ["1-of-2.json", "2-of-2.json"]
    points = [p for c in sorted(chunks.glob("*.json")) for p in json.loads(c.read_text())["points"]]
    assert sorted((p["alpha"], p["m_B"]) for p in points) == [
        (0.2, 0.5),
        (0.2, 1.5),
        (0.8, 0.5),
        (0.8, 1.5),
    ]


def test_every_figure_is_print_ready_with_its_caption(workflow_copy):
    """300-dpi PNG at print width beside a vector PDF; caption and print check in the JSON."""
    from tests.figures.test_figure_style import png_size_and_dpi

    for artifact in ARTIFACTS:
        folder = workflow_copy / "paper_figures"
        payload = json.loads((folder / f"{artifact}.json").read_text())
        width_in, height_in = payload["figure"]["size_in"]
        assert 7.0 <= width_in <= 7.5 or 3.4 <= width_in <= 3.6, artifact
        assert payload["figure"]["caption"], artifact
        check = next(c for c in payload["checks"] if c["id"] == "print_size_and_text")
        assert check["passed"] and check["observed"]["min_font_pt"] >= 7, artifact
        check = next(c for c in payload["checks"] if c["id"] == "axes_and_legends")
        assert check["passed"], (artifact, check["observed"])
        width, height, dpi = png_size_and_dpi(folder / f"{artifact}.png")
        assert round(dpi) == 300
        assert (width, height) == (round(300 * width_in), round(300 * height_in)), artifact
        assert (folder / f"{artifact}.pdf").read_bytes().startswith(b"%PDF")
        if artifact.startswith(("fig05", "fig06", "fig11")):
            failed = [
                c for c in payload["checks"] if c["kind"] in ("claim", "target") and not c["passed"]
            ]
            assert all(c["note"] for c in failed), artifact


def test_fault_tables_keep_the_contract_columns(workflow_copy):
    faults = workflow_copy / "results" / "faults"
    residuals = (faults / "residuals.csv").read_text().splitlines()
    assert residuals[0] == "t,regime,e0,e1,e2a,e2b,e3,e4"
    posteriors = (faults / "posteriors.csv").read_text().splitlines()
    assert posteriors[0] == (
        "t,regime,state,mapped_regime,p_Nominal,p_SensorNoisy,p_DynamicsOff,p_Drift"
    )
    assert len(residuals) == len(posteriors) == 1 + 400


def test_nothing_to_do_after_a_complete_run(workflow_copy):
    assert planned_rules(workflow_copy) == set()


def test_a_config_change_reruns_only_what_depends_on_it(workflow_copy):
    edit_config(workflow_copy, lambda c: c["acf"].update(nlags=20))
    assert planned_rules(workflow_copy) == {"fig03_residual_acf", "claims"}
    edit_config(workflow_copy, lambda c: c["acf"].update(nlags=30))
    edit_config(workflow_copy, lambda c: c["arx"].update(rollout_init="zeros"))
    assert planned_rules(workflow_copy) == AFTER_RESIDUALS | SWEEP | DRAWS
    edit_config(workflow_copy, lambda c: c["arx"].update(rollout_init="physics"))
    edit_config(workflow_copy, lambda c: c["twin"]["plant"].update(k=4.5))
    assert planned_rules(workflow_copy) == {
        "simulate",
        "fit_surrogates",
        *AFTER_RESIDUALS,
        *SWEEP,
        *DRAWS,
        *GAP,
    }
    edit_config(workflow_copy, lambda c: c["twin"]["plant"].update(k=4.0))
    edit_config(workflow_copy, lambda c: c["correction"].update(kappa=0.5))
    assert planned_rules(workflow_copy) == {
        "targeted_intervention",
        "fig05_correction_timeseries",
        "fig06_correction_distributions",
        "claims",
        *DRAWS - {"bic_draws"},  # K* across draws reads no correction
    }
    edit_config(workflow_copy, lambda c: c["correction"].update(kappa=0.8))
    # an MCDA weight reruns the decisions and the draws' claims, no BIC sweep
    edit_config(workflow_copy, lambda c: c["mcda"]["weights"].update(Cost=0.2))
    assert planned_rules(workflow_copy) == {
        "mcda_actions",
        "fig10_mcda_actions",
        "claims",
        *DRAWS - {"bic_draws"},
    }
    edit_config(workflow_copy, lambda c: c["mcda"]["weights"].update(Cost=0.15))
    edit_config(workflow_copy, lambda c: c["bic"].update(n_restarts=3))
    assert planned_rules(workflow_copy) == {
        "bic_sweep_dataset",
        "bic_r_signals",  # Fig. 9's sweep on R's seed-11 signals reads the bic section too
        "bic_sweep",
        "fig09_bic",
        "fig13_ar_hmm",
        "fig12_claims_across_draws",
        "claims",
    }
    edit_config(workflow_copy, lambda c: c["bic"].update(n_restarts=4))
    edit_config(workflow_copy, lambda c: c["faults"].update(drift_origin="regime_start"))
    assert planned_rules(workflow_copy) == AFTER_FAULTS | DRAWS
    edit_config(workflow_copy, lambda c: c["faults"].update(drift_origin="global"))
    assert planned_rules(workflow_copy) == set()


def test_changing_the_sweep_grid_reruns_only_the_chunks_whose_points_change(workflow_copy):
    # 4 points in 2 chunks, m_B outside alpha: [(0.2, 0.5) (0.8, 0.5)] [(0.2, 1.5) (0.8, 1.5)];
    # m_B 1.5 -> 2.0 changes the points of chunk 2 only: chunk 1 keeps its file
    edit_config(workflow_copy, lambda c: c["sensitivity"].update(sensor_B_mults=[0.5, 2.0]))
    assert planned_jobs(workflow_copy) == {
        "sweep_chunk": 1,
        "fig11_sensitivity": 1,
        "claims": 1,
    }
    edit_config(workflow_copy, lambda c: c["sensitivity"].update(sensor_B_mults=[0.5, 1.5]))
    edit_config(workflow_copy, lambda c: c["sensitivity"]["correction"].update(method="paper"))
    assert planned_jobs(workflow_copy) == {"fig11_sensitivity": 1, "claims": 1}
    edit_config(workflow_copy, lambda c: c["sensitivity"]["correction"].update(method="code"))
    assert planned_rules(workflow_copy) == set()


def test_a_library_edit_reruns_the_rules_that_import_it(workflow_copy):
    edited = {
        path: path.read_text()
        for path in (
            workflow_copy / "dtwin" / "residual_stats.py",
            workflow_copy / "dtwin" / "figures" / "fig01_pipeline.py",
            workflow_copy / "dtwin" / "bias_correction.py",
            workflow_copy / "dtwin" / "figures" / "fig05_correction_timeseries.py",
        )
    }
    residual_stats, pipeline, correction, label = edited
    try:
        # a figure's own edit (a label) reruns that figure and the claims page: no draw, since
        # the draws judge with dtwin.claim_criteria and import no figure module
        label.write_text(edited[label] + "\n# edited\n")
        assert planned_rules(workflow_copy) == {"fig05_correction_timeseries", "claims"}
        # the draws' claims judge residual structure; their BIC sweeps do not import it
        judged = DRAWS - {"bic_draws"}
        residual_stats.write_text(edited[residual_stats] + "\n# edited\n")
        assert planned_rules(workflow_copy) == {
            "fig05_correction_timeseries",
            "fig03_residual_acf",
            "claims",
            *judged,
        }
        pipeline.write_text(edited[pipeline] + "\n# edited\n")
        assert planned_rules(workflow_copy) == {
            "fig05_correction_timeseries",
            "fig01_pipeline",
            "fig03_residual_acf",
            "claims",
            *judged,
        }
        correction.write_text(edited[correction] + "\n# edited\n")
        assert planned_rules(workflow_copy) == {
            "fig01_pipeline",
            "fig03_residual_acf",
            "targeted_intervention",
            "fig05_correction_timeseries",
            "fig06_correction_distributions",
            "claims",
            *SWEEP,
            *DRAWS,
        }
    finally:
        # the edits were comments: restore the sources and mark the outputs current
        for path, text in edited.items():
            path.write_text(text)
        snakemake(workflow_copy, "--touch", "--cores", "1")
        assert planned_rules(workflow_copy) == set()


#: The sweep and the gap benchmark: independent of every other rule (no input of theirs is
#: another rule's output), and rerun byte for byte by the tests that change their chunking or
#: executor (test_chunked_and_unchunked_batches_give_byte_identical_outputs,
#: test_sweep_jobs_run_unchanged_under_a_cluster_executor,
#: test_a_run_interrupted_during_the_sweep_resumes_to_identical_outputs).
BATCH_RULES = {"sweep_chunk", "fig11_sensitivity", "gap_cases", "gap_diagnoses", "gap_benchmark"}


#: What a rule's log says when the job server (dtwin/_job_server.py) ran the job.
SERVED = "started (forked from the job server)"


def served_rules(workdir: Path) -> set[str]:
    """Rules whose last job (its log) ran in a child of the job server."""
    folder = workdir / "logs"
    logs = [p for p in folder.rglob("*.log") if SERVED in p.read_text(errors="replace")]
    return {p.relative_to(folder).parts[0].removesuffix(".log") for p in logs}


def test_rerun_gives_byte_identical_tables_and_figures(workflow_copy):
    """Every other rule forced to run again (and `claims`, which reads the batches too) gives
    the same bytes in every table, figure and JSON; the batches' own reruns are in the tests
    named at BATCH_RULES, so they are not run a second time here. The first run went through
    the job server (all jobs but those that started before it was ready), the rerun runs each
    job in its own process (``job_server=False``): the server changes no byte."""
    outputs = sorted((workflow_copy / "results").rglob("*.*")) + sorted(
        (workflow_copy / "paper_figures").glob("*.*")
    )
    assert len(
        [p for p in outputs if p.suffix == ".json" and p.parent.name == "paper_figures"]
    ) == (len(ARTIFACTS) + 1)
    # every rule has a `benchmark:` file (benchmarks/rules/<rule>.tsv or <rule>/<job>.tsv)
    every_rule = {p.parts[0].removesuffix(".tsv") for p in rule_benchmark_files(workflow_copy)}
    assert every_rule > BATCH_RULES
    forced = sorted(every_rule - BATCH_RULES)
    assert planned_rules_of(workflow_copy, "--forcerun", *forced) == set(forced)
    assert len(served_rules(workflow_copy) & set(forced)) >= len(forced) // 2
    before = {str(path): path.read_bytes() for path in outputs}
    snakemake(workflow_copy, "--cores", "2", "--forcerun", *forced, "--config", "job_server=False")
    assert served_rules(workflow_copy) & set(forced) == set()
    after = {str(path): path.read_bytes() for path in outputs}
    changed = [name for name in before if before[name] != after[name]]
    assert not changed


#: What the sweep and the gap benchmark publish (their chunk files aside).
BATCH_OUTPUTS = (
    "results/sensitivity/runs.csv",
    "results/sensitivity/summary.csv",
    "results/gap/benchmark.csv",
    *(
        f"paper_figures/{name}.{ext}"
        for name in ("fig11_sensitivity", "gap_benchmark")
        for ext in ("png", "pdf", "json")
    ),
)


def case_files(workdir: Path, chunks: str) -> dict[str, bytes]:
    """The gap benchmark's per-case files in the chunk folders ``chunks`` (a glob), by
    kind/case/name."""
    gap = workdir / "results" / "gap"
    return {
        f"{p.relative_to(gap).parts[0]}/{p.parent.name}/{p.name}": p.read_bytes()
        for p in sorted(gap.glob(f"*/{chunks}/*/*"))
    }


def test_chunked_and_unchunked_batches_give_byte_identical_outputs(workflow_copy):
    """One chunk instead of the default (2 sweep chunks, 2 gap chunks): same bytes everywhere.

    A changed chunk count plans only the chunk jobs and the rules that gather them.
    """
    before = {name: (workflow_copy / name).read_bytes() for name in BATCH_OUTPUTS}
    cases_before = case_files(workflow_copy, "*-of-2")
    # two cases, each: recording.csv, twin.yaml, key.json (cases/) and diagnosis.json,
    # report.md (diagnoses/; the benchmark draws no gap.png)
    assert len(cases_before) == 2 * 5
    assert not any(name.endswith("gap.png") for name in cases_before)
    targets = ["fig11_sensitivity", "gap_benchmark", "--set-scatter", "sweep=1", "gap=1"]
    assert planned_jobs(workflow_copy, *targets) == {
        "sweep_chunk": 1,
        "fig11_sensitivity": 1,
        "gap_cases": 1,
        "gap_diagnoses": 1,
        "gap_benchmark": 1,
    }
    snakemake(workflow_copy, "--cores", "2", *targets)
    assert (workflow_copy / "results" / "sensitivity" / "chunks" / "1-of-1.json").exists()
    changed = [name for name, data in before.items() if (workflow_copy / name).read_bytes() != data]
    assert not changed
    assert case_files(workflow_copy, "1-of-1") == cases_before
    # back to the default chunks (still on disk): only the gathers and what reads them rerun
    for one_chunk in workflow_copy.glob("results/*/*/1-of-1*"):
        if one_chunk.is_dir():
            shutil.rmtree(one_chunk)
        else:
            one_chunk.unlink()
    assert planned_rules(workflow_copy) == {"fig11_sensitivity", "gap_benchmark", "claims"}
    # their outputs on disk are the one-chunk run's, byte-identical to the default chunks' (above):
    # mark them current instead of recomputing them
    snakemake(workflow_copy, "--touch", "--cores", "1")
    assert planned_rules(workflow_copy) == set()


def csv_bytes(table) -> bytes:
    """The bytes `write_csv` would write for ``table`` (every table of the pipeline goes so)."""
    return table.to_csv(index=False, float_format="%.12g").encode()


def test_each_config_seed_gives_byte_identical_draws_and_another_seed_different_ones():
    """Every random draw derives from a seed in the config: simulation.seed (command steps and
    process noise), faults.seed (SensorNoisy noise), hmm.seed (EM starts) and the gap
    benchmark's case seeds. Each stage is run twice with its seed and once with seed + 1."""
    from dtwin.gapbench.generator import generate_case
    from dtwin.stages.faults import inject_scenario
    from dtwin.stages.regimes import fit_regimes
    from dtwin.stages.twin import fit_twin_surrogates, roll_out_twin, simulate_asset

    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    config["simulation"]["T"] = 6.0
    config["hmm"].update(n_restarts=2, max_iter=20)

    def with_seed(section: str, seed: int) -> dict:
        return {**config[section], "seed": seed}

    def physics(seed: int):
        return simulate_asset(with_seed("simulation", seed), config["command"], config["twin"])

    nominal = physics(config["simulation"]["seed"])
    theta = fit_twin_surrogates(nominal, config["arx"])
    surrogate, _ = roll_out_twin(nominal, theta, config["twin"], "physics")

    def faulted(seed: int):
        return inject_scenario(nominal, surrogate, with_seed("faults", seed), config["twin"])[0]

    residuals = inject_scenario(nominal, surrogate, config["faults"], config["twin"])[1]
    features = residuals[["e1", "e2a", "e2b", "e4"]]

    def em_fit(seed: int):
        fit = fit_regimes(features, with_seed("hmm", seed), "fault_fit")[1]
        return pd.DataFrame(fit.means).assign(log_likelihood=fit.log_likelihood)

    draws = {
        "simulation.seed": physics,
        "faults.seed": faulted,
        "hmm.seed": em_fit,
        "gap case seed": lambda seed: (
            generate_case("coulomb_friction", seed, nominal=paper_twin()).recording
        ),
    }
    for name, draw in draws.items():
        first, again, other = (csv_bytes(draw(seed)) for seed in (11, 11, 12))
        assert first == again, f"{name}: the same seed gave different bytes"
        assert first != other, f"{name}: another seed gave the same bytes"


def test_lint_is_clean(workflow_copy):
    result = snakemake(workflow_copy, "--lint")
    assert "Congratulations" in result.stdout + result.stderr


def test_sweep_dry_run_plans_the_requested_number_of_chunks(tmp_path):
    workdir = tmp_path / "repo"
    shutil.copytree(REPO, workdir, ignore=IGNORED)

    def grid(config):
        config["sensitivity"].update(
            alphas=[0.2, 0.8], sensor_A_mults=[1.5], sensor_B_mults=[0.5], n_replicates=3
        )

    edit_config(workdir, grid)
    # 6 points: the default 2 chunks, 4 when asked, at most one per point, 0 = one per point
    for scatter, chunks in (([], 2), (["sweep=4"], 4), (["sweep=50"], 6), (["sweep=0"], 6)):
        options = ["--set-scatter", *scatter] if scatter else []
        assert planned_jobs(workdir, "fig11_sensitivity", *options) == {
            "sweep_chunk": chunks,
            "fig11_sensitivity": 1,
        }


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda c: c["twin"]["fusion"].update(alpha=1.3), "twin.fusion.alpha"),
        (lambda c: c["twin"]["plant"].pop("k"), "twin.plant"),
        (lambda c: c["simulation"].update(seed="eleven"), "simulation.seed"),
        (lambda c: c["twin"]["actuator"].update(tau=-0.15), "twin.actuator.tau"),
        (lambda c: c["faults"].update(drift_origin="sideways"), "faults.drift_origin"),
        (lambda c: c["faults"]["schedule"][1].pop("end"), "faults.schedule.1"),
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


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1400,1000",
    "--virtual-time-budget=15000",
]


def screenshot(url: str, path: Path, profile: Path, attempts: int = 3) -> np.ndarray:
    """A headless-Chromium screenshot of ``url``; retried while the page is still blank.

    A first Chromium start in a fresh profile can take the shot before the report's
    JavaScript has drawn anything; a page that never draws stays blank on every attempt.
    """
    image = None
    for attempt in range(attempts):
        subprocess.run(
            [
                CHROMIUM,
                *CHROMIUM_FLAGS,
                "--run-all-compositor-stages-before-draw",
                f"--user-data-dir={profile}-{attempt}",
                f"--screenshot={path}",
                url,
            ],
            capture_output=True,
            timeout=120,
            check=True,
        )
        image = plt.imread(path)
        if non_white_fraction(image) > 0.05:
            break
    return image


def non_white_fraction(image: np.ndarray) -> float:
    return float(np.mean(np.any(image[..., :3] < 0.95, axis=-1)))


@pytest.fixture(scope="module")
def report_html(workflow_copy) -> Path:
    """`snakemake --report` of the complete short run."""
    report = workflow_copy / "paper_figures" / "report.html"
    snakemake(workflow_copy, "--report", str(report))
    return report


class _Tags(HTMLParser):
    """Every start tag of an HTML page with its attributes."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []

    def handle_starttag(self, tag, attrs) -> None:
        self.tags.append((tag, dict(attrs)))


def report_variable(html: str, script_id: str):
    """The JSON value of ``var NAME = ...`` in the report's ``<script id=script_id>``."""
    found = re.search(
        rf'<script id="{script_id}">\s*var \w+ = (.*?);?\s*</script>', html, flags=re.S
    )
    assert found, f"the report has no <script id={script_id!r}> holding a JSON value"
    return json.loads(found.group(1))


def test_html_report_is_self_contained_with_every_figure(report_html):
    """Without a browser: one offline page (no external script, style or image), the app's
    mount point and data, and every artifact's PNG embedded, decodable and drawn, with its
    caption and rule. Non-white share of each figure measured 0.069 (fig09) to 0.63 (fig10)
    on the short run (2026-11-23); a blank or broken image gives 0, the bound is 0.03."""
    html = report_html.read_text()
    parser = _Tags()
    parser.feed(html)
    external = [
        (tag, attrs)
        for tag, attrs in parser.tags
        if tag in ("script", "link", "img", "iframe") and (attrs.get("src") or attrs.get("href"))
    ]
    assert external == []
    assert ("div", {"id": "app"}) in parser.tags and "react.production.min.js" in html
    results = report_variable(html, "results")
    rules = report_variable(html, "rules")
    for artifact in ARTIFACTS:
        entry = results.get(f"paper_figures/{artifact}.png")
        assert entry is not None, f"{artifact}.png is not in the report"
        assert entry["job_properties"]["rule"] == artifact and artifact in rules
        assert entry["caption"].strip(), f"{artifact}.png has no caption"
        header, _, data = entry["data_uri"].partition(";base64,")
        assert header.startswith("data:image/png")
        png = base64.b64decode(data, validate=True)
        assert png.startswith(b"\x89PNG\r\n\x1a\n")
        assert non_white_fraction(plt.imread(io.BytesIO(png))) > 0.03, artifact


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="optional browser render skipped: Chromium is not installed (Debian package "
    "'chromium'); the report's structure is still checked without a browser by "
    "test_html_report_is_self_contained_with_every_figure",
)
def test_html_report_renders_in_a_browser(report_html, tmp_path):
    """Optional extra: headless Chromium runs the report's JavaScript and draws its figures."""
    landing = screenshot(report_html.as_uri(), tmp_path / "landing.png", tmp_path / "profile")
    assert non_white_fraction(landing) > 0.05  # the app ran: menu and contact sheet are drawn
    assert_landing_is_the_contact_sheet(report_html, landing, tmp_path)
    results = report_variable(report_html.read_text(), "results")
    uris = {f"{a}.png": results[f"paper_figures/{a}.png"]["data_uri"] for a in ARTIFACTS}
    page = tmp_path / "figures.html"
    page.write_text("".join(f'<img src="{uris[f"{a}.png"]}" width="600">' for a in ARTIFACTS))
    figures = screenshot(page.as_uri(), tmp_path / "figures.png", tmp_path / "profile2")
    assert non_white_fraction(figures) > 0.05  # the embedded figures decode and draw


def assert_landing_is_the_contact_sheet(report_html: Path, landing: np.ndarray, tmp_path: Path):
    """The report opens on the contact sheet: a card per figure in the DOM the app rendered,
    and the sheet's closing rule drawn inside the 1400 x 1000 screenshot (the whole sheet is
    on one screen; the rule spans the sheet, about 1100 px, no thumbnail card is 300 px wide)."""
    from dtwin.figures._contact_sheet import SHEET_END_COLOR

    dom = subprocess.run(
        [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path}/profile-dom", "--dump-dom",
         report_html.as_uri()],
        capture_output=True, text=True, timeout=120, check=True,
    ).stdout  # fmt: skip
    assert 'class="dtwin-sheet"' in dom, "the landing page does not show the contact sheet"
    sheet = dom[dom.index('class="dtwin-sheet"') :]
    assert len(re.findall(r'<a class="card"', sheet)) == len(ARTIFACTS)
    for artifact in ARTIFACTS:
        assert f"app.showResultInfo('paper_figures/{artifact}.png')" in sheet, artifact
    rgb = np.array([int(SHEET_END_COLOR[i : i + 2], 16) / 255 for i in (1, 3, 5)])
    rule = np.all(np.abs(landing[..., :3] - rgb) < 0.04, axis=-1).sum(axis=1)
    assert rule.max() > 600, f"the sheet's closing rule is not on screen (longest run {rule.max()})"


def _default_sigint() -> None:
    """Give a child process the default SIGINT disposition (it may inherit SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_a_run_interrupted_during_the_sweep_resumes_to_identical_outputs(workflow_copy, tmp_path):
    """SIGINT to Snakemake mid-sweep, then the same command again: complete, equal, no debris.

    Runs on its own copy with a 12-point grid in 12 chunks, so that chunks are still pending
    when the first one lands (the shared copy's grid has 4 points: at most 4 chunks) and so
    that a failure here cannot leave the other tests' copy half-deleted. The reference is the
    same grid in one chunk (one job instead of twelve; the chunk count changes no gathered
    byte, test_chunked_and_unchunked_batches_give_byte_identical_outputs): the resumed run's
    gathered tables and figure equal it byte for byte, its twelve chunks hold its points and
    rows.
    """
    workdir = tmp_path / "repo"
    shutil.copytree(workflow_copy, workdir, symlinks=True)

    def twelve_points(config: dict) -> None:
        config["sensitivity"].update(alphas=[0.2, 0.5, 0.8], sensor_B_mults=[0.5, 1.0, 1.5, 2.0])

    edit_config(workdir, twelve_points)
    sweep_dir = workdir / "results" / "sensitivity"
    target = ["results/sensitivity/summary.csv", "--set-scatter", "sweep=12"]
    snakemake(
        workdir, "--cores", "2", "results/sensitivity/summary.csv", "--set-scatter", "sweep=1"
    )
    figure_files = sorted((workdir / "paper_figures").glob("fig11_sensitivity.*"))
    gathered = [sweep_dir / "summary.csv", sweep_dir / "runs.csv", *figure_files]
    reference = {p: p.read_bytes() for p in gathered}
    one_chunk = chunk_contents([sweep_dir / "chunks" / "1-of-1.json"])
    assert len(one_chunk["points"]) == 12
    for path in reference:
        path.unlink()
    env = {**os.environ, "PYTHONPATH": str(workdir), "MPLBACKEND": "Agg"}
    command = [sys.executable, "-m", "snakemake", "--cores", "2", *target]
    log_path = tmp_path / "interrupted.log"
    with log_path.open("w") as log_file:
        # a test run started in the background (`make test &`, nohup) inherits SIGINT ignored,
        # and Python then installs no KeyboardInterrupt handler: Snakemake ran every SIGINT
        # through to the end (measured once, load 7); the child gets the default disposition
        process = subprocess.Popen(
            command,
            cwd=workdir,
            env=env,
            stdout=log_file,
            stderr=subprocess.STDOUT,
            preexec_fn=_default_sigint,
        )
        deadline = time.monotonic() + 300
        while not list(sweep_dir.glob("chunks/*-of-12.json")) and time.monotonic() < deadline:
            time.sleep(0.05)
        # Snakemake 9 can miss a SIGINT that lands while it finishes a job (twice in about six
        # runs the sweep then ran to the end); a user presses Ctrl-C again, and so does this
        # test, until Snakemake says it is terminating (never during its clean-up)
        for _ in range(30):
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=2.0)
                break
            except subprocess.TimeoutExpired:
                if "Terminating processes on user request" in log_path.read_text():
                    process.wait(timeout=120)
                    break
        else:
            process.wait(timeout=120)
    log = log_path.read_text()
    assert process.returncode != 0, f"Snakemake exited 0 after SIGINT:\n{log}"
    finished = len(list(sweep_dir.glob("chunks/*-of-12.json")))
    assert 1 <= finished < 12, f"{finished} of 12 sweep chunks had finished when interrupted"
    debris = [p.name for p in workdir.rglob(".*.tmp*")]
    assert not debris, debris
    snakemake(workdir, "--cores", "2", *target)
    changed = [p.name for p, data in reference.items() if not p.exists() or p.read_bytes() != data]
    assert not changed
    chunks = sorted(sweep_dir.glob("chunks/*-of-12.json"))
    assert len(chunks) == 12
    assert chunk_contents(chunks) == one_chunk


def chunk_contents(chunks: list[Path]) -> dict[str, list[str]]:
    """The sweep points and rows of ``chunks`` together, each as sorted-key JSON, sorted."""
    contents = [json.loads(chunk.read_text()) for chunk in chunks]
    return {
        key: sorted(json.dumps(item, sort_keys=True) for c in contents for item in c[key])
        for key in ("points", "rows")
    }


SUBMIT_SCRIPT = """#!/usr/bin/env bash
# A stand-in scheduler for Snakemake's cluster-generic executor: run the job script detached
# and print a job id, as `sbatch --parsable` would.
jobscript="${@: -1}"
nohup bash "$jobscript" > "$jobscript.out" 2>&1 &
echo "$!"
"""


def test_sweep_jobs_run_unchanged_under_a_cluster_executor(workflow_copy):
    """The two sweep chunks through cluster-generic give the local run's bytes."""
    sweep_dir = workflow_copy / "results" / "sensitivity"
    local = {p: p.read_bytes() for p in sorted(sweep_dir.glob("chunks/*.json"))}
    assert len(local) == 2
    for path in local:
        path.unlink()
    (workflow_copy / "submit.sh").write_text(SUBMIT_SCRIPT)
    snakemake(
        workflow_copy,
        *[str(p.relative_to(workflow_copy)) for p in local],
        "--executor",
        "cluster-generic",
        "--cluster-generic-submit-cmd",
        "bash submit.sh",
        "--jobs",
        "4",
        "--latency-wait",
        "30",
    )
    changed = [p.name for p, data in local.items() if p.read_bytes() != data]
    assert not changed
    assert planned_rules(workflow_copy) == set()
