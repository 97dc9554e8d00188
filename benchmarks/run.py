"""`make bench`: timings of the DAG, the HMM engine and the gap diagnoser → benchmarks/results.json.

Benchmarks, not tests: one run each on whatever this machine is doing, medians where repeated.
1. the paper DAG (every paper figure, without the gap benchmark) cold with --cores 2 and
   --cores 1 on a copy in a temporary folder, then a no-op rerun;
2. per-rule wall time and peak memory from the rules' `benchmark:` files of the cold run;
3. one HMM fit (K 4, D 10, 10 restarts) at T = 1e3 … 1e6 through dtwin and through plain
   hmmlearn with its defaults, each in a fresh process: seconds per EM iteration, peak memory
   (for T >= 1e5 the iterations are capped at 3 per restart so the run ends in minutes;
   seconds per iteration exclude start-up, random starts and the final posteriors);
4. `dtwin diagnose` on a 2,000-sample six-module recording and a 100,000-sample one.
"""

from __future__ import annotations

import csv
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable
IGNORE = shutil.ignore_patterns(
    ".git",
    ".venv",
    ".snakemake",
    "results",
    "logs",
    "benchmarks",
    "paper_figures",
    "__pycache__",
    "*.egg-info",
    ".pytest_cache",
)


def run(args, cwd, env=None) -> float:
    start = time.perf_counter()
    subprocess.run(args, cwd=cwd, env=env, check=True, capture_output=True, text=True)
    return time.perf_counter() - start


#: Every paper figure's JSON (workflow/artifacts.yaml): the DAG benchmark's targets.
PAPER_TARGETS = [
    f"paper_figures/{name}.json"
    for name in yaml.safe_load((REPO / "workflow" / "artifacts.yaml").read_text())["paper"]
]


def dag_benchmarks() -> dict:
    results = {}
    env = {**os.environ, "PYTHONPATH": ""}
    for cores in (2, 1):
        with tempfile.TemporaryDirectory() as folder:
            workdir = Path(folder) / "repo"
            shutil.copytree(REPO, workdir, ignore=IGNORE)
            env["PYTHONPATH"] = str(workdir)
            targets = PAPER_TARGETS
            cold = run([PY, "-m", "snakemake", "--cores", str(cores), *targets], workdir, env)
            results[f"cold_cores{cores}_s"] = round(cold, 2)
            if cores == 2:
                results["targets"] = targets
                results["noop_rerun_s"] = round(
                    run([PY, "-m", "snakemake", "--cores", "2", *targets], workdir, env), 2
                )
                results["rules"] = rule_benchmarks(workdir / "benchmarks" / "rules")
    return results


def rule_benchmarks(folder: Path) -> dict:
    rules = {}
    for path in sorted(folder.rglob("*.tsv")):
        with path.open() as handle:
            row = next(csv.DictReader(handle, delimiter="\t"))
        name = str(path.relative_to(folder).with_suffix(""))
        rules[name] = {"wall_s": float(row["s"]), "max_rss_mb": float(row["max_rss"])}
    return rules


def hmm_benchmarks() -> list[dict]:
    rows = []
    for n_steps in (1_000, 10_000, 100_000, 1_000_000):
        max_iter = "500" if n_steps < 100_000 else "3"
        for engine in ("dtwin", "hmmlearn"):
            done = subprocess.run(
                [PY, str(REPO / "benchmarks" / "hmm_fit.py"), engine, str(n_steps), "10", max_iter],
                capture_output=True,
                text=True,
                check=True,
                cwd=REPO,
            )
            rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
            print(rows[-1], flush=True)
    return rows


def gap_benchmarks() -> dict:
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for n_samples in (2_000, 100_000):
            case = folder / f"case{n_samples}"
            run(
                [
                    PY,
                    "-m",
                    "dtwin",
                    "generate",
                    "coulomb_friction",
                    "--seed",
                    "3",
                    "--out",
                    str(case),
                    "--n-samples",
                    str(n_samples),
                ],
                REPO,
            )
            seconds = run(
                [
                    PY,
                    "-m",
                    "dtwin",
                    "diagnose",
                    str(case / "recording.csv"),
                    "--twin",
                    str(case / "twin.yaml"),
                    "--out",
                    str(folder / f"out{n_samples}"),
                ],
                REPO,
            )
            results[f"diagnose_{n_samples}_samples_s"] = round(seconds, 2)
    return results


def main() -> None:
    results = {
        "date": date.today().isoformat(),
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
        },
        "dag": dag_benchmarks(),
        "gap": gap_benchmarks(),
        "hmm": hmm_benchmarks(),
    }
    (REPO / "benchmarks" / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps({k: v for k, v in results.items() if k != "dag"}, indent=2))
    print({k: v for k, v in results["dag"].items() if k != "rules"})


if __name__ == "__main__":
    main()
