"""The `fmu` benchmark section's case: a two-state FMU module, and where its diagnosis spends time.

A motor benchmark family case (dtwin/gapbench/families.py: ``motor_bare_input_deadzone``, seed
3, full strength; drive voltage ``V`` in, speed ``w`` recorded) against the test FMU
(tests/twin/fmu/motor.c: ``i' = (V − R·i − Ke·w)/L``, ``w' = (Kt·i − b·w)/J``, FMI 2.0, built
from source by tests/twin/fmu/build.py) with the case's declared params; the asset has an input
dead zone the twin does not.

``python benchmarks/fmu_case.py N_SAMPLES FOLDER [INTERFACE]`` writes ``recording.csv``,
``twin.yaml``, ``models/motor.fmu`` and ``key.json`` (the truth) into FOLDER
(tests/twin/fmu/twins.py::write_fmu_case); with ``--profile`` after them it also diagnoses the
case in this process with ``calibrate`` and prints a JSON line: the CPU seconds spent in the
FMU's model (``simulate`` and ``derivatives``: the FMU's C functions and the RK4 around them;
``start``: its re-initialisation through fmpy), summed over this process and the forked
processes that fit candidates (:func:`dtwin.gap.table_fit.map_fits`), against the CPU seconds
of the whole diagnosis (this process and those; the rest is ``fitting_s``), its wall seconds
(``total_s``), and the answer.
"""

from __future__ import annotations

import json
import multiprocessing
import resource
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASE_TYPE, SEED = "motor_bare_input_deadzone", 3


def write_case(n_samples: int, folder: Path, interface: str = "model_exchange") -> None:
    """Write the case (module docstring) with ``n_samples`` samples into ``folder``."""
    sys.path.insert(0, str(REPO))
    from dtwin.artifacts import write_json
    from dtwin.gapbench.families import generate_family_case
    from tests.twin.fmu.build import build_fmu
    from tests.twin.fmu.twins import write_fmu_case

    case = generate_family_case(CASE_TYPE, SEED, n_samples=n_samples, magnitude=1.0)
    write_fmu_case(case, build_fmu(), folder, interface)
    write_json(case.key, folder / "key.json")


def profile(folder: Path) -> dict:
    """Diagnose the case with ``calibrate``; seconds in the FMU's model against the whole."""
    from dtwin.gap.recording import read_recording
    from dtwin.gap.table_diagnose import diagnose_table
    from dtwin.gap.twin_file import load_twin_text, table_file
    from dtwin.twin import fmu

    # shared with the forked fitting processes, which inherit them
    spent = {key: multiprocessing.Value("d", 0.0) for key in ("simulate", "start", "calls")}

    def timed(function, key):
        def wrapper(*args, **kwargs):
            begin = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                with spent[key].get_lock():
                    spent[key].value += time.process_time() - begin
                if key == "simulate":
                    with spent["calls"].get_lock():
                        spent["calls"].value += 1

        return wrapper

    for kind in (fmu.FmuModel, fmu.FmuModelExchange):
        kind.simulate = timed(kind.simulate, "simulate")
    fmu.FmuModelExchange.derivatives = timed(fmu.FmuModelExchange.derivatives, "simulate")
    fmu._Instance.start = timed(fmu._Instance.start, "start")
    begin, cpu_begin = time.perf_counter(), _cpu()
    table = table_file(load_twin_text((folder / "twin.yaml").read_text()), base_dir=folder)
    recording = read_recording(folder / "recording.csv", columns=("V", "w"))
    result = diagnose_table(recording, table, calibrate=True)
    total, cpu = time.perf_counter() - begin, _cpu() - cpu_begin
    return {
        "total_s": round(total, 2),
        "cpu_s": round(cpu, 2),
        "fmu_model_s": round(spent["simulate"].value, 2),
        "fmu_initialise_s": round(spent["start"].value, 2),
        "fitting_s": round(cpu - spent["simulate"].value, 2),
        "simulations": int(spent["calls"].value),
        "answer": f"{result.effect} at {result.at} {result.params}",
    }


def _cpu() -> float:
    """CPU seconds of this process and its finished children."""
    own, children = (
        resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
    )
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


if __name__ == "__main__":
    target = Path(sys.argv[2])
    write_case(int(sys.argv[1]), target, *(a for a in sys.argv[3:4] if a != "--profile"))
    if "--profile" in sys.argv:
        print(json.dumps(profile(target)))
