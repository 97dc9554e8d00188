"""The `fmu` benchmark section's case: a two-state FMU module, and where its diagnosis spends time.

The test FMU (tests/twin/fmu: ``x' = w, w' = (u − c·w − k·x)/m``, k = 4, c = 0.4, m = 1, FMI
2.0, built from source by tests/twin/fmu/build.py) as the twin; the asset is the same oscillator
behind an input dead zone of 0.5 (integrated by scipy's solve_ivp, rtol 1e-9), driven by random
steps held over 2 s, dt = 0.02 s, 1 % white noise on ``x``.

``python benchmarks/fmu_case.py N_SAMPLES FOLDER [INTERFACE]`` writes ``recording.csv``,
``twin.yaml`` and ``models/oscillator.fmu`` into FOLDER; with ``--profile`` after them it also
diagnoses the case in this process with ``calibrate`` and prints a JSON line: seconds in the
FMU's model (``simulate`` and ``derivatives``: the FMU's C functions and the RK4 around them,
and the FMU's re-initialisation through fmpy) against the whole diagnosis, and the answer.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.integrate import solve_ivp

REPO = Path(__file__).resolve().parents[1]
DT = 0.02


def write_case(n_samples: int, folder: Path, interface: str = "model_exchange") -> None:
    """Write the case (module docstring) with ``n_samples`` samples into ``folder``."""
    sys.path.insert(0, str(REPO))
    from tests.twin.fmu.build import build_fmu

    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-2, 2, n_samples // 100 + 1), 100)[:n_samples]
    driven = np.sign(u) * np.maximum(np.abs(u) - 0.5, 0.0)

    def rhs(t, s):
        return [s[1], driven[min(int(t / DT), n_samples - 1)] - 0.4 * s[1] - 4.0 * s[0]]

    times = np.arange(n_samples) * DT
    sol = solve_ivp(rhs, (0, times[-1]), [0.0, 0.0], t_eval=times, max_step=DT / 2, rtol=1e-9)
    x = sol.y[0] + 0.01 * rng.standard_normal(n_samples)
    (folder / "models").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(build_fmu(), folder / "models" / "oscillator.fmu")
    pd.DataFrame({"t": times, "u": u, "x": x}).to_csv(folder / "recording.csv", index=False)
    twin = {
        "dt": DT,
        "modules": {
            "plant": {
                "fmu": "models/oscillator.fmu",
                "interface": interface,
                "inputs": {"u": "u"},
                "outputs": {"x": "x"},
                "params": {"k": 4.0, "c": 0.4},
            }
        },
        "noise": {"x": 0.01},
    }
    (folder / "twin.yaml").write_text(yaml.safe_dump(twin, sort_keys=False))


def profile(folder: Path) -> dict:
    """Diagnose the case with ``calibrate``; seconds in the FMU's model against the whole."""
    from dtwin.gap.recording import read_recording
    from dtwin.gap.table_diagnose import diagnose_table
    from dtwin.gap.twin_file import load_twin_text, table_file
    from dtwin.twin import fmu

    spent = {"simulate": 0.0, "start": 0.0, "calls": 0}

    def timed(function, key):
        def wrapper(*args, **kwargs):
            begin = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                spent[key] += time.perf_counter() - begin
                spent["calls"] += key == "simulate"

        return wrapper

    for kind in (fmu.FmuModel, fmu.FmuModelExchange):
        kind.simulate = timed(kind.simulate, "simulate")
    fmu.FmuModelExchange.derivatives = timed(fmu.FmuModelExchange.derivatives, "simulate")
    fmu._Instance.start = timed(fmu._Instance.start, "start")
    begin = time.perf_counter()
    table = table_file(load_twin_text((folder / "twin.yaml").read_text()), base_dir=folder)
    recording = read_recording(folder / "recording.csv", columns=("u", "x"))
    result = diagnose_table(recording, table, calibrate=True)
    total = time.perf_counter() - begin
    return {
        "total_s": round(total, 2),
        "fmu_model_s": round(spent["simulate"], 2),
        "fmu_initialise_s": round(spent["start"], 2),
        "fitting_s": round(total - spent["simulate"], 2),
        "simulations": spent["calls"],
        "answer": f"{result.effect} at {result.at} {result.params}",
    }


if __name__ == "__main__":
    target = Path(sys.argv[2])
    write_case(int(sys.argv[1]), target, *(a for a in sys.argv[3:4] if a != "--profile"))
    if "--profile" in sys.argv:
        print(json.dumps(profile(target)))
