"""Deep fuzz of `dtwin diagnose`: recordings that pass the early checks but are hostile inside.

Every recording here has a valid time axis (a uniform ``dt`` from 1e-6 s to 100 s), at least
200 rows and the columns of at least one module, so it reaches the diagnosis (or the recording's
content checks of docs/gap.md §Bad input). It starts from a generated withheld-effect case
(:func:`dtwin.gapbench.generate_case`: realistic signals with a gap to find) and is then made
hostile: spikes of 1e3–1e15 spreads in any column, constant and all-zero channels, scales 1e-12
to 1e12, steps, flat clipped stretches, NaN runs, duplicated (held) samples, inputs without
excitation, a twin without noise levels or without any section, calibration on or off, any
training fraction.

Each one must exit 0 (a complete output folder) or 2 (one line on stderr, no output folder,
nothing left behind), never 3; no traceback and no Python warning may reach stderr, and the
peak memory of the whole run stays under :data:`PEAK_MB`. CI draws :data:`CI_EXAMPLES`
derandomized examples (`make test-fast` the first test's :data:`FAST_EXAMPLES`, the second
test, slow, the rest); `make fuzz` draws ``FUZZ_FACTOR`` (25) times as many with fresh
randomness (>= 500).
"""

from __future__ import annotations

import contextlib
import io
import json
import resource
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from dtwin.cli import main
from dtwin.gapbench.generator import ALL_CASE_EFFECTS, generate_case
from tests.conftest import n_examples, paper_twin

#: Derandomized deep examples per CI run (each takes about one second, a quarter of a CPU
#: second): :data:`FAST_EXAMPLES` of them in `make test-fast`, the rest with the slow tests.
CI_EXAMPLES = 24
#: The deep examples of `make test-fast` (the other ``CI_EXAMPLES - FAST_EXAMPLES`` are slow).
FAST_EXAMPLES = 8
#: Largest growth of resident memory during one deep input, MB (its peak minus the memory held
#: when it starts, so earlier tests in the process do not count). Measured 2026-11-23 under
#: `make fuzz` (600 deep inputs): 599 grew by less than 25 MB, one by 25-50 MB, and the whole
#: process peaked at 253 MB on a 162 MB baseline (CI's 26 inputs: under 50 MB, 247 MB). The
#: bound is three times the largest growth seen.
PEAK_GROWTH_MB = 150
#: Column sets that each contain one module or more (docs/gap.md §Modules), full set first.
COLUMN_SETS = (
    ("u_cmd", "u_act", "x", "v", "y_A", "y_B", "y_fused", "z"),
    ("u_cmd", "u_act", "x", "y_A", "y_B", "y_fused", "z"),
    ("u_act", "x"),
    ("u_cmd", "u_act"),
    ("x", "y_A", "y_B"),
    ("y_A", "y_B", "y_fused"),
    ("x", "z"),
    ("u_cmd", "u_act", "x"),
    ("x", "v", "z"),
)
#: Internal errors found by this fuzz and not yet fixed (each with a deterministic reproduction
#: as a strict xfail test); any other exit status 3 fails the fuzz.
KNOWN_INTERNAL_ERRORS: tuple[str, ...] = ()
DTS = (1e-6, 1e-3, 0.02, 1.0, 100.0)
FLAWS = ("spike", "constant", "zero", "step", "clip", "nan_run", "hold", "no_excitation")


def _flaw(draw, frame: pd.DataFrame, columns: list[str], rng: np.random.Generator) -> str:
    """Apply one hostile change to ``frame`` in place; return its description."""
    kind = draw(st.sampled_from(FLAWS))
    name = draw(st.sampled_from(columns))
    values = frame[name].to_numpy(dtype=float, copy=True)
    n = len(values)
    spread = float(np.ptp(values)) or 1.0
    row = draw(st.integers(0, n - 1))
    if kind == "spike":
        size = 10.0 ** draw(st.floats(3, 15))
        values[row] += draw(st.sampled_from([-1.0, 1.0])) * size * spread
    elif kind == "constant":
        values[:] = draw(st.sampled_from([1.0, -3.5, 1e6, 1e-9]))
    elif kind == "zero":
        values[:] = 0.0
    elif kind == "step":
        values[row:] += 10.0 ** draw(st.floats(-2, 3)) * spread
    elif kind == "clip":
        low, high = np.quantile(values, [0.3, 0.7])
        values = np.clip(values, low, high)
    elif kind == "nan_run":
        values[row : row + draw(st.integers(1, 20))] = np.nan
    elif kind == "hold":
        hold = draw(st.integers(2, 25))
        values = values[np.arange(n) // hold * hold]
    else:  # no excitation: the module inputs become a constant plus a whisper
        for source in (c for c in ("u_cmd", "u_act", "x") if c in columns):
            frame[source] = 0.3 + 1e-9 * rng.standard_normal(n)
        return f"{kind}"
    frame[name] = values
    return f"{kind} in {name} at row {row + 1}"


@st.composite
def hostile_cases(draw):
    """A recording that passes the early checks, its twin file and the CLI options."""
    effect = draw(st.sampled_from(ALL_CASE_EFFECTS))
    seed = draw(st.integers(0, 10_000))
    n_rows = draw(st.sampled_from([250, 400, 700]))
    case = generate_case(effect, seed, n_samples=n_rows, nominal=paper_twin())
    rng = np.random.default_rng(seed)
    columns = list(draw(st.sampled_from(COLUMN_SETS)))
    frame = case.recording[["t", *columns]].copy()
    dt = draw(st.sampled_from(DTS))
    frame["t"] = np.arange(n_rows) * dt
    scale = 10.0 ** draw(st.integers(-12, 12))
    frame[columns] *= scale
    flaws = [_flaw(draw, frame, columns, rng) for _ in range(draw(st.integers(0, 3)))]
    twin = dict(case.twin["twin"], dt=dt)
    variant = draw(st.sampled_from(["full", "no_noise", "dt_only"]))
    if variant == "no_noise":
        twin.pop("noise")
    elif variant == "dt_only":
        twin = {"dt": dt}
    options = []
    if draw(st.booleans()):
        options.append("--calibrate")
    options += ["--train-frac", str(draw(st.sampled_from([0.45, 0.5, 0.6])))]
    label = f"{effect} seed {seed}, {n_rows} rows, dt {dt}, scale {scale:g}, {variant}: {flaws}"
    return frame, {"twin": twin}, options, label


def run_quietly(args: list[str]) -> tuple[int, str, list[str]]:
    """Run the CLI in-process; return its exit status, stderr and every warning raised."""
    stderr = io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            code = main(args)
    raised = [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]
    return code, stderr.getvalue(), raised


def reset_peak_memory() -> None:
    """Start a new peak-memory measurement (Linux: write 5 to /proc/self/clear_refs)."""
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")


def memory_mb(field: str = "VmHWM") -> float:
    """Resident memory of this process, MB: ``VmHWM`` the peak since
    :func:`reset_peak_memory`, ``VmRSS`` now (without /proc: the lifetime peak, getrusage)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def spiked_case() -> tuple:
    """The issue's spike: 9.1e11 in x of a full generated case."""
    case = generate_case("none", 1, n_samples=260, nominal=paper_twin())
    frame = case.recording.copy()
    frame.loc[0, "x"] = 9.1e11
    return frame, case.twin, [], "spike 9.1e11 in x at row 1"


def dead_sensor_case() -> tuple:
    """An output that is zero throughout (it once read `none` with 8 overflow warnings)."""
    case = generate_case("none", 2, n_samples=260, nominal=paper_twin())
    frame = case.recording.drop(columns="v").copy()
    frame["y_B"] = 0.0
    return frame, case.twin, [], "y_B zero throughout"


DEEP_SETTINGS = {
    "deadline": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
}


@settings(max_examples=n_examples(FAST_EXAMPLES), **DEEP_SETTINGS)
@given(hostile_cases())
@example(spiked_case())
@example(dead_sensor_case())
def test_hostile_recordings_exit_cleanly_without_warnings(case):
    exits_cleanly_without_warnings(case)


@pytest.mark.slow
@settings(max_examples=n_examples(CI_EXAMPLES - FAST_EXAMPLES), **DEEP_SETTINGS)
@given(hostile_cases())
def test_more_hostile_recordings_exit_cleanly_without_warnings(case):
    """Other derandomized examples (Hypothesis seeds each test by its own code)."""
    exits_cleanly_without_warnings(case)


def exits_cleanly_without_warnings(case: tuple) -> None:
    """Run `dtwin diagnose` on a hostile case: exit 0 or 2, no traceback, warning or leftover."""
    frame, twin, options, label = case
    reset_peak_memory()
    start_mb = memory_mb("VmRSS")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        frame.to_csv(folder / "rec.csv", index=False, float_format="%.17g")
        (folder / "twin.yaml").write_text(yaml.safe_dump(twin))
        out = folder / "out"
        args = ["diagnose", str(folder / "rec.csv"), "--twin", str(folder / "twin.yaml")]
        code, message, raised = run_quietly([*args, "--out", str(out), *options])
        event(f"exit {code}")  # counts shown by `make fuzz` (--hypothesis-show-statistics)
        known = code == 3 and any(bug in message for bug in KNOWN_INTERNAL_ERRORS)
        assert code in (0, 2) or known, (label, message)
        assert "Traceback" not in message, label
        assert not raised, (label, raised)  # the CLI turns warnings into report notes
        assert "Warning" not in message, (label, message)
        left = {p.name for p in folder.iterdir()} - {"rec.csv", "twin.yaml"}
        assert left == ({"out"} if code == 0 else set()), label
        if code in (2, 3):
            assert message.count("\n") == 1 and message.startswith("dtwin diagnose: ")
        else:
            assert message == "", (label, message)
            result = json.loads((out / "diagnosis.json").read_text())
            assert result["recording"]["n_samples"] == len(frame)
            assert {"report.md", "gap.png"} <= {p.name for p in out.iterdir()}
            noted = [n for n in result["notes"] if n.startswith("warning while diagnosing")]
            assert all(n in (out / "report.md").read_text() for n in noted), label
            for note in noted:
                event(note.partition("): ")[2])
    growth = max(memory_mb() - start_mb, 0.0)
    event(f"peak memory growth {25 * (growth // 25):.0f}-{25 * (growth // 25 + 1):.0f} MB")
    assert growth < PEAK_GROWTH_MB, (label, f"{growth:.0f} MB")


def test_a_flagged_calibrated_kpi_module_is_diagnosed(tmp_path):
    """x, z of a clean case with x offset by 0.5 and --calibrate: M4 is flagged, no candidate.

    Found by this fuzz (exit 3: the best of no candidate); a located gap no candidate can
    explain is ``unexplained``.
    """
    case = generate_case("none", 1, n_samples=250, nominal=paper_twin())
    frame = case.recording[["t", "x", "z"]].copy()
    frame["x"] += 0.5
    frame.to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "twin.yaml").write_text(yaml.safe_dump(case.twin))
    args = ["diagnose", str(tmp_path / "rec.csv"), "--twin", str(tmp_path / "twin.yaml")]
    code, message, _ = run_quietly([*args, "--out", str(tmp_path / "out"), "--calibrate"])
    assert code in (0, 2), message
