"""`dtwin regimes` and `dtwin monitor` on a twin of the paper's size: speed and latency.

Usage: python benchmarks/monitor.py [N_SAMPLES]   (default 100000; prints one JSON object)

The recording is `dtwin generate coulomb_friction --seed 3 --n-samples N` (the paper's six
modules; the monitored channels are u_act, x, v, y_A and y_B: fusion and KPI are recorded
exactly, so their residuals are round-off and left out). Measured (docs/monitor.md §Speed):

- ``regimes_s`` / ``regimes_cpu_s``: `dtwin regimes` with the BIC sweep (K ≤ 8), wall and CPU
  seconds of the process (target ≤ 60 s at 100,000 samples); ``regimes_k8_*`` with ``--k 8``;
- ``samples_per_s``: the monitor in this process (:class:`dtwin.monitor.live.Monitor`, the model
  of ``--k 8``: K = 8 regimes + unknown, 5 channels) over the recording in pieces of 8192 lines,
  one JSON line per sample, CPU seconds of this process (target ≥ 50,000); ``..._every_100``
  with one line per 100 samples;
- ``latency_ms_*``: the same monitor fed one line at a time (a live stream at its own pace):
  wall milliseconds per line, median, 99th percentile and largest of 5000 (target ≤ 1 ms), and
  ``latency_cpu_ms_mean``, CPU milliseconds per line (what another process's load does not
  change);
- ``cli_*``: `dtwin monitor < recording.csv > /dev/null` in a subprocess, wall and CPU seconds,
  and the same with an empty stream (start-up: imports and loading the model).
"""

from __future__ import annotations

import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _timed(args: list[str], stdin=None, stdout=subprocess.DEVNULL) -> tuple[float, float]:
    """Wall and CPU seconds of a subprocess."""
    cpu, start = _children_cpu(), time.perf_counter()
    subprocess.run(args, cwd=REPO, check=True, stdin=stdin, stdout=stdout,
                   stderr=subprocess.DEVNULL)  # fmt: skip
    return time.perf_counter() - start, _children_cpu() - cpu


def _monitor(regimes: Path, twin: Path, every: int):
    from dtwin.monitor.commands import load_twin
    from dtwin.monitor.live import Monitor, MonitorSettings
    from dtwin.monitor.model_file import monitor_model_from_mapping

    raw = json.loads(regimes.read_text())
    table = load_twin(str(twin), raw["dt"])
    model = monitor_model_from_mapping(raw, table)
    return Monitor(model, table, MonitorSettings(every=every), io.StringIO(), io.StringIO())


def _warm(monitor, lines: list[str]) -> None:
    """Feed the first 2000 lines in two pieces: the header, the settling period and every
    compiled loop loaded (a continued piece loads some: the tracker's shaping)."""
    monitor.feed(lines[:1000])
    monitor.feed(lines[1000:2000])


def throughput(regimes: Path, twin: Path, lines: list[str], every: int) -> float:
    """Samples per CPU second of the monitor over ``lines`` in pieces of 8192."""
    monitor = _monitor(regimes, twin, every)
    _warm(monitor, lines)
    start = time.process_time()
    for first in range(2000, len(lines), 8192):
        monitor.feed(lines[first : first + 8192])
        monitor.out.seek(0)
        monitor.out.truncate()
    return (len(lines) - 2000) / (time.process_time() - start)


def latency(regimes: Path, twin: Path, lines: list[str], n: int = 5000) -> dict[str, float]:
    """Milliseconds per line fed one at a time."""
    monitor = _monitor(regimes, twin, 1)
    _warm(monitor, lines)
    times, cpu = [], time.process_time()
    for line in lines[2000 : 2000 + n]:
        start = time.perf_counter()
        monitor.feed([line])
        times.append(1e3 * (time.perf_counter() - start))
    cpu = 1e3 * (time.process_time() - cpu) / n
    times.sort()
    return {"latency_ms_median": round(statistics.median(times), 4),
            "latency_ms_p99": round(times[int(0.99 * len(times))], 4),
            "latency_ms_max": round(times[-1], 4),
            "latency_cpu_ms_mean": round(cpu, 4)}  # fmt: skip


def main(n_samples: int) -> dict:
    out: dict = {"n_samples": n_samples}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        case = folder / "case"
        _timed([PY, "-m", "dtwin", "generate", "coulomb_friction", "--seed", "3", "--out",
                str(case), "--n-samples", str(n_samples)])  # fmt: skip
        recording, twin = case / "recording.csv", case / "twin.yaml"
        regimes = [PY, "-m", "dtwin", "regimes", str(recording), "--twin", str(twin), "--out"]
        wall, cpu = _timed([*regimes, str(folder / "bic")])
        out.update(regimes_s=round(wall, 1), regimes_cpu_s=round(cpu, 1))
        wall, cpu = _timed([*regimes, str(folder / "k8"), "--k", "8"])
        out.update(regimes_k8_s=round(wall, 1), regimes_k8_cpu_s=round(cpu, 1))
        chosen = json.loads((folder / "bic" / "regimes.json").read_text())
        out["k_chosen"] = chosen["n_states"]
        model = folder / "k8" / "regimes.json"
        out["channels"] = json.loads(model.read_text())["model"]["channels"]
        lines = recording.read_text().splitlines()
        out["samples_per_s"] = round(throughput(model, twin, lines, 1))
        out["samples_per_s_every_100"] = round(throughput(model, twin, lines, 100))
        out.update(latency(model, twin, lines))
        monitor = [PY, "-m", "dtwin", "monitor", "--twin", str(twin), "--regimes", str(model),
                   "--no-diagnose"]  # fmt: skip
        with open(recording) as stdin:
            wall, cpu = _timed(monitor, stdin=stdin)
        out.update(cli_s=round(wall, 2), cli_cpu_s=round(cpu, 2))
        with open(os.devnull) as stdin:
            wall, cpu = _timed(monitor, stdin=stdin)
        out.update(cli_start_s=round(wall, 2), cli_start_cpu_s=round(cpu, 2))
    return out


if __name__ == "__main__":
    print(json.dumps(main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)))
