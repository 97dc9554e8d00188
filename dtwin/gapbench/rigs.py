"""A family of rig-like recordings for the gap benchmark: continuous plants, any time scale.

Specification: docs/gap.md §Rig family.

The paper's asset (:mod:`dtwin.gapbench.generator`) is the twin's own Euler recursion at ~150
samples per period, with every signal recorded and the twin's parameters known. Measured rigs
are none of that: a continuous plant sampled anywhere from 3 to 1000 samples per period, in
volts or micrometres, with offsets, often integrating (``k = 0``) and run in a closed loop,
recorded as ``t, u_act, x`` with no nominal parameters. :func:`generate_rig_case` draws such a
rig and integrates it finely (classical Runge-Kutta, 10 sub-steps per sample) with one withheld
plant effect:

- open loop: a band-limited multisine force, evaluated continuously (so neither a zero- nor a
  first-order hold is exact);
- closed loop: a digital PD position controller (its force held over each sample) tracking a
  multisine reference, with a dither; always so for an integrating plant;
- white measurement noise on the position (0.5–2 % of its spread), fed back in a closed loop;
- the effect (``coulomb_friction``, ``cubic_stiffness``, ``quadratic_damping``, or ``none``)
  with a strength from barely visible (``magnitude`` 0) to strong (1), in the catalogue's form
  but a different smoothing.

Arrays are time-first, shape ``(n_samples,)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from dtwin._validation import DtwinValueError
from dtwin.gap.effects import effect_by_name
from dtwin.gapbench.families import FAMILY_PREFIXES, generate_family_case
from dtwin.gapbench.generator import GeneratedCase, accepted_effects, generate_case

__all__ = [
    "RIG_EFFECTS",
    "RIG_FORCES",
    "RigForce",
    "RIG_PREFIX",
    "RIG_SAMPLES",
    "HARD_RIG_EFFECTS",
    "HARD_RIG_PREFIX",
    "generate_rig_case",
    "generate_hard_rig_case",
    "generate_any_case",
]

#: The withheld effects of the rig family (all in the plant, M1).
RIG_EFFECTS: tuple[str, ...] = ("none", "coulomb_friction", "cubic_stiffness", "quadratic_damping")
#: Case-type prefix of the rig family in ``gap.benchmark.effects`` (``rig_coulomb_friction``).
RIG_PREFIX = "rig_"
#: Samples per rig recording.
RIG_SAMPLES = 6000
#: The withheld effects of the harder rig family (docs/gap.md §Rig family).
HARD_RIG_EFFECTS: tuple[str, ...] = (*RIG_EFFECTS, "stribeck_friction")
#: Case-type prefix of the harder rig family (``hardrig_stribeck_friction``).
HARD_RIG_PREFIX = "hardrig_"
#: Fewest and most samples of a harder rig recording (a few periods of its resonance).
HARD_RIG_SAMPLES = (3000, 20000)
_SUBSTEPS = 10


def _log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def _draw_rig(rng: np.random.Generator, effect: str, samples_per_period: float | None) -> dict:
    """Physical parameters (SI-like units, m = 1) and the experiment of one rig."""
    drawn = _log_uniform(rng, 3.0, 1000.0)
    samples_per_period = drawn if samples_per_period is None else float(samples_per_period)
    rate = _log_uniform(rng, 20.0, 20000.0)  # Hz
    dt = 1.0 / rate
    omega = 2 * math.pi / (samples_per_period * dt)
    integrating = not _needs_spring(effect) and rng.uniform() < 0.3
    closed = integrating or (samples_per_period >= 15 and rng.uniform() < 0.35)
    if closed and samples_per_period < 15:  # a digital PD loop needs ≥ 15 samples per period
        samples_per_period = max(_log_uniform(rng, 15.0, 1000.0), samples_per_period)
        omega = 2 * math.pi / (samples_per_period * dt)
    zeta = _log_uniform(rng, 0.005, 1.0)
    plant = _draw_plant(rng, zeta, omega, dt, integrating)
    return {
        "dt": dt,
        "omega": omega,
        "samples_per_period": samples_per_period,
        "zeta": zeta,
        "integrating": integrating,
        "closed_loop": closed,
        "plant": plant,
        "u_scale": 10 ** rng.uniform(-3, 3),
        "x_scale": 10 ** rng.uniform(-6, 3),
    }


def _draw_plant(
    rng: np.random.Generator, zeta: float, omega: float, dt: float, integrating: bool
) -> dict:
    """Return the plant ``m, c, k`` of damping ratio ``zeta`` at ``omega`` (rad/s).

    An integrating plant has no period (k = 0): its damping is a velocity time constant of
    30–3000 samples, drawn from ``rng`` (the only draw here).
    """
    plant = {"m": 1.0, "c": 2 * zeta * omega, "k": 0.0 if integrating else omega**2}
    if integrating:
        plant["c"] = 1.0 / (_log_uniform(rng, 30.0, 3000.0) * dt)
    return plant


def _draw_hard_rig(rng: np.random.Generator, effect: str, samples_per_period: float | None) -> dict:
    """Draw the harder family's rig: lightly damped, a few periods, held input, coloured noise."""
    drawn = _log_uniform(rng, 3.0, 1000.0)
    samples_per_period = drawn if samples_per_period is None else float(samples_per_period)
    integrating = not _needs_spring(effect) and rng.uniform() < 0.4
    closed = integrating or (samples_per_period >= 15 and rng.uniform() < 0.35)
    if closed and samples_per_period < 15:
        samples_per_period = max(_log_uniform(rng, 15.0, 1000.0), samples_per_period)
    dt = 1.0 / _log_uniform(rng, 20.0, 20000.0)
    omega = 2 * math.pi / (samples_per_period * dt)
    zeta = _log_uniform(rng, 0.01, 0.3)
    plant = _draw_plant(rng, zeta, omega, dt, integrating)
    low, high = HARD_RIG_SAMPLES
    periods = _log_uniform(rng, 3.0, 30.0)
    return {
        "dt": dt,
        "omega": omega,
        "samples_per_period": samples_per_period,
        "zeta": zeta,
        "integrating": integrating,
        "closed_loop": closed,
        "plant": plant,
        "u_scale": 10 ** rng.uniform(-3, 3),
        "x_scale": 10 ** rng.uniform(-3, 3),
        "hold": True,
        "noise_pole": rng.uniform(0.5, 0.95),
        "noise_level": (0.005, 0.03),
        "n_samples": int(min(max(round(periods * samples_per_period), low), high)),
        "periods": periods,
        "breakaway": rng.uniform(1.5, 3.0),  # Stribeck: Fs over Fc
        "stribeck_velocity": rng.uniform(0.05, 0.3),  # Stribeck: vs over std(v)
    }


def _multisine(rng: np.random.Generator, low: float, high: float, n_lines: int = 16):
    """Return a band-limited multisine, unit RMS: ``f(t)`` for scalar or array ``t`` (s)."""
    freqs = np.exp(rng.uniform(math.log(low), math.log(high), n_lines))
    phases = rng.uniform(0, 2 * math.pi, n_lines)
    scale = math.sqrt(2.0 / n_lines)

    def signal(t):
        return scale * np.sum(np.sin(2 * math.pi * np.multiply.outer(t, freqs) + phases), axis=-1)

    return signal


def _rig_coulomb(strength, rig, u_std, x_rms, v_rms):
    fc = strength * u_std
    smooth = 0.002 * v_rms
    return ("tanh_friction", (fc, smooth)), {"Fc": fc}


def _rig_cubic(strength, rig, u_std, x_rms, v_rms):
    k3 = strength * rig["plant"]["k"] / x_rms**2
    return ("cubic_spring", (k3, 0.0)), {"k3": k3}


def _rig_quadratic_damping(strength, rig, u_std, x_rms, v_rms):
    c2 = strength * rig["plant"]["c"] / v_rms
    return ("quadratic_damping", (c2,)), {"c2": c2}


def _rig_stribeck(strength, rig, u_std, x_rms, v_rms):
    fc = strength * u_std
    fs, vs = fc * rig["breakaway"], rig["stribeck_velocity"] * v_rms
    smooth = 0.002 * v_rms
    law = ("stribeck_friction", (fc, fs - fc, vs, smooth))
    return law, {"Fc": fc, "Fs": fs, "vs": vs}


@dataclass(frozen=True)
class RigForce:
    """One withheld force of the rig families, in one place.

    Attributes
    ----------
    law : callable
        ``law(strength, rig, u_std, x_rms, v_rms) -> ((name, params), its parameters in
        physical units)``: the force ``F(x, v)`` (N) as a law of
        :data:`dtwin.twin._force_kernels.LAWS` and its parameters (a case effect's ``force``).
    strength : (float, float)
        Strength (relative to the linear force it competes with) at magnitude 0 and 1.
    size : str
        The parameter that sets the effect's size, in the catalogue's name (what the benchmark
        scores, :func:`dtwin.gapbench.scores.true_parameter`).
    spring : bool
        The force scales with the spring ``k``: an integrating rig (``k = 0``) cannot carry it,
        so such a case never draws one.
    """

    law: Callable[..., tuple[tuple[str, tuple[float, ...]], dict[str, float]]]
    strength: tuple[float, float]
    size: str
    spring: bool = False


#: The rig families' withheld forces, by effect; ``none`` has no force.
RIG_FORCES: dict[str, RigForce] = {
    "coulomb_friction": RigForce(_rig_coulomb, (0.04, 0.3), "Fc"),  # Fc over std(u)
    "cubic_stiffness": RigForce(_rig_cubic, (0.08, 0.6), "k3", spring=True),  # k3·x_rms² over k
    "quadratic_damping": RigForce(_rig_quadratic_damping, (0.2, 1.5), "c2"),  # c2·v_rms over c
    # Fc over std(u); the breakaway Fs is 1.5–3 Fc
    "stribeck_friction": RigForce(_rig_stribeck, (0.04, 0.3), "Fc"),
}


def _needs_spring(effect: str) -> bool:
    """Return whether ``effect``'s force scales with the spring (:attr:`RigForce.spring`)."""
    force = RIG_FORCES.get(effect)
    return force is not None and force.spring


def _force_law(effect: str, strength: float, rig: dict, u_std: float, x_rms: float, v_rms: float):
    """Return the withheld force ``F(x, v)`` (N; a law, None for none) and its parameters."""
    force = RIG_FORCES.get(effect)
    return (None, {}) if force is None else force.law(strength, rig, u_std, x_rms, v_rms)


def _integrate(rig: dict, drive: _Drive, law, n: int, noise: np.ndarray) -> np.ndarray:
    """Runge-Kutta integration; return the states ``(x, v)`` at the sample instants, ``(n, 2)``.

    :func:`dtwin.twin._force_kernels.rk4_plant` (the step of the continuous asset's loop) under
    ``drive``'s force, or its PD loop closed on the position plus ``noise`` (``drive.held``
    becomes the force the loop held); ``law`` is the withheld force ``(name, params)``, None
    for none. ``n`` is the drive's length.
    """
    from dtwin.twin._force_kernels import (  # numba (~0.5 s) only when run
        ForceLaw,
        PdLoop,
        rk4_plant,
    )

    plant = rig["plant"]
    force = drive.held if drive.continuous is None else drive.continuous
    loop = None if not drive.closed else PdLoop(drive.kp, drive.kd, drive.reference, drive.dither)
    states, drive.held = rk4_plant(
        force[:n],
        plant["m"],
        plant["c"],
        plant["k"],
        rig["dt"],
        _SUBSTEPS,
        None if law is None else ForceLaw(*law),
        loop,
        noise,
    )
    return states


class _Drive:
    """The force on the plant: an open-loop multisine, or a digital PD loop (held per sample).

    Every signal is evaluated once for all instants it is needed at (arrays, not one point at a
    time): the continuous multisine at each Runge-Kutta instant, the loop's reference at each
    sample.
    """

    def __init__(self, rig: dict, rng: np.random.Generator, n: int):
        omega, dt = rig["omega"], rig["dt"]
        nyquist = 0.5 / dt
        self.closed = rig["closed_loop"]
        self.held_input = False
        self.dt = dt
        self.held = np.zeros(n)
        self.continuous = None
        band_high = min(3.0 * omega / (2 * math.pi), 0.4 * nyquist)
        if not self.closed:
            self.excite = _multisine(rng, 0.1 * omega / (2 * math.pi), band_high)
            self.held_input = rig.get("hold", False)
            if self.held_input:  # a DAC: the force held over each sample
                self.held = self.excite(np.arange(n) * dt)
            else:
                self.continuous = _runge_kutta_values(self.excite, dt, n)
            return
        m, c = rig["plant"]["m"], rig["plant"]["c"]
        loop = omega * _log_uniform(rng, 0.5, 1.5)
        self.kp = m * loop**2
        self.kd = max(2 * 0.7 * m * loop - c, 0.0)
        reference = _multisine(rng, 0.05 * loop / (2 * math.pi), 0.7 * loop / (2 * math.pi))
        self.reference = reference(np.arange(n) * dt)
        self.dither = rng.standard_normal(n) * 0.1

    def recorded(self, n: int) -> np.ndarray:
        """Return the force at the sample instants, shape ``(n,)``."""
        if self.closed or self.held_input:
            return np.array(self.held[:n])
        return self.excite(np.arange(n) * self.dt)


#: Samples whose Runge-Kutta instants one multisine evaluation covers (bounds its memory).
_CHUNK = 2048


def _runge_kutta_values(signal: Callable, dt: float, n: int) -> np.ndarray:
    """Return ``signal`` at every Runge-Kutta instant of ``n`` samples, ``(n, _SUBSTEPS, 3)``.

    Sub-step ``s`` of sample ``j`` starts at ``t = j·dt + s·h`` (``h = dt / _SUBSTEPS``); its
    instants are ``t``, ``t + h/2`` and ``t + h``, each rounded as a scalar loop would round it.
    """
    h = dt / _SUBSTEPS
    values = np.empty((n, _SUBSTEPS, 3))
    offsets = np.arange(_SUBSTEPS) * h
    for start in range(0, n, _CHUNK):
        t = (np.arange(start, min(start + _CHUNK, n)) * dt)[:, None] + offsets
        instants = np.stack([t, t + h / 2, t + h], axis=-1)
        values[start : start + len(t)] = signal(instants)
    return values


def _measurement_noise(rig: dict, rng: np.random.Generator, n: int) -> tuple[float, np.ndarray]:
    """Return the position noise's level (over std(x)) and unit-variance shape ``(n,)``.

    White, or AR(1) in the harder family: ``e[k] = a·e[k−1] + √(1 − a²)·w[k]``.
    """
    level = rng.uniform(*rig.get("noise_level", (0.005, 0.02)))
    white = rng.standard_normal(n)
    pole = rig.get("noise_pole")
    if pole is None:
        return level, white
    return level, lfilter([math.sqrt(1.0 - pole**2)], [1.0, -pole], white)


def _run(rig, rng_seed: int, effect: str, strength: float, n: int):
    """Simulate the linear rig (for the scales), then the rig with its effect (same draws)."""
    rng = np.random.default_rng(rng_seed)
    pilot = _Drive(rig, np.random.default_rng(rng_seed), n)
    linear = _integrate(rig, pilot, None, n, np.zeros(n))
    x_rms = float(np.std(linear[:, 0])) or 1.0
    v_rms = float(np.std(linear[:, 1])) or 1.0
    u_std = float(np.std(pilot.recorded(n))) or 1.0
    level, shape = _measurement_noise(rig, rng, n)
    noise = x_rms * level * shape
    force, params = _force_law(effect, strength, rig, u_std, x_rms, v_rms)
    drive = _Drive(rig, np.random.default_rng(rng_seed), n)
    states = _integrate(rig, drive, force, n, noise)
    return states, drive.recorded(n), noise, params, linear


def generate_rig_case(
    effect: str,
    seed: int,
    *,
    magnitude: float | None = None,
    n_samples: int | None = None,
    samples_per_period: float | None = None,
) -> GeneratedCase:
    """Generate one rig recording (``t, u_act, x``) with a withheld plant effect, or none.

    Parameters
    ----------
    effect : str
        One of :data:`RIG_EFFECTS`.
    seed : int
        Seed of every draw.
    magnitude : float, optional
        0 (faint) to 1 (strong); drawn uniformly when None.
    n_samples : int, optional
        Default :data:`RIG_SAMPLES`.
    samples_per_period : float, optional
        The resonance's samples per period (drawn in 3–1000 when None; a closed loop needs at
        least 15 and draws a larger one).

    Returns
    -------
    GeneratedCase
        ``recording`` (``t`` s, ``u_act`` and ``x`` in the rig's units), ``twin`` (``dt``
        only: the plant must be calibrated) and ``key`` (the truth, parameters in recording
        units).
    """
    if effect not in RIG_EFFECTS:
        raise DtwinValueError(
            f"rig effect must be one of {', '.join(RIG_EFFECTS)} (got {effect!r})"
        )
    rng = np.random.default_rng(seed)
    rig = _draw_rig(rng, effect, samples_per_period)
    return _generate(rig, rng, effect, seed, magnitude, int(n_samples or RIG_SAMPLES))


def generate_hard_rig_case(
    effect: str,
    seed: int,
    *,
    magnitude: float | None = None,
    n_samples: int | None = None,
    samples_per_period: float | None = None,
) -> GeneratedCase:
    """Generate one recording of the harder rig family (docs/gap.md §Rig family).

    Like :func:`generate_rig_case`, but: the force is held over each sample (a DAC) in open
    loop too; damping ratio 0.01–0.3 and 3–30 periods of the resonance in the record
    (3000–20,000 samples); AR(1) measurement noise (pole 0.5–0.95, 0.5–3 % of the position's
    spread); units 10^U(−3, 3) on both channels; 40 % integrating plants (always in a PD
    loop); and ``stribeck_friction``: ``(Fc + (Fs − Fc)·exp(−(v/vs)²))·sign(v)``, ``Fs`` 1.5–3
    ``Fc``, ``vs`` 0.05–0.3 of std(v). Parameters as in :func:`generate_rig_case`
    (``effect`` one of :data:`HARD_RIG_EFFECTS`; ``n_samples`` overrides the drawn length).

    Returns
    -------
    GeneratedCase
        As :func:`generate_rig_case`; the key's ``arm`` is ``"hard"``.
    """
    if effect not in HARD_RIG_EFFECTS:
        raise DtwinValueError(
            f"hard rig effect must be one of {', '.join(HARD_RIG_EFFECTS)} (got {effect!r})"
        )
    rng = np.random.default_rng(seed)
    rig = _draw_hard_rig(rng, effect, samples_per_period)
    case = _generate(rig, rng, effect, seed, magnitude, int(n_samples or rig["n_samples"]))
    case.key.update(arm="hard", noise_pole=rig["noise_pole"], periods=rig["periods"])
    return case


def _generate(rig, rng, effect, seed, magnitude, n) -> GeneratedCase:
    """Simulate a drawn rig with its effect and return the case in recording units."""
    magnitude = float(rng.uniform()) if magnitude is None else float(magnitude)
    low, high = RIG_FORCES[effect].strength if effect in RIG_FORCES else (0.0, 0.0)
    strength = low * (high / low) ** magnitude if high else 0.0
    states, force, noise, params, linear = _run(rig, seed + 1, effect, strength, n)
    u_rec, x_rec = _to_recording_units(rig, rng, force, states[:, 0] + noise)
    if effect in RIG_FORCES and "x0" in effect_by_name(effect).params:
        params["x0"] = rig["x_offset_phys"]  # the catalogue form's centre: the position's offset
    t = np.arange(n) * rig["dt"]
    recording = pd.DataFrame({"t": t, "u_act": u_rec, "x": x_rec})
    contribution = float(np.std(states[:, 0] - linear[:, 0]))
    key = _rig_key(effect, seed, magnitude, rig, params, n)
    key["snr"] = contribution / float(np.std(noise)) if effect != "none" else 0.0
    return GeneratedCase(recording=recording, twin={"twin": {"dt": rig["dt"]}}, key=key)


def _to_recording_units(rig, rng, force, x) -> tuple[np.ndarray, np.ndarray]:
    u_off = rng.uniform(-0.5, 0.5) * float(np.std(force))
    x_off = rng.uniform(-2.0, 2.0) * float(np.std(x))
    rig["u_offset_phys"], rig["x_offset_phys"] = u_off, x_off
    return rig["u_scale"] * (force + u_off), rig["x_scale"] * (x + x_off)


def _rig_key(effect, seed, magnitude, rig, params, n) -> dict:
    """Return the truth of a rig case, parameters converted to recording units."""
    us, xs = rig["u_scale"], rig["x_scale"]
    per_unit = {
        "m": us / xs,
        "c": us / xs,
        "k": us / xs,
        "Fc": us,
        "k3": us / xs**3,
        "x0": xs,
        "c2": us / xs**2,
        "Fs": us,
        "vs": xs,
    }
    plant = {name: value * per_unit[name] for name, value in rig["plant"].items()}
    # m·ẍ + c·ẋ + k·x = u − u_offset in recording units: the force offset and, through the
    # spring, the position offset (an integrating plant's position offset is its start)
    u_offset = us * (rig["u_offset_phys"] - rig["plant"]["k"] * rig["x_offset_phys"])
    return {
        "family": "rig",
        "arm": "rig",
        "effect": effect,
        "module": "M1",
        "expected_effect": effect,
        "accepted_effects": accepted_effects(effect, params),
        "in_list": effect != "none",
        "magnitude": magnitude,
        "seed": seed,
        "n_samples": n,
        "params": {name: value * per_unit[name] for name, value in params.items()},
        "plant": plant,
        "u_offset": u_offset,
        "samples_per_period": rig["samples_per_period"],
        "zeta": rig["zeta"],
        "integrating": rig["integrating"],
        "closed_loop": rig["closed_loop"],
        "dt": rig["dt"],
        "u_scale": us,
        "x_scale": xs,
    }


def generate_any_case(case_type: str, seed: int, **paper_options) -> GeneratedCase:
    """Generate a benchmark case: a rig family's, another physics' family's, else the paper's.

    Prefixes ``rig_``, ``hardrig_`` (this module); ``tanks_``, ``motor_``, ``thermal_``,
    ``battery_`` (:mod:`dtwin.gapbench.families`); anything else is the paper asset's case type.
    A paper-asset case type may carry an arm (``no_noise__none``, dtwin/gapbench/arms.py).
    ``paper_options`` go to :func:`dtwin.gapbench.generator.generate_case` (``nominal``, the
    nominal twin, is needed; ``miscalibration``, ``noise_error``); the other families have none.
    """
    if case_type.startswith(FAMILY_PREFIXES):
        return generate_family_case(case_type, seed)
    if case_type.startswith(RIG_PREFIX):
        return generate_rig_case(case_type[len(RIG_PREFIX) :], seed)
    if case_type.startswith(HARD_RIG_PREFIX):
        return generate_hard_rig_case(case_type[len(HARD_RIG_PREFIX) :], seed)
    return generate_case(case_type, seed, **paper_options)
