"""The 95 % intervals of a fitted candidate's parameters (dtwin/gap/intervals.py)."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.gap.effects import Scales, effect_by_name
from dtwin.gap.effects.actuator_deadzone import SOFT_DEADZONE
from dtwin.gap.fit import FIT_XTOL, fit_candidate
from dtwin.gap.intervals import parameter_intervals, smoothed_fit
from dtwin.gap.models import ModuleData, first_order_lag


def _scales(u: np.ndarray, y: np.ndarray, dt: float, noise: float) -> Scales:
    return Scales(
        input_max=float(np.max(np.abs(u))),
        input_std=float(np.std(u)),
        output_std=float(np.std(y)),
        velocity_std=0.0,
        duration=float(len(u) * dt),
        dt=dt,
        noise_std=noise,
        stiffness=1.0,
        mass=1.0,
        output_mean=float(np.mean(y)),
    )


def _sensor(noise: float, gain: float = 1.08, n: int = 1500):
    """Sensor A with a scale error, white noise of std ``noise`` (0: none): data, truth."""
    dt = 0.02
    t = np.arange(n) * dt
    x = np.sin(2 * np.pi * 0.3 * t) + 0.5 * np.sign(np.sin(2 * np.pi * 0.07 * t))
    y = gain * first_order_lag(x, 0.08, dt, x[0]) + 0.01
    y = y + noise * np.random.default_rng(3).standard_normal(n)
    data = ModuleData("M2a", {"x": x}, y, dt, t, scales=_scales(x, y, dt, max(noise, 1e-3)))
    return data, gain


def test_a_noiseless_module_gets_the_fits_step_tolerance_and_holds_the_truth():
    """Residuals at rounding level give a sandwich interval of ~1e-13: the fit itself is only
    converged to FIT_XTOL, so the interval is never narrower than that and holds the truth."""
    effect = effect_by_name("sensor_scale_error")
    data, gain = _sensor(noise=0.0)
    fit = fit_candidate(data, effect, {"tau": 0.08, "bias": 0.0}, n_train=750)
    low, high = parameter_intervals(data, effect, fit.lin, fit.theta, 750)["gain"]
    assert low <= gain <= high
    assert FIT_XTOL * gain <= high - low < 1e3 * FIT_XTOL * gain


def test_a_wider_forms_contrast_counts_only_beyond_its_own_spread():
    """The same fit as its own wider form adds nothing (contrast 0, its variance 0); a wider
    fit off by 3 interval widths with the same block influences adds its full square, so its
    estimate lies inside the interval."""
    effect = effect_by_name("sensor_scale_error")
    data, _ = _sensor(noise=0.03)
    fit = fit_candidate(data, effect, {"tau": 0.08, "bias": 0.0}, n_train=750)
    plain = parameter_intervals(data, effect, fit.lin, fit.theta, 750)
    same = parameter_intervals(
        data, effect, fit.lin, fit.theta, 750, wider=(effect, fit.lin, fit.theta)
    )
    assert same == plain
    other = fit.theta[0] + 3.0 * (plain["gain"][1] - plain["gain"][0])
    off = (effect, fit.lin, (other,))
    wide = parameter_intervals(data, effect, fit.lin, fit.theta, 750, wider=off)
    assert wide["gain"][0] < plain["gain"][0] and wide["gain"][1] > other
    assert wide["tau"] == plain["tau"]


def test_a_saturation_level_the_input_never_reaches_is_bounded_from_below_by_the_data():
    """A tanh saturation driven to 0.8 of its level, read through the catalogue's algebraic
    form: the fitted level overshoots; the interval reaches down to the map's largest output
    over the recorded inputs, and holds the true level."""
    effect = effect_by_name("actuator_saturation")
    assert effect.input_limit == ("U", "u_cmd")
    dt, n, level = 0.01, 3000, 2.0
    t = np.arange(n) * dt
    rng = np.random.default_rng(7)
    u = 0.8 * level * np.sin(2 * np.pi * 0.4 * t + np.sin(2 * np.pi * 0.05 * t))
    y = first_order_lag(level * np.tanh(u / level), 0.15, dt, 0.0)
    y = y + 0.002 * rng.standard_normal(n)
    data = ModuleData("M0", {"u_cmd": u}, y, dt, t, scales=_scales(u, y, dt, 0.002))
    fit = fit_candidate(data, effect, {"tau": 0.15}, n_train=n // 2)
    low, high = parameter_intervals(data, effect, fit.lin, fit.theta, n // 2)["U"]
    reached = np.max(np.abs(effect.input_map(u[: n // 2], fit.theta, dt)))
    assert low == reached < level <= high


def _deadzone_case(smooth: bool, width: float = 0.2, n: int = 3000):
    """The actuator behind a dead zone of half-width ``width``, hard or ``u − D·tanh(u/D)``."""
    dt = 0.01
    t = np.arange(n) * dt
    u = np.sin(2 * np.pi * 0.4 * t + np.sin(2 * np.pi * 0.05 * t))
    hard = np.sign(u) * np.maximum(np.abs(u) - width, 0.0)
    mapped = u - width * np.tanh(u / width) if smooth else hard
    y = first_order_lag(mapped, 0.15, dt, 0.0) + 0.002 * np.random.default_rng(5).standard_normal(n)
    return ModuleData("M0", {"u_cmd": u}, y, dt, t, scales=_scales(u, y, dt, 0.002))


def test_a_rounded_dead_zone_read_as_the_hard_one_is_covered_through_its_smoothed_form():
    """Rounded edges bias the hard form's D low beyond its statistical interval; the smoothed
    form (the input less the catalogue's saturation) estimates it, and the contrast covers the
    truth. A hard dead zone's smoothed fit is as sharp as it may be, and adds nothing."""
    effect = effect_by_name("actuator_deadzone")
    for smooth in (True, False):
        data = _deadzone_case(smooth)
        fit = fit_candidate(data, effect, {"tau": 0.15}, n_train=1500)
        plain = parameter_intervals(data, effect, fit.lin, fit.theta, 1500)["D"]
        wider = smoothed_fit(data, effect, fit.lin, fit.theta, 1500)
        assert wider is not None and wider[0] is effect.smoothed is SOFT_DEADZONE
        low, high = parameter_intervals(data, effect, fit.lin, fit.theta, 1500, wider=wider)["D"]
        assert low <= 0.2 <= high
        if smooth:
            assert not plain[0] <= 0.2 <= plain[1]
        else:
            assert (low, high) == pytest.approx(plain, rel=1e-3)


def test_a_parameter_the_residuals_do_not_see_is_held_and_the_others_keep_their_intervals():
    """A Jacobian column at 0 (a plant's k fitted at 1e-15 of its mode's size on an integrating
    rig) made JᵀJ singular and left the whole answer without an interval; the parameter is held
    at its value instead (NaN influence) and the others' influences are those without it."""
    from dtwin.gap.intervals import _block_influences

    rng = np.random.default_rng(5)
    jac = rng.standard_normal((400, 2))
    r0 = 0.1 * rng.standard_normal(400)
    alone = _block_influences(jac, r0, 20)
    held = _block_influences(np.column_stack([jac[:, 0], np.zeros(400), jac[:, 1]]), r0, 20)
    assert np.all(np.isnan(held[:, 1]))
    np.testing.assert_allclose(held[:, [0, 2]], alone, rtol=1e-12)


def test_a_force_on_the_exact_plant_has_its_jacobian_taken_with_the_fits_step():
    """The interval's Jacobian reads the training error with the step its fit used
    (fit.fit_diff_step): FORCE_DIFF_STEP·max(1, |θ/typical|) of each typical size for a force on
    the exact plant, _STEP of it elsewhere."""
    from dataclasses import replace

    from dtwin.gap.fit import FORCE_DIFF_STEP
    from dtwin.gap.intervals import _STEP, _steps

    data, _ = _sensor(noise=0.0, n=200)
    beta, typical = np.array([0.5, 30.0]), np.array([1.0, 2.0])
    force = effect_by_name("coulomb_friction")
    exact = replace(data, discretisation="zoh")
    np.testing.assert_allclose(
        _steps(exact, force, beta, typical), FORCE_DIFF_STEP * np.array([1.0, 30.0])
    )
    np.testing.assert_allclose(_steps(data, force, beta, typical), _STEP * typical)
    sensor = effect_by_name("sensor_scale_error")
    np.testing.assert_allclose(_steps(exact, sensor, beta, typical), _STEP * typical)
