"""The exact plant's window states under a candidate force (docs/gap.md §Gaps).

A strong velocity-dependent force changes the motion inside the warm-up samples that estimate
each window's initial state; the state must be fitted with the force in the model, or the true
model reads a gap far above the noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.gap.effects import FRICTION_SMOOTHING, Scales, effect_by_name
from dtwin.gap.models import (
    STIFF_BAND,
    STIFF_MEMORY,
    ModuleData,
    _force,
    _stiff_weight,
    _velocity_memory,
    simulate_module,
    warmup_samples,
)
from dtwin.twin.exact import exact_plant_response
from dtwin.twin.paper_modules import ZOH


def _damped_rig(noise: float, seed: int = 3):
    """An integrating plant (m = 2, c = 1, k = 0), quadratic damping 20·v·|v|, held input.

    The damping's force at the velocity's RMS is 5 times the viscous one.
    """
    n, dt = 6000, 1e-3
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.standard_normal(n // 50), 50) * 8.0 + 2.0 * np.sin(np.arange(n) * dt * 9)
    c2 = 20.0
    x = exact_plant_response(
        u,
        2.0,
        1.0,
        0.0,
        dt,
        windows=[(0, n)],
        x_start=np.zeros(n),
        v_start=np.zeros(n),
        hold=ZOH,
        force=lambda x, v: c2 * v * np.abs(v),
    )
    measured = x + noise * rng.standard_normal(n)
    velocity = np.gradient(measured) / dt
    scales = Scales(
        input_max=float(np.max(np.abs(u))),
        input_std=float(np.std(u)),
        output_std=float(np.std(measured)),
        velocity_std=float(np.std(np.gradient(x) / dt)),
        duration=n * dt,
        dt=dt,
        noise_std=noise,
        stiffness=1.0,
        mass=2.0,
    )
    data = ModuleData(
        name="M1",
        inputs={"u_act": u},
        output=measured,
        dt=dt,
        t=np.arange(n) * dt,
        velocity=velocity,
        scales=scales,
        discretisation=ZOH,
        horizon=750,
    )
    return data, c2


def test_the_true_model_over_windows_reads_the_noise_with_a_strong_damping():
    noise = 1e-3
    data, c2 = _damped_rig(noise)
    lin = {"m": 2.0, "c": 1.0, "k": 0.0, "u_offset": 0.0, "delay_samples": 0}
    simulated = simulate_module(data, lin, effect_by_name("quadratic_damping"), (c2,))
    error = (data.output - simulated)[np.isfinite(simulated)]
    # the windows' states carry a little of the warm-up noise forward (window_noise_gain);
    # the force felt once at the linear state's velocity, the former estimate: 30 times the noise
    assert np.sqrt(np.mean(error**2)) < 1.5 * noise


def test_the_velocity_memory_under_a_force_is_the_mass_over_its_slope():
    """m/max|∂F/∂v| per window: a smoothed sign through rest, a quadratic damping, a spring."""
    m, spread = 2.0, 1.0
    v = np.array([np.linspace(-0.5, 0.5, 11), np.linspace(1.0, 2.0, 11)])
    x = np.zeros_like(v)
    coulomb = _force(effect_by_name("coulomb_friction"), (0.4,), spread, arrays=True)
    smooth = FRICTION_SMOOTHING * spread  # the friction's smoothing velocity
    memory = _velocity_memory(coulomb, x, v, m, spread)
    # through rest the sign's slope Fc/v_s; away from rest the tanh is flat
    assert memory[0] == pytest.approx(m * smooth / 0.4, rel=1e-3)
    assert memory[1] > 1e6 * memory[0]
    damping = _force(effect_by_name("quadratic_damping"), (3.0,), spread, arrays=True)
    memory = _velocity_memory(damping, x, v, m, spread)
    assert memory == pytest.approx([m / (2 * 3.0 * 0.5), m / (2 * 3.0 * 2.0)], rel=1e-6)
    spring = _force(effect_by_name("cubic_stiffness"), (5.0, 0.0), spread, arrays=True)
    assert np.all(np.isinf(_velocity_memory(spring, x + 1.0, v, m, spread)))


def test_a_strong_damping_is_not_stiff_over_its_warm_ups():
    """The damped rig's warm-ups are refined: memory about the warm-up, far above STIFF_MEMORY.

    Along its noise-free velocities, as the state fit takes them from a simulation.
    """
    data, c2 = _damped_rig(0.0)
    force = _force(
        effect_by_name("quadratic_damping"), (c2,), data.scales.velocity_std, arrays=True
    )
    warmup = warmup_samples(data.horizon)
    starts = np.arange(0, data.n_samples - data.horizon + 1, data.horizon)
    rows = starts[:, None] + np.arange(warmup)
    memory = _velocity_memory(force, data.output[rows], data.velocity[rows], 2.0, 1.0)
    assert np.all(memory > 3 * STIFF_MEMORY * warmup * data.dt)


def test_the_force_felt_states_weight_passes_smoothly_from_stiff_to_fitted():
    """1 up to the limit, 0 from STIFF_BAND times it on, monotone and continuous between."""
    ratio = np.exp(np.linspace(-2.0, 2.0, 4001))
    weight = _stiff_weight(ratio)
    assert np.all(weight[ratio <= 1.0] == 1.0) and np.all(weight[ratio >= STIFF_BAND] == 0.0)
    assert np.all(np.diff(weight) <= 0.0) and np.max(np.abs(np.diff(weight))) < 3e-3
    assert _stiff_weight(np.array([0.0, np.inf, np.nan])).tolist() == [1.0, 0.0, 0.0]
