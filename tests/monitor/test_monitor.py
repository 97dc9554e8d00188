"""dtwin regimes and dtwin monitor on a user's twin (docs/monitor.md).

A valve feeding a Torricelli tank whose level is recorded (a state reset from the recording at
every window) and whose flow is not (a state fitted over the settling period), simulated with
scipy's solve_ivp. Checked: the monitor replaying a recording gives ``dtwin regimes``' filtered
posteriors and correction to 1e-10 whatever the chunks; an effect switched on halfway (seen in
the fitted recording, or never seen: the ``unknown`` regime) leaves nominal within 200 samples
and a clean recording raises no event; hostile rows are events and counted; a model file of
another twin is refused with one line and exit status 2.
"""

from __future__ import annotations

import io
import json
from functools import cache

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from dtwin.artifacts import to_jsonable
from dtwin.cli import main
from dtwin.gap.recording import recording_with_columns
from dtwin.monitor.batch_regimes import regimes_of
from dtwin.monitor.live import Monitor, MonitorSettings
from dtwin.monitor.model_file import monitor_model_from_mapping, regimes_file_mapping
from dtwin.monitor.regime_model import RegimeSettings
from dtwin.monitor.row_stream import LineSource
from dtwin.twin.table import table_from_mapping

DT = 0.1
N = 3000
SWITCH = N // 2
TWIN = {
    "dt": DT,
    "modules": {
        "valve": {
            "block": "lag",
            "inputs": ["u"],
            "outputs": ["q"],
            "params": {"tau": 0.5, "gain": 1.0},
        },
        "tank": {
            "inputs": ["q"],
            "outputs": ["level"],
            "states": ["level"],
            "params": {"a": 0.8},
            "derivatives": {"level": "q - a*sqrt(max(level, 0))"},
        },
    },
    "noise": {"level": 0.01},
}


@cache
def _asset(seed: int, effect: str | None = None, n: int = N) -> pd.DataFrame:
    """The valve and tank; ``effect`` (``bias``: the level sensor reads 0.08 high; ``faint``:
    0.01 high, the noise's sd; ``leak``: the outflow coefficient 25 % larger) from sample
    ``SWITCH`` on."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.4, 1.4, n // 40 + 1), 40)[:n]
    leak = 1.25 if effect == "leak" else 1.0

    def rhs(t, s):
        k = min(int(round(t / DT, 9)), n - 1)
        q, h = s
        a = 0.8 * (leak if k >= SWITCH else 1.0)
        return [(u[k] - q) / 0.5, q - a * np.sqrt(max(h, 0.0))]

    times = np.arange(n) * DT
    sol = solve_ivp(rhs, (0, times[-1]), [0.8, 1.0], t_eval=times, max_step=DT, rtol=1e-7)
    level = sol.y[1] + 0.01 * rng.standard_normal(n)
    if effect == "bias":
        level[SWITCH:] += 0.08
    if effect == "faint":  # one noise standard deviation
        level[SWITCH:] += 0.01
    return pd.DataFrame({"t": times, "u": u, "level": level})


#: A short BIC sweep (K ≤ 4, 3 starts each) keeps the tests fast.
SETTINGS = RegimeSettings(k_max=4, n_restarts=3)


def _regimes(frame: pd.DataFrame, **kwargs):
    table = table_from_mapping(TWIN)
    recording = recording_with_columns(frame, (*table.signals, *table.exogenous))
    return table, regimes_of(recording, table, settings=SETTINGS, **kwargs)


def _lines(frame: pd.DataFrame) -> list[str]:
    return frame.to_csv(index=False, float_format="%.17g").splitlines()


def _monitor(result, table, lines, chunks=None, **settings):
    """Run the monitor in-process over ``lines`` in the given chunk sizes; return parsed output."""
    raw = json.loads(json.dumps(to_jsonable(regimes_file_mapping(result))))
    model = monitor_model_from_mapping(raw, table)
    out, err = io.StringIO(), io.StringIO()
    monitor = Monitor(model, table, MonitorSettings(**settings), out, err)
    out.write(json.dumps(monitor.start_line()) + "\n")
    first = 0
    for size in chunks or [len(lines)]:
        monitor.feed(lines[first : first + size])
        first += size
    monitor.feed(lines[first:])
    summary = monitor.summary("end_of_input", 0.0)
    return [json.loads(x) for x in out.getvalue().splitlines()], err.getvalue(), summary


@pytest.fixture(scope="module")
def seen():
    """Regimes fitted on a recording whose level sensor reads high from halfway."""
    frame = _asset(1, "bias")
    table, result = _regimes(frame)
    return frame, table, result


@pytest.fixture(scope="module")
def clean():
    """Regimes fitted on a clean recording (nominal regimes only)."""
    frame = _asset(2)
    table, result = _regimes(frame)
    return frame, table, result


def test_the_regimes_of_a_recording_with_a_switch(seen):
    _, _, result = seen
    model = result.regime_fit.model
    assert model.n_states >= 2 and not all(model.nominal)
    s = result.settling
    regimes = np.array(model.labels)[result.tracked.regime]
    nominal = set(np.array(model.labels)[:-1][np.array(model.nominal)])
    assert np.mean([r in nominal for r in regimes[: SWITCH - s]]) > 0.99
    # a window restarts the level from the biased reading: a few samples after it look nominal
    assert np.mean([r not in nominal for r in regimes[SWITCH - s + 50 :]]) > 0.9


def test_replay_equals_batch(seen):
    """Filtered posteriors and correction of a replay in random chunks equal the batch's.

    The chunks include 600 single lines (a live stream's pace, across window cuts).
    """
    frame, table, result = seen
    rng = np.random.default_rng(0)
    lines = _lines(frame)
    chunks = [*rng.integers(1, 400, size=20).tolist(), *[1] * 600,
              *rng.integers(1, 400, size=20).tolist()]  # fmt: skip
    output, _, summary = _monitor(result, table, lines, chunks)
    samples = [row for row in output if "p" in row]
    assert summary["rows_used"] == N and len(samples) == N - result.settling
    posteriors = np.array([row["p"] for row in samples])
    corrected = np.array([row["corrected"] for row in samples])
    np.testing.assert_allclose(posteriors, result.tracked.posteriors, rtol=0, atol=1e-10)
    np.testing.assert_allclose(corrected, result.tracked.corrected, rtol=0, atol=1e-10)
    assert output[0]["settling"]["samples"] == result.settling
    assert all(row.get("settling") for row in output[1 : result.settling + 1])


def test_a_seen_effect_leaves_nominal_within_200_samples_and_a_clean_stream_stays(seen):
    _, table, result = seen
    output, _, _ = _monitor(result, table, _lines(_asset(11, "bias")))
    left = [row for row in output if row.get("event") == "left_nominal"]
    assert left and 0 <= left[0]["since"] / DT - SWITCH <= 200
    assert left[0]["regime"] != "unknown"
    output, _, summary = _monitor(result, table, _lines(_asset(12)))
    assert summary["left_nominal"] == 0


def test_an_unseen_effect_moves_to_the_unknown_regime(clean):
    _, table, result = clean
    assert all(result.regime_fit.model.nominal)
    output, _, _ = _monitor(result, table, _lines(_asset(13, "leak")))
    left = [row for row in output if row.get("event") == "left_nominal"]
    assert left and left[0]["regime"] == "unknown"
    assert 0 <= left[0]["since"] / DT - SWITCH <= 200
    _, _, summary = _monitor(result, table, _lines(_asset(14)))
    assert summary["left_nominal"] == 0
    assert result.false_alarms["simulated_unknown"]["events"] == 0


def test_a_faint_unseen_change_is_found_by_the_novelty_test_alone(clean):
    """A level bias of one noise sd: no sample is outside what the fitted regime explains, so
    the regime filter stays nominal; the CUSUMs on the innovations leave nominal."""
    _, table, result = clean
    test = result.regime_fit.model.novelty
    assert test.order == (0,) and test.threshold == pytest.approx(np.log(3e6))
    bound = result.false_alarms["novelty_bound"]
    assert bound["per_hour"] == pytest.approx(3600.0 / (1e6 * DT))
    output, _, _ = _monitor(result, table, _lines(_asset(17, "faint")))
    rows = [row for row in output if "p" in row]
    left = [row for row in output if row.get("event") == "left_nominal"]
    assert left and left[0]["regime"] == "unknown"
    assert 0 <= left[0]["t"] / DT - SWITCH <= 200
    fired = next(i for i, row in enumerate(rows) if row["t"] == left[0]["t"])
    assert rows[fired]["novelty"] >= 1 and rows[fired]["p"][0] > 0.5  # the filter: nominal
    assert max(row["novelty"] for row in rows if row["t"] / DT < SWITCH) < 1


def test_a_monitor_attached_mid_run_settles_first_and_raises_no_event(clean):
    """Started at sample 1000 of a running asset (its flow unknown): the first line declares
    the settling period, whose samples carry no posterior, and no event comes in or after it."""
    _, table, result = clean
    lines = _lines(_asset(16))
    output, _, summary = _monitor(result, table, [lines[0], *lines[1001:]])
    settling = output[0]["settling"]["samples"]
    assert settling == result.settling > 1
    assert all(row == {"t": row["t"], "settling": True} for row in output[1 : settling + 1])
    assert "p" in output[settling + 1] and summary["left_nominal"] == 0


def test_hostile_rows_are_events_and_counted(clean):
    frame, table, result = clean
    lines = _lines(frame.iloc[:800])
    hostile = list(lines)
    hostile[400] = "not,a,row,at,all"  # malformed
    hostile[401] = hostile[401].split(",")[0] + ",nan," + hostile[401].split(",")[2]
    hostile[402] = hostile[390]  # backward time (an old row again)
    hostile[403] = hostile[403].split(",")[0] + ",abc," + hostile[403].split(",")[2]
    hostile[404] = ""
    hostile[405] = hostile[405].split(",")[0] + ",1e6," + hostile[405].split(",")[2]  # far out
    hostile.insert(500, hostile[499])  # duplicate time
    hostile.insert(600, "t,level")  # a header without u: its rows are refused
    hostile.insert(603, "t,u,level")  # u is back
    jump = [f"{float(x.split(',')[0]) + 100.0!r},{x.split(',', 1)[1]}" for x in lines[700:]]
    hostile = hostile[:700] + jump  # a jump in time: a restart
    output, err, summary = _monitor(result, table, hostile, chunks=[450, 1, 200])
    events = [json.loads(x) for x in err.splitlines()]
    kinds = {e["event"] for e in events}
    assert {"malformed", "missing_value", "backward_time", "non_numeric", "empty", "out_of_range",
            "duplicate_time", "missing_column", "header", "time_jump"} <= kinds  # fmt: skip
    assert summary["refused"] == {"malformed": 1, "missing_value": 1, "non_numeric": 1,
                                  "backward_time": 1, "empty": 1, "duplicate_time": 1,
                                  "missing_column": 2, "out_of_range": 1}  # fmt: skip
    assert summary["rows_read"] == summary["rows_used"] + summary["rows_refused"]
    assert summary["restarts"] == 1 and summary["left_nominal"] == 0
    assert output[-1]["t"] == pytest.approx(float(jump[-1].split(",")[0]))
    missing = next(e for e in events if e["event"] == "missing_value")
    assert missing["row"] == 402 and missing["detail"] == "u"  # line 402: hostile[401]


def test_a_short_gap_is_bridged_and_the_stream_goes_on(clean):
    frame, table, result = clean
    lines = _lines(frame.iloc[:900])
    gapped = lines[:500] + lines[503:]
    output, err, summary = _monitor(result, table, gapped)
    assert summary["missing_samples"] == 3 and summary["restarts"] == 0
    assert '"time_gap"' in err
    assert len([row for row in output if "t" in row]) == 897


def test_cli_regimes_then_monitor_and_a_foreign_model_is_refused(tmp_path, monkeypatch, capsys):
    frame = _asset(3, "bias")
    frame.to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "twin.yaml").write_text(yaml.safe_dump(TWIN))
    assert main(["regimes", str(tmp_path / "rec.csv"), "--twin", str(tmp_path / "twin.yaml"),
                 "--out", str(tmp_path / "out"), "--k", "2"]) == 0  # fmt: skip
    names = {p.name for p in (tmp_path / "out").iterdir()}
    assert names == {"regimes.json", "posteriors.csv", "corrected.csv", "report.md", "regimes.png"}
    capsys.readouterr()
    monkeypatch.setattr("sys.stdin", io.StringIO((tmp_path / "rec.csv").read_text()))
    regimes = str(tmp_path / "out" / "regimes.json")
    assert main(["monitor", "--twin", str(tmp_path / "twin.yaml"), "--no-diagnose",
                 "--regimes", regimes, "--every", "10"]) == 0  # fmt: skip
    out = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert out[0]["event"] == "start" and out[-1]["event"] == "summary"
    posteriors = pd.read_csv(tmp_path / "out" / "posteriors.csv")
    lines = [row for row in out if "p" in row]
    assert abs(len(lines) - (posteriors["settling"] == 0).sum() / 10) <= 1  # one line per 10
    columns = [c for c in posteriors.columns if c.startswith("filtered_")]
    first = posteriors.index[posteriors["settling"] == 0][0]
    for row in lines[:20]:
        at = first + round((row["t"] - posteriors["t"][first]) / DT)
        np.testing.assert_allclose(row["p"], posteriors.loc[at, columns], atol=1e-10)
    other = dict(TWIN, modules={**TWIN["modules"], "tank": {**TWIN["modules"]["tank"],
                 "derivatives": {"level": "q - a*max(level, 0)"}}})  # fmt: skip
    (tmp_path / "other.yaml").write_text(yaml.safe_dump(other))
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    assert main(["monitor", "--twin", str(tmp_path / "other.yaml"), "--no-diagnose",
                 "--regimes", regimes]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not match the twin" in err[0]


def test_a_regimes_file_fitted_under_one_stepping_rule_does_not_match_another():
    """A unit's digest says how its states step once a module is discrete (euler or zoh)."""
    from dtwin.monitor.causal_twin import _fingerprint
    from dtwin.twin.simulate import units_of

    def digest(twin):
        (unit,) = [u for u in units_of(table_from_mapping(twin), ["u", "q", "level"])
                   if u.modules == ("tank",)]  # fmt: skip
        return _fingerprint(unit)

    tank = TWIN["modules"]["tank"]
    stepped = {m: dict(TWIN, modules={**TWIN["modules"], "tank": {**tank, "discretisation": m}})
               for m in ("euler", "zoh", "continuous")}  # fmt: skip
    digests = {m: digest(twin) for m, twin in stepped.items()}
    assert len({digests["euler"], digests["zoh"], digest(TWIN)}) == 3
    assert digests["continuous"] == digest(TWIN)  # the default: as before it could say so


def test_a_followed_file_is_read_across_a_rotation(tmp_path):
    path = tmp_path / "live.csv"
    path.write_text("t,u,level\n0,1,2\n0.1,1,2\n")
    source = LineSource(follow=path, poll=0.01)
    pieces = source.pieces()
    read = []
    while len(read) < 3:
        read += next(pieces)
    path.rename(tmp_path / "live.csv.1")
    path.write_text("t,u,level\n0.2,1,2\n")
    while len(read) < 5:
        read += next(pieces)
    assert read == ["t,u,level", "0,1,2", "0.1,1,2", "t,u,level", "0.2,1,2"]
    assert source.rotations == 1


def test_on_the_paper_asset_with_its_faults_the_monitor_scores_as_the_batch(config):
    """The paper's six modules as a table, its asset with the fault schedule in the recording:
    the monitor's regime accuracy (Hungarian) equals dtwin regimes' (K = 4)."""
    from dtwin.fault_injection import FaultMagnitudes, fault_schedule, inject_faults, regime_labels
    from dtwin.params import twin_params_from_mapping
    from dtwin.regime_matching import hungarian_map
    from dtwin.stages.twin import simulate_asset
    from dtwin.twin.paper_chain import paper_table

    twin = twin_params_from_mapping(config["twin"])
    schedule = fault_schedule(config["faults"]["schedule"])
    physics = simulate_asset(config["simulation"], config["command"], config["twin"])
    faulted = inject_faults(
        physics, np.random.default_rng(config["faults"]["seed"]), alpha=twin.fusion.alpha,
        w1=twin.kpi.w1, w2=twin.kpi.w2, dt=twin.dt, schedule=schedule,
        magnitudes=FaultMagnitudes.from_mapping(config["faults"]),
    ).drop(columns="regime")  # fmt: skip
    table = paper_table(twin)
    recording = recording_with_columns(faulted, (*table.signals, *table.exogenous))
    result = regimes_of(recording, table, nominal=(0.0, 4.98), settings=RegimeSettings(4))
    labels = regime_labels(recording.t[result.settling :], schedule)
    output, _, _ = _monitor(result, table, _lines(faulted), chunks=[7, 300, 41])
    names = output[0]["regimes"]  # the monitor's regime: unknown while the novelty test alarms
    live = np.array([names.index(row["regime"]) for row in output if "p" in row])
    batch = hungarian_map(result.tracked.regime, labels)
    replay = hungarian_map(live, labels)
    assert np.mean(replay.predicted == labels) == np.mean(batch.predicted == labels) > 0.5


@pytest.mark.slow
def test_the_cli_diagnoses_a_change_in_the_background_and_waits_for_it(tmp_path, clean):
    """A stream whose level leaks from halfway: the change is an event, a background dtwin
    diagnose runs on the samples since it, and its answer comes before the summary at EOF."""
    import subprocess
    import sys

    _, _, result = clean
    from dtwin.artifacts import write_json

    write_json(regimes_file_mapping(result), tmp_path / "regimes.json")
    (tmp_path / "twin.yaml").write_text(yaml.safe_dump(TWIN))
    stream = "\n".join(_lines(_asset(15, "leak"))) + "\n"
    done = subprocess.run(
        [sys.executable, "-m", "dtwin", "monitor", "--twin", str(tmp_path / "twin.yaml"),
         "--regimes", str(tmp_path / "regimes.json"), "--every", "100",
         "--diagnose-samples", "600", "--diagnoses", str(tmp_path / "kept")],
        input=stream, capture_output=True, text=True, check=True,
    )  # fmt: skip
    events = [json.loads(x) for x in done.stdout.splitlines() if '"event"' in x]
    kinds = [e["event"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "summary"
    assert kinds.index("left_nominal") < kinds.index("diagnosis") < kinds.index("summary")
    diagnosis = events[kinds.index("diagnosis")]
    assert diagnosis["samples"] == 600 and "effect" in diagnosis
    assert events[-1]["diagnoses"] == {"started": 1, "written": 1, "failed": 0, "cancelled": 0}
    assert (tmp_path / "kept" / "diagnosis_1" / "window.csv").exists()


@pytest.mark.slow
def test_an_interrupted_follow_writes_its_summary(tmp_path, clean):
    """dtwin monitor --follow on a file that is appended and rotated, ended by SIGINT."""
    import signal
    import subprocess
    import sys
    import time

    _, _, result = clean
    from dtwin.artifacts import write_json

    write_json(regimes_file_mapping(result), tmp_path / "regimes.json")
    (tmp_path / "twin.yaml").write_text(yaml.safe_dump(TWIN))
    lines = _lines(_asset(16))
    live = tmp_path / "live.csv"
    live.write_text("\n".join(lines[:1000]) + "\n")
    out = tmp_path / "out.jsonl"

    def wait_for(n_lines: int) -> None:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            if out.exists() and out.read_text().count("\n") >= n_lines:
                return
            time.sleep(0.1)
        raise AssertionError(f"the monitor did not write {n_lines} lines in 180 s")

    with open(out, "w") as handle:
        process = subprocess.Popen(
            [sys.executable, "-m", "dtwin", "monitor", "--twin", str(tmp_path / "twin.yaml"),
             "--regimes", str(tmp_path / "regimes.json"), "--follow", str(live),
             "--no-diagnose"], stdout=handle, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        wait_for(1000)  # the start line and 999 samples
        live.rename(tmp_path / "live.csv.1")
        live.write_text("\n".join([lines[0], *lines[1000:1500]]) + "\n")
        wait_for(1500)
        process.send_signal(signal.SIGINT)
        process.wait(timeout=120)
    summary = json.loads(out.read_text().splitlines()[-1])
    assert summary["event"] == "summary" and summary["ended"] == "interrupted"
    assert summary["rows_used"] == 1499 and summary["rotations"] == 1
    assert summary["headers"] == 2 and summary["rows_refused"] == 0


def test_the_compiled_filter_is_the_forward_recursion_of_the_dag():
    """Without the unknown state, filter_rows gives dtwin.hmm.filtered_posteriors' numbers."""
    from dtwin.hmm import filtered_posteriors, fit_hmm
    from dtwin.monitor._stream_kernels import filter_rows

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.normal(-1, 1, (300, 2)), rng.normal(1.5, 0.7, (300, 2))])
    fit = fit_hmm(x, 2, n_restarts=2, seed=0)
    variances = fit.sds**2
    arrays = (fit.means, 1 / variances, -0.5 * np.log(2 * np.pi * variances).sum(axis=1))
    ours = filter_rows(x, *arrays, fit.transmat, fit.startprob.copy(), True)
    np.testing.assert_allclose(ours, filtered_posteriors(fit, x), rtol=0, atol=1e-10)
    alpha = fit.startprob.copy()
    first = filter_rows(x[:250], *arrays, fit.transmat, alpha, True)
    rest = filter_rows(x[250:], *arrays, fit.transmat, alpha, False)
    np.testing.assert_array_equal(np.vstack([first, rest]), ours)


def test_a_long_recording_is_fitted_from_starts_on_a_sample_of_its_rows():
    """Beyond MAX_SWEEP_SAMPLES rows the starts run on the sweep's rows, the best on every row.

    Its optimum on every row is as good as the best of the same starts run on every row, and
    it finds the two levels the residuals switch between.
    """
    from dtwin.hmm import fit_hmm, zscore
    from dtwin.monitor.regime_model import MAX_SWEEP_SAMPLES, REGIME_EM, fit_regime_model

    rng = np.random.default_rng(5)
    n = MAX_SWEEP_SAMPLES + 5000
    state = (np.cumsum(rng.random(n) < 0.01) % 2).astype(bool)  # ~100-sample dwells
    levels = np.where(state[:, None], [1.5, -0.5], [-1.0, 0.5])
    residuals = pd.DataFrame(levels + 0.4 * rng.standard_normal((n, 2)), columns=["a:y", "b:y"])
    settings = RegimeSettings(n_states=2)
    fitted = fit_regime_model(residuals, np.ones(n, dtype=bool), settings).fit
    every_row = fit_hmm(zscore(residuals).values, 2, seed=[settings.seed, 2],
                        n_restarts=settings.n_restarts, **REGIME_EM.options())  # fmt: skip
    assert len(fitted.restarts) == 1 and fitted.converged
    assert fitted.log_likelihood >= every_row.log_likelihood - 1e-6 * abs(every_row.log_likelihood)
    scaled = zscore(residuals)
    means = fitted.means * np.asarray(scaled.sd) + np.asarray(scaled.mean)
    np.testing.assert_allclose(means[np.argsort(means[:, 0])], [[-1.0, 0.5], [1.5, -0.5]],
                               atol=0.02)  # fmt: skip
