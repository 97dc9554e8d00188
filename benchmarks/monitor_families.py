"""The monitor on the benchmark families (tanks, motor, thermal) with an effect switched on halfway.

Usage: python benchmarks/monitor_families.py [N_SEEDS] [N_SAMPLES] [--diagnose N]
(default 5 seeds, 4000 samples; prints one JSON object; docs/monitor.md §Checked on the families)

Per family and seed (the ``bare`` arm: only the input and the last output recorded, the
modules one unit, the twin file of the case):

- ``dtwin regimes`` (:func:`dtwin.monitor.batch_regimes.regimes_of`, defaults) is fitted on the
  first half of the ``none`` case: a clean recording, so the model holds nominal regimes only
  and any effect is one it never saw (the ``unknown`` regime);
- **clean**: the monitor over the whole ``none`` case (its second half unseen by the fit): an
  event there is a false alarm;
- **switch**: for every effect of the family, the monitor over the ``none`` case's first half
  followed by the effect case's second half (same seed: same asset, input and noise). The
  delay is the first ``left_nominal`` event's change sample minus the switch. For an effect at
  an output the splice is exactly the effect switching on; for one in the dynamics the effect
  case's states have run with the effect from the start, so the splice also jumps the states.
  An effect that acts only beyond a level (a limit, a saturation) shows when the signal gets
  there: the delay counts from its **onset**, the first sample after the switch at which it
  moves an output by a noise standard deviation (the two recordings share their noise); an
  effect that never does is not counted.

``--diagnose N``: for the first N seeds, ``dtwin diagnose`` on the 1000 samples since the
detected change (what the monitor runs in the background), scored with the family's key.
"""

from __future__ import annotations

import io
import json
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
from dtwin.monitor.batch_regimes import regimes_of
from dtwin.monitor.live import Monitor, MonitorSettings
from dtwin.monitor.model_file import monitor_model_from_mapping, regimes_file_mapping

PY = sys.executable
OUTPUT_EFFECTS = ("output_bias_drift", "output_quantization", "output_scale_error",
                  "output_delay", "output_saturation")  # fmt: skip
WINDOW = 200


def _events(model, table, frame: pd.DataFrame) -> list[dict]:
    monitor = Monitor(model, table, MonitorSettings(), io.StringIO(), io.StringIO())
    monitor.feed(frame.to_csv(index=False, float_format="%.17g").splitlines())
    rows = [json.loads(x) for x in monitor.out.getvalue().splitlines()]
    return [row for row in rows if row.get("event") == "left_nominal"]


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


def _family_seed(family: str, seed: int, n: int, diagnose: bool) -> dict:
    none = generate_family_case(f"{family}_bare_none", seed, n_samples=n)
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
           "fit_cpu_s": round(fit_cpu, 2), "clean_events": len(clean), "effects": {}}  # fmt: skip
    for effect in FAMILY_EFFECTS[family][1:]:
        case = generate_family_case(f"{family}_bare_{effect}", seed, n_samples=n)
        stream = pd.concat([none.recording.iloc[:half], case.recording.iloc[half:]])
        onset = _onset(none, case, half)
        events = [e for e in _events(model, table, stream) if e["since"] / dt >= half - WINDOW]
        delay = None
        if events and onset is not None:
            delay = round(events[0]["since"] / dt) - onset
        entry = {"onset": None if onset is None else onset - half, "delay": delay,
                 "regime": events[0]["regime"] if events else None,
                 "snr": round(float(case.key["snr"]), 2)}  # fmt: skip
        if diagnose and events:
            entry["diagnosis"] = _diagnose(stream, none.twin, half + max(delay, 0), case.key)
        out["effects"][effect] = entry
    return out


def _summary(results: dict) -> dict:
    summary = {}
    for family, seeds in results.items():
        delays = {"output": [], "dynamics": []}
        for run in seeds.values():
            for effect, entry in run["effects"].items():
                kind = "output" if effect in OUTPUT_EFFECTS else "dynamics"
                if entry["onset"] is not None:  # an effect that never shows is not counted
                    delays[kind].append(entry["delay"])
        row = {"settling": sorted({run["settling"] for run in seeds.values()}),
               "clean_without_event": sum(run["clean_events"] == 0 for run in seeds.values()),
               "clean_runs": len(seeds)}  # fmt: skip
        for kind, values in delays.items():
            found = [d for d in values if d is not None and 0 <= d <= WINDOW]
            row[kind] = {"n": len(values), "within_200": len(found),
                         "median_delay": float(np.median(found)) if found else None}  # fmt: skip
        summary[family] = row
    return summary


def main(n_seeds: int, n_samples: int, n_diagnosed: int) -> dict:
    results = {family: {} for family in FAMILY_EFFECTS}
    for family in FAMILY_EFFECTS:
        for seed in range(n_seeds):
            run = _family_seed(family, seed, n_samples, seed < n_diagnosed)
            results[family][seed] = run
            print(family, seed, json.dumps(run), file=sys.stderr, flush=True)
    return {"summary": _summary(results), "runs": results}


if __name__ == "__main__":
    args = sys.argv[1:]
    n_diagnosed = 0
    if "--diagnose" in args:
        n_diagnosed = int(args[args.index("--diagnose") + 1])
        del args[args.index("--diagnose") : args.index("--diagnose") + 2]
    seeds = int(args[0]) if args else 5
    samples = int(args[1]) if len(args) > 1 else 4000
    print(json.dumps(main(seeds, samples, n_diagnosed)))
