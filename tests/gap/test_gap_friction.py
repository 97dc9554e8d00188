"""Friction beyond Coulomb: Stribeck friction fitted from Coulomb friction, chosen when it shows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dtwin.gap.effects import Scales, effect_by_name
from dtwin.gap.results import CandidateReport, GapSettings
from dtwin.gap.which import NEST_DEPARTURE, NEST_EVIDENCE, NEST_MARGIN_PCT, choose


def _report(effect: str, params: dict, share: float, score: float, weight: float):
    return CandidateReport(
        module="M1",
        effect=effect,
        params=params,
        lin={"m": 1.0, "c": 0.1, "k": 1.0},
        n_params=3 + len(params),
        choosing_gap=0.02,
        choosing_share_pct=share,
        scoring_gap_after=0.02,
        raw_shrink_pct=50.0,
        own_shrink_pct=share,
        excess_shrink_pct=share,
        excess_clipped=False,
        score=score,
        weight=weight,
    )


class _Work:
    name, gap_cal, threshold, nested = "M1", 0.1, 0.02, None


def _answer(fs: float, stribeck_share: float, coulomb_score: float = 40.0):
    ranked = [
        _report("stribeck_friction", {"Fc": 1.0, "Fs": fs, "vs": 0.2}, stribeck_share, 0.0, 0.9),
        _report("coulomb_friction", {"Fc": 1.3}, 80.0, coulomb_score, 0.1),
    ]
    return choose([_Work()], {"M1": ranked}, GapSettings())[1]


def test_a_breakaway_the_fit_shows_is_stribeck_friction_whatever_its_share_margin():
    """A breakaway force 1.6 times the sliding one, 1 point more of the excess: Stribeck."""
    chosen = _answer(fs=1.6, stribeck_share=81.0)
    assert chosen.effect == "stribeck_friction" and chosen.weight == pytest.approx(0.9)
    weak = _answer(fs=1.6, stribeck_share=81.0, coulomb_score=0.8 * NEST_EVIDENCE)
    assert weak.effect == "coulomb_friction"  # a bump the score barely prefers: not shown
    ranked = [
        _report("stribeck_friction", {"Fc": 1.0, "Fs": 1.6, "vs": 0.2}, 100.0, 0.0, 0.9),
        _report("coulomb_friction", {"Fc": 1.3}, 100.0, 40.0, 0.1),
    ]
    plain = choose([_Work()], {"M1": ranked}, GapSettings())[1]
    assert plain.effect == "coulomb_friction"  # Coulomb friction leaves nothing to the floor


def test_a_faint_bump_stays_coulomb_friction_unless_it_removes_clearly_more():
    """A bump of 10 % is a shape mismatch: Coulomb keeps both weights; 6 points more win."""
    faint = _answer(fs=1.0 + 0.4 * NEST_DEPARTURE, stribeck_share=81.0)
    assert faint.effect == "coulomb_friction" and faint.weight == pytest.approx(1.0)
    clear = _answer(fs=1.0 + 0.4 * NEST_DEPARTURE, stribeck_share=80.0 + NEST_MARGIN_PCT + 1)
    assert clear.effect == "stribeck_friction"


def test_stribeck_friction_starts_at_the_fitted_coulomb_friction_and_departs_by_its_bump():
    stribeck = effect_by_name("stribeck_friction")
    scales = Scales(
        input_std=2.0,
        input_max=6.0,
        output_std=1.0,
        velocity_std=4.0,
        duration=10.0,
        dt=0.01,
        noise_std=0.01,
    )
    starts = stribeck.nested_starts([0.7], scales)
    assert starts[0] == [0.7, 0.7, pytest.approx(0.4)]  # the Coulomb fit itself
    assert all(fs > fc for fc, fs, _ in starts[1:])
    low, high = stribeck.bounds(scales)[2]
    assert all(low <= vs <= high for _, _, vs in starts)
    assert stribeck.departure(starts[0]) == 0.0
    assert stribeck.departure([1.0, 1.5, 0.2]) == pytest.approx(0.5)
    assert stribeck.departure([1.0, 0.8, 0.2]) == 0.0  # no bump below the sliding force
    assert math.isinf(stribeck.departure([0.0, 0.5, 0.2]))
    assert effect_by_name("coulomb_friction").departure is None


@pytest.mark.slow
def test_a_breakaway_rig_reads_stribeck_friction_though_it_removes_barely_more():
    """Harder rig, Stribeck seed 501 (a dev seed; open loop, 979 samples per period, Fs = 2.6
    Fc): Stribeck friction removes 76 % of the choosing excess, Coulomb friction 75 % with a
    level 1.6 times the sliding force. The fitted breakaway (Fs/Fc = 2.6) shows what Coulomb
    friction lacks; before, the share margin alone kept Coulomb friction.

    Slow (a whole diagnosis of 20,000 samples, 7-8 CPU s): `make test-fast` checks the choice
    on these shares (test_a_breakaway_the_fit_shows_is_stribeck_friction_whatever_its_share_margin).
    """
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
    from dtwin.gapbench.rigs import generate_hard_rig_case

    case = generate_hard_rig_case("stribeck_friction", 501)
    recording = recording_from_frame(case.recording)
    result = diagnose(recording, twin_from_mapping(case.twin, dt=recording.dt), calibrate=True)
    truth = case.key["params"]
    assert (result.module, result.effect) == ("M1", "stribeck_friction")
    for name in ("Fc", "Fs"):
        assert result.params[name] == pytest.approx(truth[name], rel=0.1)
        low, high = result.param_intervals[name]
        assert low <= truth[name] <= high


def test_stribeck_friction_without_a_bump_is_coulomb_friction_at_its_plain_part():
    """``plain_part`` maps a Stribeck fit to the Coulomb friction it equals when ``Fs ≤ Fc``."""
    from dtwin.gap.models import _force

    stribeck, coulomb = effect_by_name("stribeck_friction"), effect_by_name("coulomb_friction")
    velocity = np.linspace(-3.0, 3.0, 61)
    for theta in ([1.3, 0.9, 0.2], [1.3, 1.3, 0.5]):
        plain = stribeck.plain_part(theta)
        assert plain == [1.3]
        wide_force = _force(stribeck, theta, 4.0, arrays=True)(0 * velocity, velocity)
        plain_force = _force(coulomb, plain, 4.0, arrays=True)(0 * velocity, velocity)
        np.testing.assert_array_equal(wide_force, plain_force)
    assert coulomb.plain_part is None


def test_a_fit_from_another_models_start_replaces_its_incumbent_only_when_it_trains_better():
    """``fit_candidate(incumbent=...)``: a start no better than the incumbent fit is not refined
    and the incumbent itself comes back; a better start is refined and wins."""
    from dtwin.gap.fit import fit_candidate
    from dtwin.gap.models import ModuleData, first_order_lag

    dt, n = 0.02, 1000
    t = np.arange(n) * dt
    x = np.sin(2 * np.pi * 0.3 * t) + 0.5 * np.sign(np.sin(2 * np.pi * 0.07 * t))
    y = 1.08 * first_order_lag(x, 0.08, dt, x[0]) + 0.01
    y = y + 0.01 * np.random.default_rng(3).standard_normal(n)
    scales = Scales(
        input_max=1.5,
        input_std=float(np.std(x)),
        output_std=float(np.std(y)),
        velocity_std=0.0,
        duration=n * dt,
        dt=dt,
        noise_std=0.01,
    )
    data = ModuleData("M2a", {"x": x}, y, dt, t, scales=scales)
    effect = effect_by_name("sensor_scale_error")
    start = {"tau": 0.08, "bias": 0.0}
    best = fit_candidate(data, effect, start, n_train=700)
    again = fit_candidate(data, effect, best.lin, n_train=700, starts=[[0.5]], incumbent=best)
    assert again is best
    poor = fit_candidate(data, effect, start, n_train=700, starts=[[0.5]], n_refine=0)
    better = fit_candidate(data, effect, start, n_train=700, starts=[[1.0]], incumbent=poor)
    assert better is not poor and better.train_rms < poor.train_rms
    assert better.theta[0] == pytest.approx(1.08, rel=0.01)


def test_a_force_on_the_exact_plant_is_fitted_with_a_finite_difference_step_above_its_roughness(
    monkeypatch,
):
    """An exact plant's training error with a candidate force is rough on small scales (window
    states fitted under the force, stick–slip), so its Jacobian takes steps of
    ``FORCE_DIFF_STEP`` of each typical size; the linear twin keeps SciPy's default step."""
    from dtwin.gap import fit
    from dtwin.gap.models import ModuleData, velocity_from_position

    dt, n = 0.01, 600
    t = np.arange(n) * dt
    u = np.sin(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 1.7 * t)
    x = np.cumsum(np.cumsum(u) * dt) * dt * 0.1
    velocity = velocity_from_position(x, dt)
    scales = Scales(
        input_max=1.3,
        input_std=float(np.std(u)),
        output_std=float(np.std(x)),
        velocity_std=float(np.std(velocity)),
        duration=n * dt,
        dt=dt,
        noise_std=0.0,
    )
    data = ModuleData(
        "M1", {"u_act": u}, x, dt, t, velocity, scales=scales, discretisation="zoh", horizon=100
    )
    steps = []

    def recording(fun, x0, **options):
        steps.append(options.get("diff_step"))
        raise ValueError("recorded")  # _scaled_least_squares treats it as a failed fit

    monkeypatch.setattr(fit, "least_squares", recording)
    start = {"m": 1.0, "c": 0.1, "k": 0.0}
    fit.fit_candidate(data, effect_by_name("coulomb_friction"), start, n_train=400, n_refine=1)
    fit.fit_candidate(data, None, start, n_train=400)
    assert steps == [fit.FORCE_DIFF_STEP, None]
