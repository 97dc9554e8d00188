"""The nested test (docs/gap.md §Where): a likelihood ratio of stated size on coloured noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import chi2

from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping, which
from dtwin.gap.noise import whitening_filter
from dtwin.gap.which import module_part
from tests.gap.test_gap_diagnose import _rig


def _ar1(pole: float, shape: tuple[int, ...], seed: int) -> np.ndarray:
    """AR(1) noise of unit innovation, shape ``shape`` (the last axis is time)."""
    return lfilter([1.0], [1.0, -pole], np.random.default_rng(seed).standard_normal(shape), axis=-1)


def test_the_whitening_filter_reads_an_ar1_pole_across_unscored_gaps():
    noise = _ar1(0.67, (20000,), seed=1)
    noise[::500] = np.nan  # a window's warm-up is not scored
    whiten = whitening_filter(noise)
    assert whiten[0] == 1.0 and whiten[1] == pytest.approx(-0.67, abs=0.03)
    assert np.all(np.abs(whiten[2:]) < 0.05)
    assert len(whitening_filter(np.random.default_rng(2).standard_normal(20000))) <= 2


def test_the_whitened_ratio_has_its_stated_size_under_coloured_noise():
    """Noise with pole 0.67 and a least-squares term along a slow direction: T is χ²₁.

    The worst case of the test, in sample (out of sample a spurious term only adds error),
    whitened by the noise model of the candidate's error, as the test is. Scaled by the
    effective sample size of a mean square instead, T was 1.9 times too large along such a
    direction (mean 1.86 here), a size of 5 % (21 of these 400) for a stated 1 %.
    """
    n, trials = 3000, 400
    noise = _ar1(0.67, (trials, n), seed=3)
    slow = np.sin(2 * np.pi * np.arange(n) / 700.0)
    statistics = []
    for error in noise:
        fitted = error - (error @ slow) / (slow @ slow) * slow  # the candidate's error
        whiten = whitening_filter(fitted)
        linear, candidate = (lfilter(whiten, [1.0], e)[len(whiten) :] for e in (error, fitted))
        statistics.append(len(linear) * math.log(linear @ linear / (candidate @ candidate)))
    statistics = np.array(statistics)
    assert 0.7 < statistics.mean() < 1.4  # χ²₁ has mean 1
    assert np.count_nonzero(statistics >= chi2.ppf(0.99, 1)) <= 10  # expected 4 of 400


def test_a_slow_effect_is_not_taken_for_coloured_noise():
    """An effect four times the noise's innovation along a slow direction, then removed.

    The linear twin's error holds the effect: an AR model of it whitens the slow term away
    (AR(8) here, and T about 14 times smaller). The candidate's error is the noise alone under
    either hypothesis: its AR(1) model has the noise's pole, and T is the effect's.
    """
    n = 3000
    slow = np.sin(2 * np.pi * np.arange(2 * n) / 700.0)
    error = _ar1(0.67, (2 * n,), seed=5) + 4.0 * slow  # the linear twin's, training then choosing
    train, choose = slice(0, n), slice(n, 2 * n)
    fitted = error - (error[train] @ slow[train]) / (slow[train] @ slow[train]) * slow

    def statistic(whiten):
        linear, candidate = (
            lfilter(whiten, [1.0], e[choose])[len(whiten) :] for e in (error, fitted)
        )
        return len(linear) * math.log(linear @ linear / (candidate @ candidate))

    own, absorbed = whitening_filter(fitted[train]), whitening_filter(error[train])
    assert len(own) == 2 and own[1] == pytest.approx(-0.67, abs=0.05)
    assert len(absorbed) > 2
    assert statistic(own) > 10 * statistic(absorbed)


@pytest.fixture(scope="module")
def rig_data():
    from dtwin.gap.localise import module_inputs
    from dtwin.gap.models import ModuleData

    frame = _rig(0.0, n=2000)
    signals = {"u_act": frame["u_act"].to_numpy(), "x": frame["x"].to_numpy()}
    t = frame["t"].to_numpy()
    inputs = module_inputs("M1", signals, 0.002)
    velocity = np.gradient(signals["x"]) / 0.002
    return ModuleData("M1", inputs, signals["x"], 0.002, t, velocity, restarts=(500, 1500))


def test_module_part_slices_every_signal_and_moves_the_restarts(rig_data):
    part = module_part(rig_data, 400, 1200)
    assert part.n_samples == 800 and part.t[0] == rig_data.t[400]
    assert np.array_equal(part.inputs["u_act"], rig_data.inputs["u_act"][400:1200])
    assert np.array_equal(part.velocity, rig_data.velocity[400:1200])
    assert part.restarts == (100,) and part.position is None


def _noisy_rig(friction: float):
    """The rig of test_gap_diagnose with 0.03 V more white noise on the position (12,000 samples).

    Its gap threshold then needs an excess of about 0.03 of the signal's spread; Coulomb
    friction 0.05 and 0.1 leave 0.016 and 0.031 of it (0.2: above the threshold).
    """
    frame = _rig(friction)
    frame["x"] = frame["x"] + 0.03 * np.random.default_rng(7).standard_normal(len(frame))
    return diagnose(recording_from_frame(frame), twin_from_mapping({"dt": 0.002}))


def test_a_faint_friction_within_the_threshold_is_named_and_a_clean_rig_reads_none():
    faint = _noisy_rig(0.05)
    plant = faint.modules["M1"]
    assert (faint.module, faint.effect) == ("M1", "coulomb_friction")
    assert faint.params["Fc"] == pytest.approx(0.05, rel=0.2)
    assert "within the noise threshold" in plant.reason and "likelihood ratio" in plant.reason
    assert _noisy_rig(0.0).effect == "none"


def test_a_long_recording_is_tested_on_a_bounded_part(monkeypatch):
    """Parts of 1,500 samples (of 6,000 training and 3,000 choosing ones): the same answer."""
    monkeypatch.setattr(which, "NESTED_PART_SAMPLES", 1500)
    calls, fit = [], which.fit_candidates

    def counted(work, split, **options):
        calls.append(split)
        return fit(work, split, **options)

    monkeypatch.setattr(which, "fit_candidates", counted)
    faint = _noisy_rig(0.1)
    assert faint.effect == "coulomb_friction" and faint.params["Fc"] == pytest.approx(0.1, rel=0.2)
    assert (calls[0].n_train, calls[0].n_choose) == (1500, 3000)  # the part: 1,500 of each
    assert calls[1].n_train == 6000  # found: the answer's fits on the whole training part


def test_each_windows_initial_state_is_profiled_out_of_the_error():
    """An integrating plant (velocity time constant 2,000 samples), its true parameters.

    With the state fitted to each window's warm-up (120 of 600 samples), the true twin's error
    holds the state's error, a drift through the window: its mean square is 1.6 times the
    white noise's. With the state fitted to the whole window it is the noise less two
    directions per window, ``σ²·(1 − 2/600)``.
    """
    from dtwin.gap.models import ModuleData, profiled_window_error, simulate_module
    from dtwin.twin.exact import exact_plant_response
    from dtwin.twin.paper_modules import ZOH

    n, dt, horizon, sigma = 6000, 0.001, 600, 0.01
    rng = np.random.default_rng(11)
    u = lfilter([1.0], [1.0, -0.99], rng.standard_normal(n))
    u -= u.mean()
    lin = {"m": 0.02, "c": 0.01, "k": 0.0, "u_offset": 0.0, "delay_samples": 0}
    zeros = np.zeros(n)
    x = exact_plant_response(
        u, 0.02, 0.01, 0.0, dt, windows=[(0, n)], x_start=zeros, v_start=zeros, hold=ZOH
    )
    spread = float(np.std(x))
    x = x / spread + sigma * rng.standard_normal(n)
    lin["m"], lin["c"] = 0.02 * spread, 0.01 * spread  # the same plant, the position scaled
    t = np.arange(n) * dt
    data = ModuleData("M1", {"u_act": u}, x, dt, t, np.gradient(x) / dt, None, ZOH, horizon)
    plain = x - simulate_module(data, lin)
    profiled = profiled_window_error(data, lin)
    assert np.all(np.isfinite(profiled))
    assert np.nanmean(plain**2) > 1.4 * sigma**2
    assert np.mean(profiled**2) == pytest.approx(sigma**2 * (1 - 2 / horizon), rel=0.05)


def test_the_linear_alternative_fits_a_linear_chain_the_twin_cannot():
    """A fourth-order linear chain (two lightly damped sections), noise 0.01 on the output.

    The nested test's OE(6, 6) alternative (docs/gap.md §Where), its window states fitted to
    each window, leaves about the noise on the choosing part; no effect is needed to explain
    what a linear model of higher order removes.
    """
    from dtwin.gap.models import ModuleData
    from dtwin.gap.oe_reference import plain_linear_error
    from dtwin.twin.paper_modules import ZOH

    n, dt, sigma = 4000, 0.01, 0.01
    rng = np.random.default_rng(13)
    u = lfilter([1.0], [1.0, -0.9], rng.standard_normal(n))
    section = [1.0, -1.8, 0.9]  # poles at radius 0.95
    x = lfilter([0.0, 0.05], np.convolve(section, [1.0, -1.7, 0.8]), u)
    x = x / np.std(x) + sigma * rng.standard_normal(n)
    t = np.arange(n) * dt
    data = ModuleData("M1", {"u_act": u}, x, dt, t, np.gradient(x) / dt, None, ZOH, 500)
    error = plain_linear_error(data, 0, n // 2, 6, 1)
    assert np.all(np.isfinite(error))
    assert np.sqrt(np.mean(error[n // 2 :] ** 2)) < 1.3 * sigma  # measured 0.00996
    second_order = plain_linear_error(data, 0, n // 2, 2, 1)  # the twin's order: 0.158
    assert np.sqrt(np.mean(second_order[n // 2 :] ** 2)) > 5 * sigma
