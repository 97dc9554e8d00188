"""The benchmark's arms: conditions and effect forms that do not flatter the gap diagnoser.

Specification: this docstring (docs/gap.md §Benchmark describes the benchmark around it).

The default cases of :mod:`dtwin.gapbench.generator` give the diagnoser the twin's true noise levels
(±10 %), the plant's exact state, an asset that is the twin's own recursion and effects in the
catalogue's families. Each *arm* takes one of these away (a case type ``<arm>__<effect>``):

====================  =============================================================================
arm                   condition (expected answer)
====================  =============================================================================
``no_noise``          (a) the twin file has no ``noise`` section (the effect, or ``none``)
``wrong_noise``       (b) every noise level in the twin file off by exactly 25 %, up or down
``noisy_x``           (c) ``x`` recorded through a position sensor with white noise of 1 % of its
                      standard deviation; no ``v`` or ``z`` columns
``continuous``        (d) a continuous-time asset: actuator lag and plant integrated by classical
                      Runge-Kutta at dt/20, sensor lags on the continuous position; the twin file
                      names no ``discretisation`` (the asset is no recursion)
``unseen``            (e) effect forms from families the catalogue does not use
                      (:data:`UNSEEN_FORMS`: Stribeck friction with a generalised exponent,
                      an asymmetric tanh saturation, a dead zone one side 0.2–0.6 of the other,
                      a quintic spring, a delay with i.i.d. jitter, stick-slip friction; the
                      answer is the nearest catalogue effect)
``near``              (f) near-catalogue effects outside the list (:data:`NEAR_CATALOGUE`:
                      actuator backlash and rate limit, sensor hysteresis, a cogging force
                      periodic in the position; the answer is ``unexplained``)
``two``               (g) two effects in two modules (``<effect>+<effect>``; the answer is the
                      one with the larger signal-to-noise ratio)
``harder``            (h) (c) and (d) at once, with (a) or (b): the continuous asset, ``x``
                      recorded through a position sensor with AR(1) noise (pole uniform in
                      :data:`HARDER_X_POLES`, standard deviation 1 % of std(x)), no ``v`` or
                      ``z`` columns and no ``discretisation``; the twin file's noise levels
                      absent or every one off by 25 % (one of the two per case, even odds)
====================  =============================================================================

This module holds the arms' effect forms, their draws and the continuous asset; the generator
places them in the asset. Arrays are time-first, shape ``(n_samples,)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.signal import lfilter

from dtwin.gapbench.case_effects import CaseEffect, log_between, spec_value
from dtwin.twin.paper_modules import lag_coefficient
from dtwin.twin.wiring import ACTUATOR, role_of

__all__ = [
    "ARMS",
    "ARM_SEPARATOR",
    "DEFAULT_ARM",
    "UNSEEN_FORMS",
    "NEAR_CATALOGUE",
    "FRICTION_FAMILY",
    "TWO_EFFECT_PAIRS",
    "WRONG_NOISE_ERROR",
    "NOISY_X_FRACTION",
    "HARDER_X_POLES",
    "CONTINUOUS_SUBSTEPS",
    "split_case_type",
    "unseen_expected",
    "ARM_CASE_EFFECTS",
    "hysteresis_offset",
    "stiction_plant",
    "continuous_chain",
]

#: The arm of a case whose type carries no ``<arm>__`` prefix.
DEFAULT_ARM = "default"
#: Separator between an arm and an effect in a case type (``no_noise__coulomb_friction``).
ARM_SEPARATOR = "__"
#: The arms and what each takes away (see the module docstring).
ARMS: dict[str, str] = {
    "no_noise": "(a) no noise levels in the twin file",
    "wrong_noise": "(b) noise levels in the twin file off by ±25 %",
    "noisy_x": "(c) x through a noisy sensor, no v or z columns",
    "continuous": "(d) continuous-time asset (Runge-Kutta at dt/20)",
    "unseen": "(e) effect forms outside the catalogue's families",
    "near": "(f) near-catalogue out-of-list effects",
    "two": "(g) two effects at once",
    "harder": "(h) continuous asset, AR(1)-coloured noise on x, noise levels absent or ±25 %",
}
#: Relative error of every noise level in a ``wrong_noise`` twin file (sign drawn per level).
WRONG_NOISE_ERROR = 0.25
#: Standard deviation of the ``noisy_x`` position sensor's white noise, over std(x) (also the
#: ``harder`` arm's coloured noise).
NOISY_X_FRACTION = 0.01
#: Range of the AR(1) pole of the ``harder`` arm's noise on ``x`` (a sensor's anti-aliasing
#: filter or slow drift).
HARDER_X_POLES = (0.5, 0.8)
#: Runge-Kutta sub-steps per sample of the ``continuous`` asset.
CONTINUOUS_SUBSTEPS = 20

#: ``unseen`` effects: the modules they may sit in and the nearest catalogue effect per module
#: (the expected answer).
UNSEEN_FORMS: dict[str, dict[str, str]] = {
    "stribeck_friction": {"M1": "stribeck_friction"},
    "smooth_saturation": {"M0": "actuator_saturation"},
    "asymmetric_deadzone": {"M0": "actuator_deadzone"},
    "quintic_stiffness": {"M1": "cubic_stiffness"},
    "jittered_delay": {"M0": "actuator_delay", "M2a": "sensor_delay", "M2b": "sensor_delay"},
    "stiction": {"M1": "stribeck_friction"},
}
#: Catalogue effects that are also right for a truth with a breakaway force (``Fs > Fc``):
#: Coulomb friction is Stribeck friction without its bump, which a faint or fast motion
#: cannot show (docs/gap.md §Candidate effects).
FRICTION_FAMILY: tuple[str, ...] = ("coulomb_friction", "stribeck_friction")
#: ``near`` effects (answer ``unexplained``) and the modules they may sit in.
NEAR_CATALOGUE: dict[str, tuple[str, ...]] = {
    "backlash": ("M0",),
    "rate_limit": ("M0",),
    "hysteresis": ("M2a", "M2b"),
    "cogging": ("M1",),
}
#: ``two`` arm: pairs of catalogue effects, always in different modules. Most pair modules
#: whose signal-to-noise ratios are alike (actuator and plant, the two sensors), so that either
#: may be the larger; one pairs a plant effect with a (usually much smaller) sensor one.
TWO_EFFECT_PAIRS: tuple[tuple[str, str], ...] = (
    ("coulomb_friction", "sensor_bias_drift"),
    ("actuator_saturation", "quadratic_damping"),
    ("actuator_deadzone", "cubic_stiffness"),
    ("actuator_delay", "coulomb_friction"),
    ("sensor_bias_drift", "sensor_scale_error"),
    ("sensor_delay", "sensor_quantization"),
)


def split_case_type(case_type: str) -> tuple[str, str]:
    """Return ``(arm, effect)`` of a case type ``[<arm>__]<effect>`` (no prefix: the default arm).

    Examples
    --------
    >>> split_case_type("no_noise__none"), split_case_type("none")
    (('no_noise', 'none'), ('default', 'none'))
    """
    arm, sep, effect = case_type.partition(ARM_SEPARATOR)
    return (arm, effect) if sep else (DEFAULT_ARM, case_type)


def unseen_expected(effect: str, module: str) -> str:
    """Return the catalogue effect nearest to an ``unseen`` form in ``module`` (the answer)."""
    return UNSEEN_FORMS[effect][module]


# --- draws: (module, level, rng, scale) -> the real effect's form and parameters ---------------


def _draw_stribeck(module, level, rng, scale) -> dict[str, Any]:
    """Stribeck friction: ``(Fc + (Fs − Fc)·exp(−|v/vs|^δ))·sign(v) + c_v·v`` (N)."""
    fc = log_between(0.012, 0.2, level) * scale["u_max"]
    return {
        "form": "stribeck",
        "Fc": fc,
        "Fs": fc * rng.uniform(1.5, 3.0),
        "vs": rng.uniform(0.05, 0.4) * scale["v_std"],
        "delta": rng.uniform(0.5, 2.0),
        "viscous": rng.uniform(0.0, 0.1),
    }


def _draw_smooth_saturation(module, level, rng, scale) -> dict[str, Any]:
    """Asymmetric tanh saturation ``U·tanh(u/U)``, ``U_high`` above 0, ``U_low`` below (u units).

    Not the catalogue's ``u/(1 + |u/U|^p)^(1/p)`` for any sharpness ``p``, and asymmetric.
    """
    high = log_between(1.6, 0.5, level) * scale["u_max"]
    low = high * rng.uniform(1.0, 1.4)
    if rng.uniform() < 0.5:
        high, low = low, high
    return {"form": "asymmetric tanh", "U_high": high, "U_low": low}


def _draw_asymmetric_deadzone(module, level, rng, scale) -> dict[str, Any]:
    """Dead zone ``[−D_low, D_high]``, one side 0.2–0.6 of the other (u units).

    The catalogue's dead zone is symmetric; the generator's default cases stay within 0.6–1.
    """
    wide = log_between(0.05, 0.3, level) * scale["u_std"]
    narrow = wide * rng.uniform(0.2, 0.6)
    high, low = (wide, narrow) if rng.uniform() < 0.5 else (narrow, wide)
    return {"form": "asymmetric", "D_high": high, "D_low": low}


def _draw_quintic(module, level, rng, scale) -> dict[str, Any]:
    """Quintic hardening spring ``ratio·k·x_ref·(x/x_ref)^5`` (N)."""
    return {
        "form": "x^5 hardening",
        "ratio": log_between(0.08, 1.0, level),
        "x_ref": scale["x_max"],
    }


def _draw_jittered_delay(module, level, rng, scale) -> dict[str, Any]:
    """Delay of ``delay_samples`` with i.i.d. jitter uniform in ±``jitter`` samples."""
    low, high = (0.8, 6.0) if role_of(module) == ACTUATOR else (4.0, 15.0)
    delay = log_between(low, high, level)
    jitter = rng.uniform(0.25, 0.75) * min(delay, 2.0)
    return {
        "form": "jittered",
        "delay_samples": delay,
        "jitter": jitter,
        "jitter_seed": int(rng.integers(2**31)),
    }


def _draw_backlash(module, level, rng, scale) -> dict[str, Any]:
    """Backlash (play) of half-width ``b`` on the actuator's command (u units)."""
    return {"form": "play operator", "b": log_between(0.03, 0.3, level) * scale["u_std"]}


def _draw_rate_limit(module, level, rng, scale) -> dict[str, Any]:
    """Rate limit ``rate`` (u units per second) on the actuator's command."""
    return {"form": "slew limit", "rate": log_between(25.0, 2.5, level) * scale["u_std"]}


def _draw_hysteresis(module, level, rng, scale) -> dict[str, Any]:
    """Sensor hysteresis: an offset ``±H`` that follows the direction of motion over ``width``."""
    return {
        "form": "Duhem",
        "H": log_between(1.5, 8.0, level) * scale["sigma"],
        "width": rng.uniform(0.05, 0.25) * scale["x_std"],
    }


def _draw_cogging(module, level, rng, scale) -> dict[str, Any]:
    """Cogging: a force ``A·sin(2π·x/period + phase)`` periodic in the position (N)."""
    return {
        "form": "sinusoidal in x",
        "A": log_between(0.02, 0.25, level) * scale["u_max"],
        "period": rng.uniform(0.2, 0.5) * scale["x_std"],
        "phase": rng.uniform(0.0, 2 * math.pi),
    }


def _draw_stiction(module, level, rng, scale) -> dict[str, Any]:
    """Stiction: breakaway force ``Fs``, sliding friction ``Fc = ratio·Fs`` (N)."""
    fs = log_between(0.02, 0.25, level) * scale["u_max"]
    return {"form": "stick-slip", "Fs": fs, "Fc": fs * rng.uniform(0.2, 0.5)}


# --- forms ---------------------------------------------------------------------------------


def _jittered_delay(u: np.ndarray, spec: Mapping[str, Any]) -> np.ndarray:
    """Return ``u`` read ``delay + jitter_k`` samples late (linear interpolation), ``(n,)``."""
    n = len(u)
    jitter = np.random.default_rng(spec["jitter_seed"]).uniform(-1.0, 1.0, n) * spec["jitter"]
    at = np.arange(n) - np.maximum(spec["delay_samples"] + jitter, 0.0)
    return np.interp(at, np.arange(n), u)


def _play(u: np.ndarray, half_width: float) -> np.ndarray:
    out = np.empty(len(u))
    last = float(u[0])
    for k, value in enumerate(u):
        if value - last > half_width:
            last = value - half_width
        elif last - value > half_width:
            last = value + half_width
        out[k] = last
    return out


def _slew(u: np.ndarray, max_step: float) -> np.ndarray:
    out = np.empty(len(u))
    last = float(u[0])
    for k, value in enumerate(u):
        last += min(max(value - last, -max_step), max_step)
        out[k] = last
    return out


def _smooth_saturation(u: np.ndarray, spec: Mapping[str, Any], dt: float) -> np.ndarray:
    level = np.where(u >= 0, spec["U_high"], spec["U_low"])
    return level * np.tanh(u / level)


def _asymmetric_deadzone(u: np.ndarray, spec: Mapping[str, Any], dt: float) -> np.ndarray:
    high, low = spec["D_high"], spec["D_low"]
    return np.where(u > high, u - high, np.where(u < -low, u + low, 0.0))


def _jittered_command(u: np.ndarray, spec: Mapping[str, Any], dt: float) -> np.ndarray:
    return _jittered_delay(u, spec)


def _backlash(u: np.ndarray, spec: Mapping[str, Any], dt: float) -> np.ndarray:
    return _play(u, spec["b"])


def _rate_limit(u: np.ndarray, spec: Mapping[str, Any], dt: float) -> np.ndarray:
    return _slew(u, spec["rate"] * dt)


def hysteresis_offset(x: np.ndarray, spec: Mapping[str, Any]) -> np.ndarray:
    """Return a sensor's hysteresis offset, shape ``(n,)`` (output units).

    Duhem model: ``h[k] = h[k−1] + min(1, |Δx_k|/width)·(H·sign(Δx_k) − h[k−1])``; the offset
    moves towards ``+H`` while the position rises and ``−H`` while it falls.
    """
    out = np.zeros(len(x))
    steps = np.diff(x)
    gains = np.minimum(1.0, np.abs(steps) / spec["width"])
    targets = spec["H"] * np.sign(steps)
    h = 0.0
    for k in range(1, len(x)):
        h += gains[k - 1] * (targets[k - 1] - h)
        out[k] = h
    return out


def _stribeck_force(spec: Mapping[str, Any], c: float, k: float, min_smoothing: float = 0.0):
    """Stribeck friction with a generalised exponent; its sign smoothed over ``10⁻³·vs`` or more."""
    fc, fs, vs = spec["Fc"], spec["Fs"], spec["vs"]
    smooth = max(1e-3 * vs, min_smoothing)
    return "generalised_stribeck", (fc, fs - fc, vs, spec["delta"], smooth, spec["viscous"])


def _quintic_force(spec: Mapping[str, Any], c: float, k: float, min_smoothing: float = 0.0):
    ratio, ref = spec["ratio"], spec["x_ref"]
    return "power_spring", (ratio * k * ref, ref, 5.0)


def _cogging_force(spec: Mapping[str, Any], c: float, k: float, min_smoothing: float = 0.0):
    return "sine_in_position", (spec["A"], 2 * math.pi / spec["period"], spec["phase"])


def _hysteresis_reading(y, spec: Mapping[str, Any], t, x) -> np.ndarray:
    return y + hysteresis_offset(x, spec)


def _stiction(u, m, c, k, dt, noise, spec, n) -> tuple[np.ndarray, np.ndarray]:
    return stiction_plant(u[:n], m, c, k, dt, noise[:n], spec)


def stiction_plant(u, m, c, k, dt, noise, spec) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(x, v)`` of the Euler plant with stick-slip friction, each shape ``(n,)``.

    At rest the mass sticks until the applied force ``u − c·v − k·x + m·ξ`` exceeds ``Fs``;
    sliding, the friction is ``Fc·sign(v)``, and a velocity sign change sticks it again.
    Otherwise the paper's explicit Euler step (``dtwin.twin.paper_modules.plant_response``).
    """
    fs, fc = spec["Fs"], spec["Fc"]
    n = len(u)
    xs, vs = np.zeros(n), np.zeros(n)
    x, v, stuck = 0.0, 0.0, True
    for j in range(1, n):
        applied = u[j - 1] - c * v - k * x + m * noise[j]
        if stuck and abs(applied) <= fs:
            xs[j], vs[j] = x, 0.0
            continue
        direction = math.copysign(1.0, v if not stuck else applied)
        accel = (applied - fc * direction) / m
        x, v_new = x + dt * v, v + dt * accel
        stuck = v_new * direction <= 0.0
        v = 0.0 if stuck else v_new
        xs[j], vs[j] = x, v
    return xs, vs


#: The arms' effects (draws and real forms), by name.
ARM_CASE_EFFECTS: dict[str, CaseEffect] = {
    effect.name: effect
    for effect in (
        CaseEffect(
            "stribeck_friction", _draw_stribeck, force=_stribeck_force, truth=spec_value("Fc")
        ),
        CaseEffect("smooth_saturation", _draw_smooth_saturation, actuator=_smooth_saturation),
        CaseEffect("asymmetric_deadzone", _draw_asymmetric_deadzone, actuator=_asymmetric_deadzone),
        CaseEffect("quintic_stiffness", _draw_quintic, force=_quintic_force),
        CaseEffect(
            "jittered_delay",
            _draw_jittered_delay,
            actuator=_jittered_command,
            sensor_input=_jittered_delay,
        ),
        CaseEffect("backlash", _draw_backlash, actuator=_backlash),
        CaseEffect("rate_limit", _draw_rate_limit, actuator=_rate_limit),
        CaseEffect("hysteresis", _draw_hysteresis, reading=_hysteresis_reading),
        CaseEffect("stiction", _draw_stiction, plant=_stiction, truth=spec_value("Fc")),
        CaseEffect("cogging", _draw_cogging, force=_cogging_force),
    )
}


# --- the continuous asset -------------------------------------------------------------------


def _continuous_lag(x_fine: np.ndarray, tau: float, h: float, delay: float) -> np.ndarray:
    """First-order lag ``τ·ẏ = x(t − delay) − y`` on the sub-step grid (midpoint input)."""
    grid = np.arange(len(x_fine)) * h
    midpoints = np.interp(grid[1:] - h / 2 - delay, grid, x_fine, left=0.0)
    a = math.exp(-h / tau)
    return np.r_[0.0, lfilter([1 - a], [1.0, -a], midpoints)]


def continuous_chain(
    u_in: np.ndarray,
    asset: Mapping[str, Any],
    law: tuple[str, tuple[float, ...]] | None,
    act_noise: np.ndarray,
    accel_noise: np.ndarray,
    sensor_delays: Mapping[str, float],
    substeps: int = CONTINUOUS_SUBSTEPS,
) -> dict[str, np.ndarray]:
    """Return the continuous asset's ``u_act, x, v`` and the sensors' noise-free lags.

    Parameters
    ----------
    u_in : array, shape (n,)
        The actuator's input after its effect, held over each sample (a digital command).
    asset : mapping
        The asset's sections (``dt``, ``actuator.tau``, ``plant``, ``sensor_A/B.tau``).
    law : (str, tuple of float) or None
        The plant's extra force ``F(x, v)`` (N): a law of :data:`dtwin.twin._force_kernels.LAWS`
        and its parameters (a case effect's ``force``), None for none.
    act_noise, accel_noise : array, shape (n,)
        The Euler twin's per-step actuator noise ``w[j]`` (held on the lag's input as
        ``w[j]/(1 − a)``, the same step variance) and acceleration noise ``ξ[j]`` (m/s², held).
    sensor_delays : mapping
        ``{"A": s, "B": s}``: each sensor's transport delay, s. Half a sample is added: the
        twin's one-sample input delay is the sensor reading the position at the middle of the
        previous interval.
    substeps : int, default :data:`CONTINUOUS_SUBSTEPS`

    Returns
    -------
    dict
        ``u_act``, ``x``, ``v``, ``lag_A``, ``lag_B``, each shape ``(n,)`` at the samples.
    """
    dt = asset["dt"]
    tau = asset["actuator"]["tau"]
    p = asset["plant"]
    a = lag_coefficient(tau, dt)
    eta = np.asarray(act_noise) / (1 - a)
    from dtwin.twin._force_kernels import ForceLaw, rk4_chain  # numba (~0.5 s) only when run

    force = None if law is None else ForceLaw(*law)
    fine = rk4_chain(u_in, tau, p["m"], p["c"], p["k"], dt, eta, accel_noise, substeps, force)
    h = dt / substeps
    out = {"u_act": fine[::substeps, 0], "x": fine[::substeps, 1], "v": fine[::substeps, 2]}
    for which in ("A", "B"):
        tau_s = asset[f"sensor_{which}"]["tau"]
        lag = _continuous_lag(fine[:, 1], tau_s, h, dt / 2 + sensor_delays[which])
        out[f"lag_{which}"] = lag[::substeps]
    return out
