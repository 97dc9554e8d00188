"""`make bench`: timings of the DAG, imports, the HMM engine and the gap diagnoser → results.json.

Benchmarks, not tests: one run each on whatever this machine is doing (each section records the
load average before and after it), medians where repeated. Sections (`python benchmarks/run.py
[section ...]` runs only those and keeps the others of benchmarks/results.json):

- ``dag``: the paper DAG (every paper figure, without the gap benchmark and the draws) cold with
  --cores 2 and --cores 1 on a copy in a temporary folder after set-up (:func:`set_up`: the EM
  kernels and the force loop compiled into the copy's numba cache, as `make` does), then the no-op
  (a rerun and a dry run ``snakemake -n``, median of 3 each, wall and CPU seconds). CPU seconds come
  from the processes themselves, not Snakemake's ``benchmark:`` sampler (which stops after ~15 s):
  every job is measured by the kernel (benchmarks/cpu_probe/sitecustomize.py: ``os.wait4`` on the
  job's process), Snakemake's own process by ``getrusage``, and the run's total is the
  ``RUSAGE_CHILDREN`` of this process around it. Per job (``jobs``: CPU s, wall s, peak MB) and per
  rule (``by_rule``: jobs, wall s, CPU s) for the cold --cores 2 run, with each job's start and end
  (s after the run started) and the jobs' summed wall time over the run's
  (``jobs_wall_over_run_wall``: 2 when both cores are always busy); ``vs_r`` is the R scripts' time
  (:data:`R_REFERENCE_S`) over ours, for each core count;
- ``figures``: `snakemake --cores 2 all` cold after set-up (every artifact incl. the gap
  benchmark and the claims across draws), measured the same way;
- ``imports``: per script in scripts/, the CPU seconds of a fresh interpreter that runs only its
  imports (median of 3) and which heavy libraries they load;
- ``hmm``: one HMM fit (K 4, D 10, 10 restarts) at T = 1e3 … 1e6 through dtwin and through plain
  hmmlearn with its defaults, each in a fresh process: seconds per EM iteration, peak memory
  (for T >= 1e5 the iterations are capped at 3 per restart so the run ends in minutes;
  seconds per iteration are the whole fit's seconds over its EM iterations); then one EM
  iteration alone at T = 1e6 through dtwin's engine and hmmlearn's stock GaussianHMM
  (``em-dtwin``, ``em-hmmlearn``: median of 3 of ``(t(3 iterations) − t(1)) / 2``, the
  iteration's tracemalloc peak and the process's peak RSS; benchmarks/hmm_fit.py), and the
  same at T = 1000 for K = 4, 12, 20 (median of 7; the BIC sweeps' size);
- ``gap``: `dtwin diagnose` on a 2,000-sample six-module recording and a 100,000-sample one,
  and `--calibrate` on a 130,000-sample plant-only rig (target: ≤ 30 s);
- ``table``: `dtwin diagnose --calibrate` on a two-state expression module written as a twin
  table, 10,000 and 100,000 samples (benchmarks/table_cases.py): wall, CPU, peak RSS, answer;
- ``fmu``: `dtwin diagnose --calibrate` on a two-state FMU module (the test FMU, a DC motor,
  Model Exchange and Co-Simulation), a 10,000-sample motor family case with an input dead zone
  (benchmarks/fmu_case.py; target ≤ 60 s): wall, CPU, peak
  RSS and answer of the command, and in-process where the diagnosis spends its time (the FMU's
  model against the fitting);
- ``monitor``: `dtwin regimes` on a 100,000-sample recording of the paper's six modules (with
  the BIC sweep, and with ``--k 8``), then the monitor on it (K = 8, 5 channels): samples per
  CPU second with one JSON line per sample and with ``--every 100``, milliseconds per line fed
  one at a time, the CLI's wall and start-up (benchmarks/monitor.py);
- ``tests``: `make test-fast` in the repository (its .venv set up): wall seconds, the CPU
  seconds of every process (``RUSAGE_CHILDREN`` around it: lint, both pytest-xdist workers and
  the subprocesses the tests start) and the tests passed.
"""

from __future__ import annotations

import ast
import json
import os
import platform
import resource
import shutil
import statistics
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
#: The authors' R scripts on all paper figures, cold, single-threaded, same machine kind, load
#: 0.4-0.7: median of fresh runs, seconds (110-128 s; docs/performance.md).
R_REFERENCE_S = 112.7
#: The folder whose sitecustomize.py measures every job's CPU time (see its docstring).
CPU_PROBE = REPO / "benchmarks" / "cpu_probe"


def children_cpu() -> float:
    """User + system CPU seconds of every child process this process has reaped so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measured_run(args: list[str], workdir: Path) -> dict:
    """Run Snakemake in ``workdir`` with the CPU probe; wall, CPU and every job's numbers."""
    with tempfile.TemporaryDirectory() as log:
        env = {
            **os.environ,
            "PYTHONPATH": f"{CPU_PROBE}{os.pathsep}{workdir}",
            "MPLBACKEND": "Agg",
            "DTWIN_CPU_LOG": log,
        }
        cpu_before, started = children_cpu(), time.time()
        wall = run([PY, "-m", "snakemake", *args], workdir, env)
        total = children_cpu() - cpu_before
        jobs, snakemake_cpu, server_cpu = probe_records(Path(log), started)
    busy = sum(job["wall_s"] for job in jobs.values())
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(total, 2),
        "snakemake_cpu_s": snakemake_cpu,
        "job_server_cpu_s": server_cpu,
        "served_jobs": sum(1 for job in jobs.values() if job.get("served")),
        "jobs_wall_over_run_wall": round(busy / wall, 2),
        "jobs": jobs,
    }


def probe_records(folder: Path, started: float) -> tuple[dict, float, float]:
    """Per job ``rule[/wildcards]``: CPU s, wall s, peak MB, start and end s after ``started``
    (an epoch time); Snakemake's own CPU s and the job server's (its preload). A job the job
    server ran (dtwin/_job_server.py) has two records, its own process's and the forked
    child's (``served``): CPU s are summed, the peak is the larger, wall and times are the
    job process's; ``served`` says it was."""
    read = {path.stem: json.loads(path.read_text()) for path in folder.glob("*.json")}
    jobs: dict[str, dict] = {}
    for key, identity in sorted(
        read.items(), key=lambda item: "served" in read.get(f"usage-{item[0][4:]}", {})
    ):
        if key.startswith("job-"):
            usage = read[f"usage-{key[4:]}"]
            name = "/".join([identity["rule"], *identity["wildcards"].values()])
            if usage.get("served"):
                row = jobs[name]
                row["cpu_s"] = round(row["cpu_s"] + usage["cpu_s"], 3)
                row["max_rss_mb"] = max(row["max_rss_mb"], usage["max_rss_mb"])
                row["served"] = True
                continue
            end = usage["end_epoch_s"] - started
            jobs[name] = {k: usage[k] for k in ("cpu_s", "wall_s", "max_rss_mb")} | {
                "start_s": round(end - usage["wall_s"], 2),
                "end_s": round(end, 2),
            }
    processes = [r for k, r in read.items() if k.startswith("process-")]
    own = round(sum(r["cpu_s"] for r in processes if not _is_job_server(r)), 2)
    server = round(sum(r["cpu_s"] for r in processes if _is_job_server(r)), 2)
    return dict(sorted(jobs.items())), own, server


def _is_job_server(record: dict) -> bool:
    """Whether a process record is dtwin's job server's (its own CPU: the preload)."""
    return any("_job_server" in str(arg) for arg in record["argv"])


def noop(args: list[str], workdir: Path, repeats: int = 3) -> dict:
    """Median wall and CPU seconds of ``snakemake <args>`` when nothing is to be done."""
    env = {**os.environ, "PYTHONPATH": str(workdir), "MPLBACKEND": "Agg"}
    walls, cpus = [], []
    for _ in range(repeats):
        before = children_cpu()
        walls.append(run([PY, "-m", "snakemake", *args], workdir, env))
        cpus.append(children_cpu() - before)
    return {
        "wall_s": round(statistics.median(walls), 2),
        "cpu_s": round(statistics.median(cpus), 2),
    }


def set_up(workdir: Path) -> None:
    """What `make` does in a fresh clone before any timing: compile the EM kernels and the gap
    diagnoser's force loop into the copy's numba cache (the __pycache__ folders, left out of the
    copy), so no job pays a cold compile."""
    env = {**os.environ, "PYTHONPATH": str(workdir)}
    warm = (
        "from dtwin import _em_kernels; from dtwin.twin import _force_kernels; "
        "_em_kernels.warm_up(); _force_kernels.warm_up()"
    )
    run([PY, "-c", warm], workdir, env)


def dag_benchmarks() -> dict:
    results: dict = {"targets": PAPER_TARGETS, "r_reference_s": R_REFERENCE_S}
    for cores in (2, 1):
        with tempfile.TemporaryDirectory() as folder:
            workdir = Path(folder) / "repo"
            shutil.copytree(REPO, workdir, ignore=IGNORE)
            set_up(workdir)
            cold = measured_run(["--cores", str(cores), *PAPER_TARGETS], workdir)
            results[f"cold_cores{cores}_s"] = cold["wall_s"]
            results[f"cold_cores{cores}_cpu_s"] = cold["cpu_s"]
            results[f"vs_r_cores{cores}"] = round(R_REFERENCE_S / cold["wall_s"], 2)
            if cores == 2:
                results["snakemake_cpu_s"] = cold["snakemake_cpu_s"]
                results["job_server_cpu_s"] = cold["job_server_cpu_s"]
                results["served_jobs"] = cold["served_jobs"]
                results["jobs_wall_over_run_wall"] = cold["jobs_wall_over_run_wall"]
                results["jobs"] = cold["jobs"]
                results["by_rule"] = by_rule(cold["jobs"])
                for name, extra in (("noop_rerun", []), ("noop_dry_run", ["-n"])):
                    done = noop([*extra, "--cores", "2", *PAPER_TARGETS], workdir)
                    results[f"{name}_s"], results[f"{name}_cpu_s"] = done["wall_s"], done["cpu_s"]
    return results


def by_rule(jobs: dict) -> dict:
    """Jobs, summed wall seconds and summed CPU seconds per rule (chunks and cases together)."""
    totals: dict[str, dict] = {}
    for name, row in jobs.items():
        total = totals.setdefault(name.split("/")[0], {"jobs": 0, "wall_s": 0.0, "cpu_s": 0.0})
        total["jobs"] += 1
        total["wall_s"] = round(total["wall_s"] + row["wall_s"], 2)
        total["cpu_s"] = round(total["cpu_s"] + row["cpu_s"], 2)
    return dict(sorted(totals.items(), key=lambda item: -item[1]["cpu_s"]))


def figures_benchmark() -> dict:
    """`snakemake --cores 2` (rule all) cold on a fresh copy, then a no-op rerun."""
    with tempfile.TemporaryDirectory() as folder:
        workdir = Path(folder) / "repo"
        shutil.copytree(REPO, workdir, ignore=IGNORE)
        set_up(workdir)
        cold = measured_run(["--cores", "2"], workdir)
        rerun = noop(["--cores", "2"], workdir, repeats=1)
    return {
        "cold_cores2_s": cold["wall_s"],
        "cold_cores2_cpu_s": cold["cpu_s"],
        "snakemake_cpu_s": cold["snakemake_cpu_s"],
        "job_server_cpu_s": cold["job_server_cpu_s"],
        "served_jobs": cold["served_jobs"],
        "noop_rerun_s": rerun["wall_s"],
        "by_rule": by_rule(cold["jobs"]),
    }


#: Libraries whose import a light rule should not pay (see tests/workflow/test_import_budget.py).
HEAVY = ("sklearn", "hmmlearn", "scipy.signal", "scipy.stats", "statsmodels", "matplotlib.pyplot")


def import_benchmarks(repeats: int = 3) -> dict:
    """Per script: CPU seconds of its imports in a fresh interpreter, and the heavy ones loaded."""
    results = {}
    env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"}
    probe = (
        "\nimport json, resource, sys\n"
        "u = resource.getrusage(resource.RUSAGE_SELF)\n"
        "print(json.dumps([u.ru_utime + u.ru_stime, sorted(sys.modules)]))"
    )
    for script in sorted((REPO / "scripts").glob("*.py")):
        tree = ast.parse(script.read_text())
        imports = [ast.unparse(n) for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
        samples = []
        for _ in range(repeats):
            done = subprocess.run(
                [PY, "-c", "\n".join(imports) + probe],
                cwd=REPO,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            cpu, modules = json.loads(done.stdout.splitlines()[-1])
            samples.append(cpu)
        loaded = [h for h in HEAVY if any(m == h or m.startswith(h + ".") for m in modules)]
        results[script.stem] = {"cpu_s": round(statistics.median(samples), 3), "heavy": loaded}
    return results


def hmm_benchmarks() -> list[dict]:
    rows = []

    def measure(*arguments: str) -> None:
        done = subprocess.run(
            [PY, str(REPO / "benchmarks" / "hmm_fit.py"), *arguments],
            capture_output=True,
            text=True,
            check=True,
            cwd=REPO,
        )
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(rows[-1], flush=True)

    for n_steps in (1_000, 10_000, 100_000, 1_000_000):
        max_iter = "500" if n_steps < 100_000 else "3"
        for engine in ("dtwin", "hmmlearn"):
            measure(engine, str(n_steps), "10", max_iter)
    for engine in ("em-dtwin", "em-hmmlearn"):  # one EM iteration alone at T = 1e6
        measure(engine, "1000000", "3")
    for n_states in ("4", "12", "20"):  # and at the sweeps' size (target <= 0.5 ms at K = 20)
        for engine in ("em-dtwin", "em-hmmlearn"):
            measure(engine, "1000", "7", n_states)
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
        results["diagnose_rig_130000_samples_s"] = _plant_only_rig(folder)
    return results


def _plant_only_rig(folder: Path) -> float:
    """Seconds of `dtwin diagnose --calibrate` on a 130,000-sample plant-only rig recording.

    The speed target (≤ 30 s): the rig family's cubic-stiffness seed 2 (13.7 samples per
    period, open loop, ``t, u_act, x`` only, no nominal parameters).
    """
    case = folder / "rig130k"
    generate = [PY, "-m", "dtwin", "generate", "rig_cubic_stiffness", "--seed", "2"]
    run([*generate, "--out", str(case), "--n-samples", "130000"], REPO)
    diagnose = [PY, "-m", "dtwin", "diagnose", str(case / "recording.csv")]
    options = ["--twin", str(case / "twin.yaml"), "--out", str(folder / "rig130k_out")]
    return round(run([*diagnose, *options, "--calibrate"], REPO), 2)


def table_benchmarks() -> dict:
    """`dtwin diagnose --calibrate` on a two-state expression module written as a table.

    The speed targets of a user's twin: 10,000 samples in ≤ 10 s, 100,000 in ≤ 30 s, peak
    memory ≤ 1 GB (benchmarks/table_cases.py: an oscillator with a withheld friction). Wall
    and CPU seconds of the whole command, the child's peak RSS (MB) and the answer.
    """
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for n_samples in (10_000, 100_000):
            case = folder / f"osc{n_samples}"
            run([PY, str(REPO / "benchmarks" / "table_cases.py"), str(n_samples), str(case)], REPO)
            cpu_before, start = children_cpu(), time.perf_counter()
            diagnose = [PY, "-m", "dtwin", "diagnose", str(case / "recording.csv"), "--twin"]
            out = folder / f"out{n_samples}"
            run([*diagnose, str(case / "twin.yaml"), "--out", str(out), "--calibrate"], REPO)
            answer = json.loads((out / "diagnosis.json").read_text())
            results[f"diagnose_{n_samples}"] = {
                "wall_s": round(time.perf_counter() - start, 2),
                "cpu_s": round(children_cpu() - cpu_before, 2),
                "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024),
                "answer": f"{answer['effect']} at {answer['at']}",
            }
            print(n_samples, results[f"diagnose_{n_samples}"], flush=True)
    return results


def fmu_benchmarks() -> dict:
    """`dtwin diagnose --calibrate` on a 10,000-sample two-state FMU module (both interfaces).

    The command's wall and CPU seconds, peak RSS (MB) and answer; then the same case diagnosed
    in one process with the FMU's model timed (benchmarks/fmu_case.py ``--profile``).
    """
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for interface in ("model_exchange", "co_simulation"):
            case = Path(folder) / interface
            script = [PY, str(REPO / "benchmarks" / "fmu_case.py"), "10000", str(case), interface]
            done = subprocess.run([*script, "--profile"], cwd=REPO, check=True,
                                  capture_output=True, text=True)  # fmt: skip
            cpu_before, start = children_cpu(), time.perf_counter()
            diagnose = [PY, "-m", "dtwin", "diagnose", str(case / "recording.csv"), "--twin"]
            run([*diagnose, str(case / "twin.yaml"), "--out", str(case / "out"), "--calibrate"],
                REPO)  # fmt: skip
            answer = json.loads((case / "out" / "diagnosis.json").read_text())
            results[f"diagnose_10000_{interface}"] = {
                "wall_s": round(time.perf_counter() - start, 2),
                "cpu_s": round(children_cpu() - cpu_before, 2),
                "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024),
                "answer": f"{answer['effect']} at {answer['at']}",
                "in_process": json.loads(done.stdout.strip().splitlines()[-1]),
            }
            print(interface, results[f"diagnose_10000_{interface}"], flush=True)
    return results


def monitor_benchmark() -> dict:
    """benchmarks/monitor.py in a fresh process (its JSON line)."""
    done = subprocess.run(
        [PY, str(REPO / "benchmarks" / "monitor.py"), "100000"],
        cwd=REPO, check=True, capture_output=True, text=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def tests_benchmark() -> dict:
    """`make test-fast` once: wall s, CPU s of every process and the count of tests passed."""
    cpu_before, start = children_cpu(), time.perf_counter()
    done = subprocess.run(["make", "test-fast"], cwd=REPO, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - start, children_cpu() - cpu_before
    if done.returncode != 0:
        raise RuntimeError(f"make test-fast failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}")
    summary = done.stdout.strip().splitlines()[-1]  # "1107 passed, 60 deselected in 52.3s"
    return {
        "test_fast_s": round(wall, 1),
        "test_fast_cpu_s": round(cpu, 1),
        "test_fast_passed": int(summary.split(" passed")[0].split()[-1]),
    }


SECTIONS = {
    "dag": dag_benchmarks,
    "figures": figures_benchmark,
    "imports": import_benchmarks,
    "gap": gap_benchmarks,
    "table": table_benchmarks,
    "fmu": fmu_benchmarks,
    "hmm": hmm_benchmarks,
    "monitor": monitor_benchmark,
    "tests": tests_benchmark,
}


def main(sections: list[str]) -> None:
    path = REPO / "benchmarks" / "results.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    old_date = results.pop("date", None)  # results.json before sections carried their own date
    for name in SECTIONS:
        if name in results and "results" not in results[name]:
            results[name] = {"date": old_date, "results": results[name]}
    results["machine"] = {
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }
    for name in sections or list(SECTIONS):
        load_before = os.getloadavg()[0]
        value = SECTIONS[name]()
        load = {"load_1min_before": load_before, "load_1min_after": os.getloadavg()[0]}
        results[name] = {"date": date.today().isoformat(), **load, "results": value}
        path.write_text(json.dumps(results, indent=2) + "\n")
        print(name, json.dumps(load), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
