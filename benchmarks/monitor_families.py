"""The monitor on the benchmark families (tanks, motor, thermal) with an effect switched on halfway.

Usage: python benchmarks/monitor_families.py [N_SEEDS] [N_SAMPLES] [--diagnose N] [--cache DIR]
(default 14 seeds, 4000 samples; prints one JSON object; docs/monitor.md §Checked on the families)

Per family and seed (the ``bare`` arm: only the input and the last output recorded, the
modules one unit, the twin file of the case):

- ``dtwin regimes`` (:func:`dtwin.monitor.batch_regimes.regimes_of`, defaults) is fitted on the
  first half of the ``none`` case: a clean recording, so the model holds nominal regimes only
  and any effect is one it never saw (the ``unknown`` regime, the novelty test);
- **clean**: the monitor over the whole ``none`` case (its second half unseen by the fit): an
  event there is a false alarm (rate per hour of the clean samples monitored, Poisson 95 %
  upper bound);
- **switch**: for every effect of the family, the monitor over the ``none`` case's first half
  followed by the effect case's second half (same seed: same asset, input and noise). For an
  effect at an output the splice is exactly the effect switching on; for one in the dynamics
  the effect case's states have run with the effect from the start, so the splice also jumps
  the states. An effect that acts only beyond a level (a limit, a saturation) shows when the
  signal gets there: the delay counts from its **onset**, the first sample after the switch at
  which it moves an output by a noise standard deviation (the two recordings share their
  noise); an effect that never does is not counted. **Detected**: the first ``left_nominal``
  event fired from 200 samples before the switch on is fired (its ``t``, after the hold) at or
  after the switch and at most 200 samples after the onset (an event before the switch is a
  false alarm; one between the switch and the onset found the effect while it was still below
  a noise sd). ``delay`` is the event's sample minus the onset's.

Rates come with their case counts and Wilson 95 % intervals, split by the effect's size in noise
units (the case key's ``snr``: the effect's RMS over the noise standard deviation).

``--diagnose N``: for the first N seeds, the switch streams run with the monitor's background
diagnoses on (:class:`dtwin.monitor.background.DiagnosisJobs`, ``dtwin diagnose`` on the 1000
samples from each detected change); a detected case's **triggered** diagnosis is the one of its
event's window (``window_as_recorded``: that window's file holds the stream's samples from the
change, to the bit), and ``dtwin diagnose`` also runs on the 1000 samples from the switch (the
effect's own window); each is scored with the family's key. ``--cache DIR``: the generated
cases are kept in DIR (``<family>_<seed>.pkl``: effect → recording, twin, key) and read back on
a rerun.
"""

from __future__ import annotations

import io
import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from dtwin.artifacts import to_jsonable
from dtwin.gap.recording import recording_with_columns
from dtwin.gap.twin_file import table_file
from dtwin.gapbench.families import FAMILY_EFFECTS, generate_family_case, score_family_case
from dtwin.monitor.background import DiagnosisJobs
from dtwin.monitor.batch_regimes import regimes_of
from dtwin.monitor.live import Monitor, MonitorSettings
from dtwin.monitor.model_file import monitor_model_from_mapping, regimes_file_mapping
from dtwin.monitor.regime_model import poisson_upper
from dtwin.monitor.row_stream import LineSource
from dtwin.proportions import wilson_interval

PY = sys.executable
OUTPUT_EFFECTS = ("output_bias_drift", "output_quantization", "output_scale_error",
                  "output_delay", "output_saturation")  # fmt: skip
WINDOW = 200
SNR_BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, float("inf")))


def _events(model, table, frame: pd.DataFrame, jobs: DiagnosisJobs | None = None) -> list[dict]:
    """The monitor's events over ``frame``: ``left_nominal``, and ``diagnosis`` with ``jobs``."""
    monitor = Monitor(model, table, MonitorSettings(), io.StringIO(), io.StringIO(), jobs)
    monitor.run(LineSource(stream=io.StringIO(frame.to_csv(index=False, float_format="%.17g"))))
    rows = [json.loads(x) for x in monitor.out.getvalue().splitlines()]
    return [row for row in rows if row.get("event") in ("left_nominal", "diagnosis")]


def _triggered(events: list[dict], since: float, stream: pd.DataFrame, key) -> dict:
    """The score of the monitor's own diagnosis of the window from ``since`` (s)."""
    t = stream.t.to_numpy()
    start = int(np.argmin(np.abs(t - since)))  # the event's time is t0 + k·dt, not read
    found = [e for e in events if e["event"] == "diagnosis" and e["since"] == t[start]]
    if not found or "report" not in found[0]:
        return {"error": True}
    answer = Path(found[0]["report"]).parent
    window = pd.read_csv(answer.parent / "window.csv")
    recorded = stream.iloc[start : start + len(window)][window.columns]
    out = score_family_case(key, json.loads((answer / "diagnosis.json").read_text()))
    out["window_as_recorded"] = bool(np.array_equal(window.to_numpy(), recorded.to_numpy()))
    return out


def _diagnose(frame, twin, since: int, key) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        frame.iloc[since : since + 1000].to_csv(folder / "w.csv", index=False)
        (folder / "twin.json").write_text(json.dumps(twin))
        subprocess.run([PY, "-m", "dtwin", "diagnose", str(folder / "w.csv"), "--twin",
                        str(folder / "twin.json"), "--out", str(folder / "out")],
                       capture_output=True, check=False)  # fmt: skip
        answer = folder / "out" / "diagnosis.json"
        if not answer.exists():
            return {"error": True}
        return score_family_case(key, json.loads(answer.read_text()))


def _onset(none, case, half: int) -> int | None:
    """First sample from the switch at which the effect moves an output by a noise sd or more.

    Both recordings carry the same noise, so their difference is the effect's alone. None: it
    never does (the effect does not show in the second half).
    """
    for signal, sd in case.key["noise"].items():
        gap = np.abs(case.recording[signal].to_numpy() - none.recording[signal].to_numpy())
        shown = np.flatnonzero(gap[half:] >= sd)
        if shown.size:
            return half + int(shown[0])
    return None


class _Case:
    """A generated case (recording, twin, key), as :func:`generate_family_case` returns it."""

    def __init__(self, recording, twin, key):
        self.recording, self.twin, self.key = recording, twin, key


def _cases(family: str, seed: int, n: int, cache: Path | None) -> dict[str, _Case]:
    path = None if cache is None else cache / f"{family}_{seed}.pkl"
    if path is not None and path.exists():
        return {k: _Case(*v) for k, v in pickle.loads(path.read_bytes()).items()}
    cases = {}
    for effect in FAMILY_EFFECTS[family]:
        case = generate_family_case(f"{family}_bare_{effect}", seed, n_samples=n)
        cases[effect] = _Case(case.recording, case.twin, case.key)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        plain = {k: (c.recording, c.twin, c.key) for k, c in cases.items()}
        path.write_bytes(pickle.dumps(plain))
    return cases


def _family_seed(family: str, seed: int, n: int, diagnose: bool, cache: Path | None) -> dict:
    cases = _cases(family, seed, n, cache)
    none = cases["none"]
    table = table_file(none.twin)
    half = n // 2
    fitted = none.recording.iloc[:half]
    recording = recording_with_columns(fitted, (*table.signals, *table.exogenous))
    start = time.process_time()
    result = regimes_of(recording, table, nominal=(0.0, float(recording.t[-1])))
    fit_cpu = time.process_time() - start
    raw = json.loads(json.dumps(to_jsonable(regimes_file_mapping(result))))
    model = monitor_model_from_mapping(raw, table)
    dt = none.key["dt"]
    clean = [e for e in _events(model, table, none.recording) if e["since"] / dt >= result.settling]
    out = {"settling": result.settling, "k": result.regime_fit.model.n_states,
           "ar_order": list(result.regime_fit.model.novelty.order),
           "fit_cpu_s": round(fit_cpu, 2), "clean_events": len(clean),
           "clean_hours": (len(none.recording) - result.settling) * dt / 3600.0,
           "effects": {}}  # fmt: skip
    for effect in FAMILY_EFFECTS[family][1:]:
        case = cases[effect]
        stream = pd.concat([none.recording.iloc[:half], case.recording.iloc[half:]])
        with tempfile.TemporaryDirectory() as folder:
            out["effects"][effect] = _switch(model, table, none, case, stream, diagnose, folder)
    return out


def _switch(model, table, none, case, stream, diagnose: bool, folder: str) -> dict:
    """The monitor over a switch stream: detection and, with ``diagnose``, the diagnoses."""
    half, dt = len(none.recording) // 2, none.key["dt"]
    onset = _onset(none, case, half)
    jobs = None
    if diagnose:
        (Path(folder) / "twin.json").write_text(json.dumps(none.twin))
        columns = dict.fromkeys(s for u in model.units for s in (*u.inputs, *u.outputs))
        jobs = DiagnosisJobs(Path(folder) / "twin.json", columns, keep=Path(folder) / "jobs")
    seen = _events(model, table, stream, jobs)
    events = [e for e in seen if e["event"] == "left_nominal" and e["t"] / dt >= half - WINDOW]
    delay = None
    if events and onset is not None:
        delay = round(events[0]["t"] / dt) - onset
    entry = {"onset": None if onset is None else onset - half, "delay": delay,
             "regime": events[0]["regime"] if events else None,
             "snr": round(float(case.key["snr"]), 2)}  # fmt: skip
    if diagnose and _detected(entry):
        entry["diagnosis"] = _triggered(seen, events[0]["since"], stream, case.key)
        entry["diagnosis_at_switch"] = _diagnose(stream, none.twin, half, case.key)
    return entry


def _rate(flags: list[bool]) -> dict:
    k, n = int(sum(flags)), len(flags)
    low, high = wilson_interval(k, n) if n else (float("nan"), float("nan"))
    return {"k": k, "n": n, "rate": k / n if n else None,
            "wilson95": [round(low, 3), round(high, 3)]}  # fmt: skip


def _detected(entry: dict) -> bool:
    """The first event fired from the switch on and at most WINDOW samples after the onset."""
    return entry["delay"] is not None and -entry["onset"] <= entry["delay"] <= WINDOW


def _block(runs: list[dict]) -> dict:
    """Clean, detection (by SNR band and kind), delays and diagnoses over some seeds' runs."""
    entries = [(effect, e) for run in runs for effect, e in run["effects"].items()
               if e["onset"] is not None]  # fmt: skip
    events = sum(run["clean_events"] for run in runs)
    hours = sum(run["clean_hours"] for run in runs)
    row = {
        "settling": sorted({run["settling"] for run in runs}),
        "clean_without_event": _rate([run["clean_events"] == 0 for run in runs]),
        "clean_events_per_hour": {"events": events, "hours": round(hours, 3),
                                  "per_hour": events / hours if hours else None,
                                  "upper95_per_hour": poisson_upper(events, hours)},
        "detected": _rate([_detected(e) for _, e in entries]),
        "not_counted_no_onset": sum(e["onset"] is None for run in runs
                                    for e in run["effects"].values()),
    }  # fmt: skip
    for low, high in SNR_BANDS:
        band = [_detected(e) for _, e in entries if low <= e["snr"] < high]
        row[f"detected_snr_{low:g}_{high:g}"] = _rate(band)
    for kind in ("output", "dynamics"):
        row[f"detected_{kind}"] = _rate(
            [
                _detected(e)
                for effect, e in entries
                if (effect in OUTPUT_EFFECTS) == (kind == "output")
            ]
        )
    found = [e["delay"] for _, e in entries if _detected(e)]
    row["median_delay"] = float(np.median(found)) if found else None
    diagnosed = [e for _, e in entries if "diagnosis" in e]
    for key in ("diagnosis", "diagnosis_at_switch"):
        row[key] = {
            "named": _rate([bool(e[key].get("named")) for e in diagnosed]),
            "located": _rate([bool(e[key].get("located")) for e in diagnosed]),
        }
    return row


def _summary(results: dict) -> dict:
    summary = {family: _block(list(seeds.values())) for family, seeds in results.items()}
    summary["all"] = _block([run for seeds in results.values() for run in seeds.values()])
    return summary


def main(n_seeds: int, n_samples: int, n_diagnosed: int, cache: Path | None = None) -> dict:
    results = {family: {} for family in FAMILY_EFFECTS}
    for family in FAMILY_EFFECTS:
        for seed in range(n_seeds):
            run = _family_seed(family, seed, n_samples, seed < n_diagnosed, cache)
            results[family][seed] = run
            print(family, seed, json.dumps(run), file=sys.stderr, flush=True)
    return {"summary": _summary(results), "runs": results}


if __name__ == "__main__":
    args = sys.argv[1:]
    n_diagnosed, folder = 0, None
    if "--diagnose" in args:
        n_diagnosed = int(args[args.index("--diagnose") + 1])
        del args[args.index("--diagnose") : args.index("--diagnose") + 2]
    if "--cache" in args:
        folder = Path(args[args.index("--cache") + 1])
        del args[args.index("--cache") : args.index("--cache") + 2]
    seeds = int(args[0]) if args else 14
    samples = int(args[1]) if len(args) > 1 else 4000
    print(json.dumps(main(seeds, samples, n_diagnosed, folder)))
