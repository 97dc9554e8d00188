"""A plant in a feedback loop: detected, fitted with causal holds (docs/gap.md §Closed loop)."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
from dtwin.gap.closed_loop import FEEDBACK_THRESHOLD, feedback_statistic, loop_statistic
from dtwin.gapbench.generator import generate_case
from dtwin.gapbench.rigs import generate_rig_case


def _integrator_records(closed: bool, seed: int = 4, n: int = 4000) -> tuple[np.ndarray, ...]:
    """A double integrator with damping (zero-order hold) driven by a PD loop or open loop."""
    rng = np.random.default_rng(seed)
    dt, m, c = 1e-3, 2.0, 40.0
    reference = np.convolve(rng.standard_normal(n), np.ones(200) / 200, mode="same")
    open_drive = 50.0 * np.convolve(rng.standard_normal(n), np.ones(20) / 20, mode="same")
    noise = 0.002 * rng.standard_normal(n)
    x, v = 0.0, 0.0
    u, y = np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = x + noise[k]
        previous = y[k - 1] if k else y[k]
        u[k] = 4e4 * (reference[k] - y[k]) - 300.0 * (y[k] - previous) / dt
        u[k] = u[k] if closed else open_drive[k]
        x, v = x + dt * v, v + dt * (u[k] - c * v) / m
    return u, y


def test_the_statistic_tells_a_pd_loop_from_the_same_plant_in_open_loop():
    u, y = _integrator_records(closed=True)
    assert feedback_statistic(u, y, 7) >= FEEDBACK_THRESHOLD
    u, y = _integrator_records(closed=False)
    assert feedback_statistic(u, y, 7) < FEEDBACK_THRESHOLD


def test_the_paper_asset_and_an_open_loop_rig_are_not_read_as_loops():
    paper = generate_case("none", 5000).recording
    assert loop_statistic(paper["u_act"].to_numpy(), paper["x"].to_numpy()) < FEEDBACK_THRESHOLD
    rig = generate_rig_case("none", 15006)  # 60 samples per period, open loop
    assert not rig.key["closed_loop"]
    record = rig.recording.iloc[: len(rig.recording) // 2]
    assert loop_statistic(record["u_act"].to_numpy(), record["x"].to_numpy()) < FEEDBACK_THRESHOLD


def _diagnose(case):
    recording = recording_from_frame(case.recording)
    return diagnose(recording, twin_from_mapping(case.twin, dt=recording.dt), calibrate=True)


@pytest.mark.slow
def test_an_integrating_plant_in_a_pd_loop_is_calibrated_consistently():
    """Rig 15005: k = 0, m and c known (recording units); the loop's output is the input."""
    case = generate_rig_case("none", 15005)
    assert case.key["integrating"] and case.key["closed_loop"]
    result = _diagnose(case)
    plant, true = result.modules["M1"], case.key["plant"]
    assert any("feedback loop" in note for note in result.notes)
    assert plant.discretisation in ("euler", "zoh")
    assert plant.lin_used["m"] == pytest.approx(true["m"], rel=0.02)
    assert plant.lin_used["c"] == pytest.approx(true["c"], rel=0.02)
    # no spring: its mode would lie far below the damping's (ζ = c/(2·√(k·m)) > 5)
    assert plant.lin_used["k"] * plant.lin_used["m"] <= (plant.lin_used["c"] / 10) ** 2
    assert result.effect == "none"


@pytest.mark.slow
def test_a_coulomb_rig_in_a_pd_loop_reads_its_friction_through_a_causal_hold():
    """Rig 16003: before, the first-order hold won the training part and Fc read 3.1 % high."""
    case = generate_rig_case("coulomb_friction", 16003)
    assert case.key["closed_loop"]
    result = _diagnose(case)
    assert result.modules["M1"].discretisation == "zoh"
    assert (result.module, result.effect) == ("M1", "coulomb_friction")
    assert result.params["Fc"] == pytest.approx(case.key["params"]["Fc"], rel=0.02)
