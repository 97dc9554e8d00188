"""The harder rig family, Stribeck friction and the closed-loop calibration start."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dtwin._validation import DtwinValueError
from dtwin.gap.effects import ARRAY_OPS, SCALAR_OPS, effect_by_name
from dtwin.gapbench.generator import accepted_effects, generate_case
from dtwin.gapbench.rigs import (
    HARD_RIG_EFFECTS,
    RIG_FORCES,
    generate_any_case,
    generate_hard_rig_case,
)
from tests.conftest import paper_twin


def test_stribeck_friction_is_coulomb_without_a_bump_and_breaks_away_at_rest():
    stribeck = effect_by_name("stribeck_friction").force_law
    coulomb = effect_by_name("coulomb_friction").force_law
    v = np.linspace(-3.0, 3.0, 61)
    flat = stribeck((0.4, 0.4, 0.2), 1.0, ARRAY_OPS)(0.0, v)
    assert np.allclose(flat, coulomb((0.4,), 1.0, ARRAY_OPS)(0.0, v), rtol=1e-12)
    bump = stribeck((0.4, 1.0, 0.2), 1.0, ARRAY_OPS)
    assert bump(0.0, 0.05) == pytest.approx(
        1.0 * math.exp(-(0.25**2)) + 0.4 * (1 - math.exp(-(0.25**2))), rel=1e-3
    )
    assert bump(0.0, 3.0) == pytest.approx(0.4, rel=1e-6) and bump(0.0, -3.0) == pytest.approx(
        -0.4, rel=1e-6
    )
    scalar = stribeck((0.4, 1.0, 0.2), 1.0, SCALAR_OPS)
    assert [scalar(0.0, float(x)) for x in v] == pytest.approx(bump(0.0, v).tolist(), rel=1e-12)


def test_a_breakaway_friction_is_right_under_either_friction_name():
    assert accepted_effects("coulomb_friction", {"Fc": 1.0, "Fs": 1.5}) == [
        "coulomb_friction",
        "stribeck_friction",
    ]
    assert accepted_effects("coulomb_friction", {"Fc": 1.0, "Fs": 1.0}) == ["coulomb_friction"]
    assert accepted_effects("cubic_stiffness", {}) == ["cubic_stiffness"]
    key = generate_case(
        "unseen__stiction", 3, n_samples=1200, magnitude=0.7, nominal=paper_twin()
    ).key
    assert key["expected_effect"] == "stribeck_friction"
    assert "coulomb_friction" in key["accepted_effects"]


@pytest.mark.parametrize("seed", range(6))
def test_the_harder_rig_family_draws_its_conditions(seed):
    effect = HARD_RIG_EFFECTS[seed % len(HARD_RIG_EFFECTS)]
    case = generate_hard_rig_case(effect, seed)
    key = case.key
    assert key["arm"] == "hard" and key["family"] == "rig"
    assert 3000 <= key["n_samples"] == len(case.recording) <= 20000
    assert 0.01 <= key["zeta"] <= 0.3 and 0.5 <= key["noise_pole"] <= 0.95
    assert 1e-3 <= key["u_scale"] <= 1e3 and 1e-3 <= key["x_scale"] <= 1e3
    assert key["closed_loop"] or not key["integrating"]
    assert list(case.recording.columns) == ["t", "u_act", "x"]
    assert case.twin == {"twin": {"dt": key["dt"]}}


def test_the_harder_family_holds_its_force_and_colours_its_noise():
    from dtwin.gapbench.rigs import _draw_hard_rig, _Drive, _measurement_noise

    rng = np.random.default_rng(4)
    rig = _draw_hard_rig(rng, "none", 40.0)
    rig["closed_loop"] = False
    drive = _Drive(rig, np.random.default_rng(1), 500)
    # the Runge-Kutta loop holds drive.held[j] over sample j's sub-steps
    assert drive.continuous is None and np.array_equal(drive.held, drive.recorded(500))
    assert drive.recorded(500)[8] != drive.recorded(500)[7]
    rig["noise_pole"] = 0.9
    _, shape = _measurement_noise(rig, np.random.default_rng(2), 50_000)
    assert np.corrcoef(shape[1:], shape[:-1])[0, 1] == pytest.approx(0.9, abs=0.02)
    assert np.std(shape) == pytest.approx(1.0, rel=0.05)


def test_the_continuous_multisine_is_the_scalar_signal_at_every_runge_kutta_instant(monkeypatch):
    from dtwin.gapbench import rigs

    rng = np.random.default_rng(5)
    rig = rigs._draw_rig(rng, "none", 37.0)
    rig["closed_loop"] = False
    n = 300
    drive = rigs._Drive(rig, np.random.default_rng(8), n)
    dt, h = rig["dt"], rig["dt"] / 10
    for j in (0, 1, 151, n - 1):
        for s, (f0, f_half, f1) in enumerate(drive.continuous[j].tolist()):
            t = j * dt + s * h
            # the instants and sums a point-at-a-time evaluation rounds: equal to the last bit
            assert [f0, f_half, f1] == [float(drive.excite(u)) for u in (t, t + h / 2, t + h)]
    assert np.array_equal(drive.recorded(n), [float(drive.excite(j * dt)) for j in range(n)])
    monkeypatch.setattr(rigs, "_CHUNK", 7)  # chunks of instants do not change a value
    chunked = rigs._Drive(rig, np.random.default_rng(8), n)
    assert np.array_equal(chunked.continuous, drive.continuous)


def test_a_rig_recording_does_not_depend_on_the_chunks_of_its_signal(monkeypatch):
    from dtwin.gapbench import rigs

    first = rigs.generate_rig_case("cubic_stiffness", 2, n_samples=500)
    monkeypatch.setattr(rigs, "_CHUNK", 64)
    again = rigs.generate_rig_case("cubic_stiffness", 2, n_samples=500)
    assert not first.key["closed_loop"]
    assert first.recording.equals(again.recording) and first.key == again.key


def test_unknown_hard_rig_effects_are_refused_and_the_prefix_dispatches():
    with pytest.raises(DtwinValueError, match="hard rig effect must be one of"):
        generate_hard_rig_case("backlash", 1)
    assert generate_any_case("hardrig_stribeck_friction", 2).key["effect"] == "stribeck_friction"


def test_cogging_is_a_near_catalogue_plant_force_periodic_in_the_position():
    from dtwin.gapbench.arms import ARM_CASE_EFFECTS, NEAR_CATALOGUE
    from dtwin.twin._force_kernels import ForceLaw, law_function

    assert "cogging" in NEAR_CATALOGUE and "stiction" not in NEAR_CATALOGUE
    spec = {"effect": "cogging", "A": 2.0, "period": 0.5, "phase": 0.3}
    force = law_function(ForceLaw(*ARM_CASE_EFFECTS["cogging"].force(spec, 0.4, 1.0)))
    assert force(0.1, 0.0) == pytest.approx(force(0.6, 5.0))
    assert force(0.1, 0.0) == pytest.approx(2.0 * math.sin(2 * math.pi * 0.1 / 0.5 + 0.3))


@pytest.mark.parametrize("pole", [0.0, 0.5, 0.8])
def test_the_spectral_floor_reads_coloured_noise_from_the_band_above_the_plant(pole):
    """AR(1) noise of unit variance under a plant at 0.5 Hz (Nyquist 500 Hz): level and memory.

    Read as white (the former floor), the noise at pole 0.8 was 0.33 of its true level.
    """
    from scipy.signal import lfilter

    from dtwin.gap.noise import spectral_noise_floor

    white = np.random.default_rng(0).standard_normal(6000)
    noise = lfilter([math.sqrt(1 - pole**2)], [1.0, -pole], white)
    floor = spectral_noise_floor(noise, 0.001, 0.5)
    assert floor.rms == pytest.approx(1.0, rel=0.05)
    memory = floor.acf[1] if len(floor.acf) > 1 else 0.0
    assert memory == pytest.approx(pole, abs=0.05)


def test_a_window_gain_counts_a_noise_pole_but_not_one_at_the_grid_top():
    """An AR(1) noise (pole 0.7) keeps its colour in the window gain; a residual of sign changes
    (a friction force's square wave, as on the EMPS axis) fits the top of the pole grid, which is
    no estimate, and counts as white: with its colour EMPS's floor rose to 0.034 above its gap
    0.028 and the measured Coulomb friction read ``none``."""
    from scipy.signal import lfilter

    from dtwin.gap.noise import NOISE_POLES, spectral_noise_floor, window_gain_pole

    white = np.random.default_rng(2).standard_normal(6000)
    coloured = lfilter([math.sqrt(1 - 0.7**2)], [1.0, -0.7], white)
    assert window_gain_pole(spectral_noise_floor(coloured, 0.001, 0.5)) == pytest.approx(
        0.7, abs=0.05
    )
    time = np.arange(6000) * 0.001
    square = np.sign(np.sin(2 * math.pi * 0.7 * time)) + 0.001 * white
    floor = spectral_noise_floor(square, 0.001, 0.5)
    assert floor.acf[1] == pytest.approx(NOISE_POLES[-1])
    assert window_gain_pole(floor) == 0.0


@pytest.mark.parametrize("pole", [0.0, 0.67, 0.9])
def test_the_whole_band_floor_reads_coloured_noise_cut_into_windows(pole):
    """AR(1) noise of unit variance with every window's warm-up unscored (NaN): its level and
    pole over the whole band, whatever the colour (hardrig_none_01, pole 0.67 at 15 samples per
    period, read about half its level above the plant and ``unexplained``)."""
    from scipy.signal import lfilter

    from dtwin.gap.noise import residual_noise_floor

    white = np.random.default_rng(3).standard_normal(6000)
    noise = lfilter([math.sqrt(1 - pole**2)], [1.0, -pole], white)
    noise[(np.arange(6000) % 300) < 60] = np.nan
    floor = residual_noise_floor(noise, 0.01)
    assert floor is not None and not floor.identified
    assert floor.rms == pytest.approx(1.0, rel=0.08)
    memory = floor.acf[1] if len(floor.acf) > 1 else 0.0
    assert memory == pytest.approx(pole, abs=0.05)


def test_the_whole_band_floor_refuses_a_residual_that_is_not_ar1_noise():
    """A lightly damped plant's response to a friction's sign changes beside the noise leaves
    the AR(1) model's innovations coloured, and a drift as slow as the motion fits a pole at
    the grid's top: neither is taken for noise (None: the spectral floor stays)."""
    from scipy.signal import lfilter

    from dtwin.gap.noise import residual_noise_floor

    rng = np.random.default_rng(4)
    noise = lfilter([math.sqrt(1 - 0.6**2)], [1.0, -0.6], rng.standard_normal(6000))
    time = np.arange(6000) * 0.001
    force = np.sign(np.sin(2 * math.pi * 0.7 * time))
    radius, angle = 0.99, 2 * math.pi * 20 / 1000  # a resonance at 20 Hz, ζ ≈ 0.08
    response = lfilter([1.0], [1.0, -2 * radius * math.cos(angle), radius**2], force)
    assert residual_noise_floor(noise + 0.5 * response / np.std(response), 0.01) is None
    drift = np.cumsum(rng.standard_normal(6000))
    assert residual_noise_floor(drift, 0.01) is None


def test_a_band_near_the_nyquist_frequency_keeps_white_noise():
    """At 4 samples per period the band cannot tell a pole from a level: white, as before."""
    from dtwin.gap.noise import spectral_noise_floor

    white = np.random.default_rng(1).standard_normal(6000)
    floor = spectral_noise_floor(white, 0.001, 125.0)
    assert len(floor.acf) == 1 and floor.rms == pytest.approx(1.0, rel=0.1)


@pytest.mark.slow
def test_a_plain_coulomb_rig_reads_coulomb_not_its_stribeck_generalisation():
    """Rig seed 16001 (a sharp Coulomb friction): Stribeck friction removed 65 % of the choosing
    excess, Coulomb friction 61 %, and the score chose Stribeck (a shape mismatch, no bump).

    Slow (a whole calibrated diagnosis, 3.5 CPU s): `make test-fast` checks the choice on such
    shares in tests/gap/test_gap_friction.py (a faint bump stays Coulomb friction)."""
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
    from dtwin.gapbench.rigs import generate_rig_case

    case = generate_rig_case("coulomb_friction", 16001)
    recording = recording_from_frame(case.recording)
    result = diagnose(recording, twin_from_mapping(case.twin, dt=recording.dt), calibrate=True)
    assert (result.module, result.effect) == ("M1", "coulomb_friction")
    assert result.params["Fc"] == pytest.approx(case.key["params"]["Fc"], rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [104, 107])
def test_clean_harder_rigs_with_coloured_noise_read_none(seed):
    """Harder-family `none` rigs at 391 and 130 samples per period, AR(1) noise: before the
    coloured floor both read `unexplained` (floor 0.0094 and 0.0173 for gaps 0.023 and 0.028);
    the calibrated twin stays within 5 % of the plain OE fit's gap."""
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping

    case = generate_hard_rig_case("none", seed)
    recording = recording_from_frame(case.recording)
    result = diagnose(recording, twin_from_mapping(case.twin, dt=recording.dt), calibrate=True)
    plant = result.modules["M1"]
    assert result.effect == "none"
    assert plant.scoring_gap_before <= 1.05 * plant.reference_gap


def test_dtwin_generate_writes_a_harder_rig_case(tmp_path):
    import json

    from dtwin.cli import main

    assert main(["generate", "hardrig_none", "--seed", "2", "--out", str(tmp_path / "c")]) == 0
    key = json.loads((tmp_path / "c" / "key.json").read_text())
    assert (key["arm"], key["effect"], key["seed"]) == ("hard", "none", 2)


@pytest.mark.parametrize("pole", [0.0, 0.7])
def test_the_window_noise_gain_counts_the_noise_colour(pole):
    """The gain is the error variance a window's least-squares initial state carries forward
    from AR(1) measurement noise; checked against 4000 simulated windows."""
    from dtwin.gap.models import warmup_samples, window_noise_gain
    from dtwin.twin.exact import free_response_basis, hold_matrices

    lin, dt, horizon = {"m": 1.0, "c": 2.0, "k": 400.0}, 0.005, 120
    gain = window_noise_gain(lin, dt, "zoh", horizon, pole)
    basis = free_response_basis(hold_matrices(2.0, 400.0, dt, "zoh"), horizon)
    warmup = warmup_samples(horizon)
    from scipy.signal import lfilter

    white = np.random.default_rng(3).standard_normal((4000, horizon + 100))
    noise = lfilter([math.sqrt(1 - pole**2)], [1.0, -pole], white, axis=1)[:, 100:]  # stationary
    states = noise[:, :warmup] @ np.linalg.pinv(basis[:warmup]).T
    error = noise[:, warmup:] - states @ basis[warmup:].T
    assert gain == pytest.approx(float(np.mean(error**2)), rel=0.06)
    if pole:
        assert gain > window_noise_gain(lin, dt, "zoh", horizon, 0.0) * 1.1


def test_a_calibrated_rig_fits_its_input_delay_with_the_effect():
    """Rig seed 501, Coulomb friction at 980 samples per period: the linear twin's delay is 13
    samples for a true 0; at 13 the friction removed 35 % of the choosing excess
    (`unexplained`), re-fitted at its own best delay it is named within 10 %."""
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
    from dtwin.gapbench.rigs import generate_rig_case

    case = generate_rig_case("coulomb_friction", 501)
    recording = recording_from_frame(case.recording)
    result = diagnose(recording, twin_from_mapping(case.twin, dt=recording.dt), calibrate=True)
    assert (result.module, result.effect) == ("M1", "coulomb_friction")
    assert result.params["Fc"] == pytest.approx(case.key["params"]["Fc"], rel=0.1)


def test_every_rig_force_sizes_itself_by_a_parameter_of_its_catalogue_effect():
    """A rig force's scored size is a parameter of its catalogue effect, named by its law."""
    rig = {"plant": {"m": 1.0, "c": 0.3, "k": 4.0}, "breakaway": 2.0, "stribeck_velocity": 0.1}
    for name, force in RIG_FORCES.items():
        _, params = force.law(0.1, rig, 1.0, 1.0, 1.0)
        assert force.size in params
        assert force.size in effect_by_name(name).params
        assert force.strength[0] < force.strength[1]


def test_the_rig_runge_kutta_loop_is_a_fine_adaptive_integration_and_closes_its_loop():
    """The rig's loop (dtwin.twin._force_kernels.rk4_plant, the continuous asset's step) against
    scipy's DOP853 with the force held over each sample: within 1e-7 of the range; and the PD
    loop's held force is its law on the positions the loop returns, to the bit."""
    from scipy.integrate import solve_ivp

    from dtwin.twin._force_kernels import ForceLaw, PdLoop, law_function, rk4_plant

    n, m, c, k, dt = 80, 1.3, 0.4, 40.0, 0.01
    law = ForceLaw("stribeck_friction", (0.3, 0.2, 0.05, 0.02))
    friction = law_function(law)
    rng = np.random.default_rng(3)
    force = rng.normal(size=n)
    states, held = rk4_plant(force, m, c, k, dt, 10, law)
    assert np.array_equal(held, force)
    state, reference = np.zeros(2), [np.zeros(2)]
    for j in range(n - 1):

        def rhs(t, s, f=force[j]):
            return [s[1], (f - c * s[1] - k * s[0] - friction(s[0], s[1])) / m]

        state = solve_ivp(rhs, (0.0, dt), state, method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
        reference.append(state)
    scale = np.max(np.abs(reference), axis=0)
    np.testing.assert_array_less(np.max(np.abs(states - reference), axis=0), 1e-7 * scale)

    loop = PdLoop(900.0, 40.0, np.sin(np.arange(n) * 0.2), 0.1 * rng.normal(size=n))
    noise = 1e-3 * rng.normal(size=n)
    states, held = rk4_plant(np.zeros(n), m, c, k, dt, 10, law, loop, noise)
    y = states[:, 0] + noise
    velocity = np.concatenate([[0.0], (y[1:] - y[:-1]) / dt])
    expected = loop.kp * (loop.reference - y + loop.dither) - loop.kd * velocity
    assert np.array_equal(held, expected) and np.ptp(states[:, 0]) > 0.1
