"""Generate "real" recordings with a withheld effect, for checking the gap diagnoser.

Specification: docs/gap.md §Generator.

:func:`generate_case` runs the paper's asset (§3.1) with one effect (or none, or one the
catalogue does not know) and returns the recording, the nominal twin file and a separate key
holding the truth, which the diagnoser never reads. It is deliberately unkind:

- the asset is slightly miscalibrated against the twin (``m, c, k`` and the three time
  constants each off by up to ``miscalibration``, 3 % by default) while the effect dominates;
- the noise levels written into the twin file are right only to ±10 %;
- the sensor noise is coloured (AR(1), lag-1 correlation up to 0.6);
- the effects' real forms differ from the catalogue's textbook ones and vary between cases:
  friction with a Stribeck bump, a smooth (tanh) or asymmetric saturation, an asymmetric dead
  zone, a stiffness that is not exactly cubic, damping that is not exactly quadratic, drifts
  that are not linear, fractional delays, a quantizer after the noise;
- strengths from barely above the noise (``magnitude`` 0) to strong (1), log-uniformly;
- excitation amplitudes and frequencies, and lengths of 1000–5000 samples, vary by case;
- out-of-list effects (``stiffness_change``: a mid-run change of k; ``sensor_interference``: a
  sinusoid on one sensor), which the diagnoser should call ``unexplained``.

The benchmark's *arms* (:mod:`dtwin.gapbench.arms`: case types ``<arm>__<effect>``) take away what
these default cases still give: the twin's noise levels, the exact state, the twin's own
discretisation, the catalogue's families of forms, a single effect. Every key carries its
``arm`` (``default`` here; the rig family's is ``rig``). The arms' extra draws come from a
second random stream, so a default case's recording does not depend on the arms.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError, require_in_range
from dtwin.command import make_command, time_axis
from dtwin.gap.effects import CATALOGUE_CASES, EFFECTS, NONE, UNEXPLAINED
from dtwin.gap.noise import plant_noise_gain
from dtwin.gapbench.arms import (
    ARM_CASE_EFFECTS,
    CONTINUOUS_SUBSTEPS,
    DEFAULT_ARM,
    FRICTION_FAMILY,
    HARDER_X_POLES,
    NEAR_CATALOGUE,
    NOISY_X_FRACTION,
    TWO_EFFECT_PAIRS,
    UNSEEN_FORMS,
    WRONG_NOISE_ERROR,
    continuous_chain,
    split_case_type,
    unseen_expected,
)
from dtwin.gapbench.case_effects import CaseEffect, log_between
from dtwin.params import CommandParams
from dtwin.twin.paper_modules import (
    CONTRACTS,
    Step,
    fuse,
    kpi,
    lag_coefficient,
    lag_response,
    plant_response,
    run_modules,
)
from dtwin.twin.wiring import (
    ACTUATOR,
    FUSION,
    KPI,
    PLANT,
    SENSOR,
    modules_with_role,
    only_module,
    role_of,
)

__all__ = [
    "accepted_effects",
    "MIN_MAGNITUDE",
    "IN_LIST_EFFECTS",
    "OUT_OF_LIST_EFFECTS",
    "ALL_CASE_EFFECTS",
    "ARM_EFFECTS",
    "NOMINAL_KEYS",
    "GeneratedCase",
    "generate_case",
    "case_spec",
]

#: Smallest magnitude a case may be asked for: each strength's log-uniform map extrapolated
#: three of its ranges below the faintest random case (a friction of 2.6e-6 of the largest
#: command, a drift of 0.012 of the noise: invisible).
MIN_MAGNITUDE = -3.0
#: Effects of the catalogue the generator can inject, with the module(s) they may sit in: every
#: catalogue effect in its modules, in the catalogue's order, but one that only widens another
#: (``nests``: Stribeck friction is drawn as Coulomb friction, whose real form has the bump).
IN_LIST_EFFECTS: dict[str, tuple[str, ...]] = {e.name: e.modules for e in EFFECTS if not e.nests}
#: Effects outside the catalogue: the right answer is ``unexplained`` in that module.
OUT_OF_LIST_EFFECTS: dict[str, tuple[str, ...]] = {
    "stiffness_change": modules_with_role(PLANT),
    "sensor_interference": modules_with_role(SENSOR),
}
#: Every case type, ``none`` included.
ALL_CASE_EFFECTS: tuple[str, ...] = (*IN_LIST_EFFECTS, *OUT_OF_LIST_EFFECTS, NONE)
#: The effects each arm may carry (dtwin/gapbench/arms.py); arms (a)–(d) change the conditions of
#: the catalogue's effects and ``none``, (e)–(g) the effects.
ARM_EFFECTS: dict[str, tuple[str, ...]] = {
    DEFAULT_ARM: ALL_CASE_EFFECTS,
    **{arm: (*IN_LIST_EFFECTS, NONE) for arm in ("no_noise", "wrong_noise", "noisy_x")},
    "continuous": (*IN_LIST_EFFECTS, NONE),
    "harder": (*IN_LIST_EFFECTS, NONE),
    "unseen": tuple(UNSEEN_FORMS),
    "near": tuple(NEAR_CATALOGUE),
    "two": tuple(f"{a}+{b}" for a, b in TWO_EFFECT_PAIRS),
}
#: The modules every effect (catalogue, out-of-list and the arms') may sit in.
_EFFECT_MODULES: dict[str, tuple[str, ...]] = {
    **IN_LIST_EFFECTS,
    **OUT_OF_LIST_EFFECTS,
    **{name: tuple(modules) for name, modules in UNSEEN_FORMS.items()},
    **NEAR_CATALOGUE,
}

#: The keys of the nominal twin a case is generated from, in the order of its twin file: ``dt``,
#: every module's section and ``noise`` (others, such as ``discretisation``, are left out: the
#: asset is the paper's explicit-Euler simulator and its twin file says so).
NOMINAL_KEYS: tuple[str, ...] = ("dt", *(c.section for c in CONTRACTS.values()), "noise")


def _nominal_twin(nominal: Mapping[str, Any]) -> dict[str, Any]:
    """Return a copy of the nominal twin's :data:`NOMINAL_KEYS`, in the mapping's own order.

    Raises :class:`~dtwin._validation.DtwinValueError` naming a missing key.
    """
    missing = [key for key in NOMINAL_KEYS if key not in nominal]
    if missing:
        raise DtwinValueError(f"nominal twin lacks {', '.join(missing)} (needs {NOMINAL_KEYS})")
    return {
        k: (dict(v) if isinstance(v, Mapping) else v)
        for k, v in nominal.items()
        if k in NOMINAL_KEYS
    }


@dataclass(frozen=True)
class GeneratedCase:
    """One generated case.

    Attributes
    ----------
    recording : pandas.DataFrame
        Columns ``t, u_cmd, u_act, x, v, y_A, y_B, y_fused, z`` (the recording's CSV).
    twin : dict
        The nominal twin file content (``{"twin": {...}}``).
    key : dict
        The truth: ``arm``, ``effect``, ``module``, ``expected_effect``, ``magnitude`` (0–1),
        ``snr`` (RMS of the effect's contribution to the module output over its noise floor),
        ``form`` and ``params`` of the real effect, and the asset's true parameters; an
        ``unseen`` case adds ``nearest_catalogue`` (``<form> -> <catalogue effect>``), a
        ``two`` case ``effects`` (each effect's module, magnitude, snr and params).
    """

    recording: pd.DataFrame
    twin: dict[str, Any]
    key: dict[str, Any] = field(repr=False)


def _ar1(rng: np.random.Generator, n: int, sigma: float, phi: float) -> np.ndarray:
    white = rng.standard_normal(n)
    out = np.empty(n)
    out[0] = white[0]
    scale = math.sqrt(1 - phi * phi)
    for k in range(1, n):
        out[k] = phi * out[k - 1] + scale * white[k]
    return sigma * out


def _draw_interference(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``sensor_interference``: a sinusoid of 1.5–6 σ at 0.8–8 Hz."""
    return {
        "form": "sinusoid",
        "amplitude": log_between(1.5, 6.0, level) * scale["sigma"],
        "freq_hz": rng.uniform(0.8, 8.0),
        "phase": rng.uniform(0, 2 * np.pi),
    }


def _draw_stiffness_change(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``stiffness_change``: k times ``factor`` from ``at_frac`` of the run on."""
    factor = (
        log_between(1.25, 2.5, level) if rng.uniform() < 0.7 else 1 / log_between(1.25, 2.0, level)
    )
    return {"form": "step in k", "factor": factor, "at_frac": rng.uniform(0.35, 0.65)}


def _draw_effect(effect, module, level, rng, scale) -> dict[str, Any]:
    """Return the real effect's form and parameters (its :class:`CaseEffect`'s draw).

    Parameters
    ----------
    effect, module : str
        The case's effect and the module it sits in.
    level : float in [0, 1]
        Magnitude, from barely above the noise (0) to strong (1), mapped log-uniformly.
    rng : numpy.random.Generator
        The case's generator (the draws of each form are in a fixed order).
    scale : dict
        Signal sizes of the clean run: ``u_max``, ``u_std``, ``x_max``, ``v_max``, ``v_std``,
        ``sigma`` (the sensor's noise standard deviation).
    """
    if effect not in CASE_EFFECTS:
        raise DtwinValueError(f"unknown case effect {effect!r}")
    return CASE_EFFECTS[effect].draw(module, level, rng, scale)


# --- the real forms of the out-of-list effects (the catalogue's sit in dtwin/gap/effects/) ------


def _stiffness_change(u, m, c, k, dt, noise, spec, n):
    """Return the plant run in two parts, the second from the change on with ``k·factor``."""
    at = int(spec["at_frac"] * n)
    x, v = plant_response(u[:at], m, c, k, dt, accel_noise=noise[:at])
    x2, v2 = plant_response(
        u[at - 1 : n],
        m,
        c,
        k * spec["factor"],
        dt,
        x0=x[-1],
        v0=v[-1],
        accel_noise=noise[at - 1 : n],
    )
    return np.concatenate([x, x2[1:]]), np.concatenate([v, v2[1:]])


def _interference(y, spec, t, x):
    return y + spec["amplitude"] * np.sin(2 * np.pi * spec["freq_hz"] * t + spec["phase"])


#: Every case effect by name: the catalogue's (:data:`dtwin.gap.effects.CATALOGUE_CASES`, each
#: in its effect's module), the out-of-list ones and the arms'; its draw and real form.
CASE_EFFECTS: dict[str, CaseEffect] = {
    **CATALOGUE_CASES,
    **{
        effect.name: effect
        for effect in (
            CaseEffect("sensor_interference", _draw_interference, reading=_interference),
            CaseEffect("stiffness_change", _draw_stiffness_change, plant=_stiffness_change),
            *ARM_CASE_EFFECTS.values(),
        )
    },
}


def _hook(spec: Mapping[str, Any], place: str):
    """Return the hook ``place`` of the module's effect (a :class:`CaseEffect` field), or None."""
    effect = CASE_EFFECTS.get(spec.get("effect"))
    return None if effect is None else getattr(effect, place)


def _actuator_input(u_cmd, spec, dt):
    """Return the command after the actuator's effect, before its lag, shape ``(n,)``."""
    form = _hook(spec, "actuator")
    return u_cmd if form is None else form(u_cmd, spec, dt)


def _actuator(u_cmd, tau, dt, noise, spec):
    u = _actuator_input(u_cmd, spec, dt)
    # the contract's lag, but the process noise enters inside the recursion (physics adds it by
    # superposition), a different rounding order: this loop stays so recordings keep their bits
    a = lag_coefficient(tau, dt)
    out = np.zeros(len(u))
    for k in range(1, len(u)):
        out[k] = a * out[k - 1] + (1 - a) * u[k - 1] + noise[k]
    return out


def _plant_force(spec, c, k, min_smoothing=0.0):
    """Return the real effect's plant force ``(law, params)`` (a :class:`CaseEffect`'s), or None.

    A friction's sign is smoothed over its own velocity scale, or ``min_smoothing`` if larger
    (the continuous asset's Runge-Kutta step needs it).
    """
    force = _hook(spec, "force")
    return None if force is None else force(spec, c, k, min_smoothing)


def _plant(u, m, c, k, dt, noise, spec, n):
    """Return ``(x, v)`` of the asset's plant: the contract's Euler plant with the effect's hook.

    An effect with a ``plant`` hook (stick-slip friction, a change of ``k``) runs the plant
    itself.
    """
    plant = _hook(spec, "plant")
    if plant is not None:
        return plant(u, m, c, k, dt, noise, spec, n)
    law = _plant_force(spec, c, k)
    force = None
    if law is not None:
        from dtwin.twin._force_kernels import ForceLaw, law_function  # numba only for a force

        force = law_function(ForceLaw(*law))
    x, v = plant_response(u[:n], m, c, k, dt, force=force, accel_noise=noise[:n])
    return x, v


def _sensor(x, tau, bias, dt, noise, spec, t):
    read = _hook(spec, "sensor_input")
    lag = lag_response(x if read is None else read(x, spec), lag_coefficient(tau, dt))
    return _sensor_output(lag, bias, noise, spec, t, x)


def _sensor_output(lag, bias, noise, spec, t, x):
    """Return the sensor's reading from its lag: gain, bias, noise and output effects."""
    gain, reading = _hook(spec, "sensor_gain"), _hook(spec, "reading")
    if gain is not None:
        lag = gain(lag, spec)
    y = lag + bias + noise
    return y if reading is None else reading(y, spec, t, x)


def _algebraic_steps(asset) -> dict[str, Step]:
    """Return the steps of the fusion (M3) and the KPI (M4) of ``asset``."""
    alpha, weights = asset["fusion"]["alpha"], asset["kpi"]
    return {
        "M3": lambda s: {"y_fused": fuse(s["y_A"], s["y_B"], alpha)},
        "M4": lambda s: {"z": kpi(s["x"], s["v"], weights["w1"], weights["w2"])},
    }


def _run(u_cmd, steps: Mapping[str, Step]) -> dict[str, np.ndarray]:
    """Return the asset's signals, each ``(n,)``, in :data:`dtwin.twin.wiring.SIGNALS` order."""
    return {"u_cmd": u_cmd, **run_modules(steps, {"u_cmd": u_cmd})}


def _run_asset(asset, u_cmd, noises, specs, t):
    """Return the signals of the sampled asset (the paper's Euler twin with the effects' hooks)."""
    dt = asset["dt"]
    p = asset["plant"]

    def sensor(which: str, module: str) -> Step:
        s = asset[f"sensor_{which}"]
        return lambda sig: {
            f"y_{which}": _sensor(
                sig["x"], s["tau"], s["bias"], dt, noises[which], specs[module], t
            )
        }

    def plant(sig):
        n = len(sig["u_cmd"])
        x, v = _plant(sig["u_act"], p["m"], p["c"], p["k"], dt, noises["plant"], specs["M1"], n)
        return {"x": x, "v": v}

    tau = asset["actuator"]["tau"]
    steps = {
        "M0": lambda sig: {
            "u_act": _actuator(sig["u_cmd"], tau, dt, noises["actuator"], specs["M0"])
        },
        "M1": plant,
        "M2a": sensor("A", "M2a"),
        "M2b": sensor("B", "M2b"),
        **_algebraic_steps(asset),
    }
    return _run(u_cmd, steps)


def _run_continuous_asset(asset, u_cmd, noises, specs, t):
    """Return the signals of the continuous asset (arm ``continuous``), each ``(n,)``.

    The command after the actuator's effect is held over each sample; actuator and plant are
    integrated together (:func:`dtwin.gapbench.arms.continuous_chain`), the sensors' lags on the
    continuous position; noise and the sensors' output effects are added at the samples.
    """
    dt = asset["dt"]
    p = asset["plant"]
    u_in = _actuator_input(u_cmd, specs["M0"], dt)
    h = dt / CONTINUOUS_SUBSTEPS
    friction = specs["M1"].get("Fs", specs["M1"].get("Fc", 0.0))
    law = _plant_force(specs["M1"], p["c"], p["k"], min_smoothing=2 * h * friction / p["m"])
    delays = {
        which: specs[module].get("delay_samples", 0.0) * dt
        if _hook(specs[module], "continuous_delay")
        else 0.0
        for which, module in (("A", "M2a"), ("B", "M2b"))
    }
    chain = continuous_chain(u_in, asset, law, noises["actuator"], noises["plant"], delays)

    def sensor(which: str, module: str) -> Step:
        bias = asset[f"sensor_{which}"]["bias"]
        return lambda sig: {
            f"y_{which}": _sensor_output(
                chain[f"lag_{which}"], bias, noises[which], specs[module], t, sig["x"]
            )
        }

    steps = {
        "M0": lambda sig: {"u_act": chain["u_act"]},
        "M1": lambda sig: {"x": chain["x"], "v": chain["v"]},
        "M2a": sensor("A", "M2a"),
        "M2b": sensor("B", "M2b"),
        **_algebraic_steps(asset),
    }
    return _run(u_cmd, steps)


#: The asset's parameters that are miscalibrated against the twin: the contract's parameters
#: of the recursions (time constants and ``m, c, k``), in module order.
_MISCALIBRATED = tuple((c.section, p) for c in CONTRACTS.values() for p in c.dynamic_params)

_MODULE_OUTPUT = {name: c.output for name, c in CONTRACTS.items()}


def generate_case(
    effect: str,
    seed: int,
    *,
    magnitude: float | None = None,
    module: str | None = None,
    n_samples: int | None = None,
    miscalibration: float = 0.03,
    noise_error: float = 0.10,
    nominal: Mapping[str, Any],
    arm: str = DEFAULT_ARM,
) -> GeneratedCase:
    """Generate one recording of the asset with a withheld effect.

    Parameters
    ----------
    effect : str
        One of :data:`ARM_EFFECTS` ``[arm]`` (:data:`ALL_CASE_EFFECTS` for the default arm),
        optionally prefixed ``<arm>__``.
    seed : int
        Seed of every random draw of the case.
    magnitude : float in [:data:`MIN_MAGNITUDE`, 1], optional
        Effect strength, from barely above the noise (0) to strong (1); default random in
        [0, 1]. Below 0 the same log-uniform map is extrapolated to fainter effects, down to
        invisible ones (a detection-power curve, :mod:`dtwin.gapbench.power`).
    module : str, optional
        Module for effects that may sit in several (sensors, ``parameter_mismatch``).
    n_samples : int, optional
        Length; default random in 1000–5000.
    miscalibration : float, default 0.03
        Largest relative error of the twin's ``m, c, k`` and time constants.
    noise_error : float, default 0.10
        Largest relative error of the noise levels written into the twin file.
    nominal : mapping
        The nominal twin: the ``twin:`` section of ``config/config.yaml`` (the paper's, which
        the rule ``gap_cases`` passes) or of a twin file; :data:`NOMINAL_KEYS` are needed, other
        keys are ignored.
    arm : str, default "default"
        The benchmark arm (:data:`dtwin.gapbench.arms.ARMS`), or ``"default"``.

    Returns
    -------
    GeneratedCase

    Examples
    --------
    >>> from pathlib import Path
    >>> import yaml, dtwin
    >>> config = Path(dtwin.__file__).parents[1] / "config" / "config.yaml"
    >>> paper = yaml.safe_load(config.read_text())["twin"]
    >>> case = generate_case("coulomb_friction", 3, magnitude=0.8, n_samples=1000, nominal=paper)
    >>> case.recording.shape, case.key["module"], case.key["expected_effect"]
    ((1000, 9), 'M1', 'coulomb_friction')
    """
    arm, effects = _check_case(effect, arm)
    rng = np.random.default_rng(seed)
    # the arms' own draws come from a second stream: the default cases keep their bits
    arm_rng = np.random.default_rng([int(seed), 16])
    nominal = _nominal_twin(nominal)
    level = (
        float(rng.uniform())
        if magnitude is None
        else require_in_range("magnitude", magnitude, MIN_MAGNITUDE, 1)
    )
    n = int(rng.integers(1000, 5001)) if n_samples is None else int(n_samples)
    # a noisy-position recording has no z: a KPI (M4) effect could not be seen at all
    no_z = only_module(KPI) if arm in _NOISY_X_ARMS else None
    module = module or _draw_module(effects[0], rng, no_z)
    dt = float(nominal["dt"])
    t = time_axis(n, dt)
    command, u_cmd = _excitation(rng, n, dt)
    asset = _miscalibrated_asset(nominal, rng, miscalibration)
    noise_true = dict(nominal["noise"])
    phis, noises = _draw_noises(rng, n, noise_true)
    run = _run_continuous_asset if arm in _CONTINUOUS_ARMS else _run_asset
    baseline = run(asset, u_cmd, noises, {m: {} for m in _MODULE_OUTPUT}, t)
    scale = _signal_scale(u_cmd, baseline, module, noise_true)
    specs = {m: {} for m in _MODULE_OUTPUT}
    placed = []
    if effects[0] != NONE:
        placed.append(
            (effects[0], module, level, _draw_effect(effects[0], module, level, rng, scale))
        )
    for second in effects[1:]:
        where = _draw_module(second, arm_rng, exclude=module)
        second_level = float(arm_rng.uniform())
        second_scale = _signal_scale(u_cmd, baseline, where, noise_true)
        params = _draw_effect(second, where, second_level, arm_rng, second_scale)
        placed.append((second, where, second_level, params))
    for name, where, _, params in placed:
        _place_effect(name, where, params, asset, nominal, specs)
    signals = run(asset, u_cmd, noises, specs, t)
    snrs = [
        _effect_snr(asset, nominal, u_cmd, noises, specs, signals, where, t, noise_true)
        if arm not in _CONTINUOUS_ARMS
        else _snr_against(signals, baseline, asset, where, noise_true)
        for _, where, _, _ in placed
    ]
    twin_file = _twin_file(nominal, noise_true, rng, noise_error)
    key = {
        **_expected(arm, effect, effects, placed, snrs),
        "magnitude": level,
        "snr": max(snrs) if snrs else None,
        "seed": int(seed),
        "n_samples": n,
        "params": placed[0][3] if placed else {},
        "asset": asset,
        "noise_true": noise_true,
        "noise_ar1_phi": phis,
        "command": command.__dict__,
    }
    if len(placed) > 1:
        key["effects"] = [
            {"effect": e, "module": m, "magnitude": lv, "snr": r, "params": p}
            for (e, m, lv, p), r in zip(placed, snrs, strict=True)
        ]
    frame = pd.DataFrame({"t": t, **signals})
    frame, twin_file, conditions = _apply_arm(arm, frame, twin_file, noise_true, arm_rng)
    return GeneratedCase(recording=frame, twin=twin_file, key={**key, **conditions})


def _check_case(effect: str, arm: str) -> tuple[str, list[str]]:
    """Return ``(arm, effects)`` after checking that ``effect`` belongs to ``arm``.

    ``effect`` may carry the arm as a prefix (``no_noise__none``); the ``two`` arm's effect is
    ``<effect>+<effect>`` (a pair of :data:`~dtwin.gapbench.arms.TWO_EFFECT_PAIRS`).
    """
    prefixed, bare = split_case_type(effect)
    if prefixed != DEFAULT_ARM:
        if arm not in (DEFAULT_ARM, prefixed):
            raise DtwinValueError(f"case type {effect!r} is of arm {prefixed!r}, not {arm!r}")
        arm, effect = prefixed, bare
    allowed = ARM_EFFECTS.get(arm)
    if allowed is None:
        raise DtwinValueError(f"arm must be one of {', '.join(ARM_EFFECTS)} (got {arm!r})")
    if effect not in allowed:
        raise DtwinValueError(
            f"effect of arm {arm!r} must be one of {', '.join(allowed)} (got {effect!r})"
        )
    return arm, effect.split("+")


def _draw_module(effect: str, rng: np.random.Generator, exclude: str | None = None) -> str | None:
    """Return a module ``effect`` may sit in (one draw when there are several), None for none.

    ``exclude`` (a two-effect case's first module) is left out of the choices.
    """
    choices = _EFFECT_MODULES.get(effect, (None,))
    if exclude is not None:
        choices = tuple(m for m in choices if m != exclude)
    return str(rng.choice(choices)) if choices[0] is not None else None


def _place_effect(effect, module, params, asset, nominal, specs) -> None:
    """Put a drawn effect into the asset (a parameter) or the module's spec (in place)."""
    change = CASE_EFFECTS[effect].asset
    if change is not None:
        change(asset, nominal, params)
    else:
        specs[module] = {"effect": effect, **params}


def accepted_effects(expected: str, params: Mapping[str, Any]) -> list[str]:
    """Return the answers that are right for a case: ``expected``, or either friction name.

    A friction with a breakaway force above its sliding one (``Fs > Fc``) is right as
    ``coulomb_friction`` or ``stribeck_friction`` (:data:`~dtwin.gapbench.arms.FRICTION_FAMILY`):
    Coulomb friction is Stribeck friction without its bump, which a faint effect or a fast
    motion does not show.
    """
    breakaway = float(params.get("Fs", 0.0)) > float(params.get("Fc", 0.0))
    if expected in FRICTION_FAMILY and breakaway:
        return list(FRICTION_FAMILY)
    return [expected]


def _expected(arm, case_effect, effects, placed, snrs) -> dict[str, Any]:
    """Return the answer key: arm, effect, module, expected and accepted effects, in_list.

    ``unseen``: the nearest catalogue effect (``nearest_catalogue`` names the mapping);
    ``near`` and out-of-list effects: ``unexplained``; ``two``: the effect with the larger
    signal-to-noise ratio, in its module.
    """
    if arm == "two":
        larger = int(np.argmax(snrs))
        effect, module = placed[larger][0], placed[larger][1]
        return {
            "arm": arm,
            "effect": case_effect,
            "module": module,
            "expected_effect": effect,
            "accepted_effects": accepted_effects(effect, placed[larger][3]),
            "expected_module": module,
            "in_list": True,
        }
    effect = effects[0]
    module = placed[0][1] if placed else None
    if arm == "unseen":
        expected = unseen_expected(effect, module)
    elif effect in IN_LIST_EFFECTS or effect == NONE:
        expected = effect
    else:
        expected = UNEXPLAINED
    key = {
        "arm": arm,
        "effect": effect,
        "module": module,
        "expected_effect": expected,
        "accepted_effects": accepted_effects(expected, placed[0][3] if placed else {}),
        "expected_module": module,
        "in_list": expected not in (NONE, UNEXPLAINED) or effect in IN_LIST_EFFECTS,
    }
    if arm == "unseen":
        key["nearest_catalogue"] = f"{effect} -> {expected}"
    return key


#: Arms whose asset is the continuous one (Runge-Kutta), and arms whose ``x`` is noisy.
_CONTINUOUS_ARMS = ("continuous", "harder")
_NOISY_X_ARMS = ("noisy_x", "harder")


def _apply_arm(arm, frame, twin_file, noise_true, rng) -> tuple[pd.DataFrame, dict, dict]:
    """Return the recording, twin file and key entries under the arm's condition (arms.py).

    The key entries: the ``harder`` arm's ``x_noise_pole`` and ``noise_levels``
    (``"absent"`` or ``"off_25"``); none for the other arms.
    """
    twin = dict(twin_file["twin"])
    conditions: dict[str, Any] = {}
    if arm == "harder":
        conditions["noise_levels"] = "absent" if rng.uniform() < 0.5 else "off_25"
        conditions["x_noise_pole"] = float(rng.uniform(*HARDER_X_POLES))
    if arm == "no_noise" or conditions.get("noise_levels") == "absent":
        del twin["noise"]
    elif arm == "wrong_noise" or conditions.get("noise_levels") == "off_25":
        twin["noise"] = {
            name: float(value * (1 + WRONG_NOISE_ERROR * (1 if rng.uniform() < 0.5 else -1)))
            for name, value in noise_true.items()
        }
    if arm in _NOISY_X_ARMS:
        x = frame["x"].to_numpy()
        sigma = NOISY_X_FRACTION * float(np.std(x))
        pole = conditions.get("x_noise_pole", 0.0)
        noise = _ar1(rng, len(x), sigma, pole) if pole else sigma * rng.standard_normal(len(x))
        frame = frame.drop(columns=["v", "z"]).assign(x=x + noise)
    if arm in _CONTINUOUS_ARMS:
        del twin["discretisation"]
    return frame, {"twin": twin}, conditions


def _excitation(rng: np.random.Generator, n: int, dt: float):
    """Return ``(command, u_cmd)``: random excitation settings and the command, shape ``(n,)``."""
    command = CommandParams(
        amp=float(rng.uniform(0.6, 1.6)),
        sine_amp=0.6,
        sine_freq_hz=float(rng.uniform(0.15, 0.35)),
        square_amp=0.4,
        square_freq_hz=float(rng.uniform(0.03, 0.08)),
        step_every_s=2.5,
        step_std=float(rng.uniform(0.1, 0.3)),
    )
    return command, make_command(n, dt, command, rng)


def _miscalibrated_asset(nominal, rng: np.random.Generator, miscalibration: float) -> dict:
    """Return the asset: the nominal twin with ``m, c, k`` and the time constants perturbed.

    Each is multiplied by ``1 + U(−miscalibration, miscalibration)``.
    """
    asset = {k: (dict(v) if isinstance(v, dict) else v) for k, v in nominal.items()}
    for section, name in _MISCALIBRATED:
        asset[section][name] *= 1 + rng.uniform(-miscalibration, miscalibration)
    return asset


def _draw_noises(rng: np.random.Generator, n: int, noise_true: Mapping[str, float]):
    """Return ``(phis, noises)``: the sensors' AR(1) coefficients and every noise, ``(n,)``.

    Process noises (``actuator``, ``plant``) are white with element 0 unused; sensor noises
    (``A``, ``B``) are AR(1) with lag-1 correlation ``phis[which]`` in [0, 0.6].
    """
    phis = {"A": float(rng.uniform(0.0, 0.6)), "B": float(rng.uniform(0.0, 0.6))}
    noises = {
        "actuator": np.r_[0.0, noise_true["actuator"] * rng.standard_normal(n - 1)],
        "plant": np.r_[0.0, noise_true["plant"] * rng.standard_normal(n - 1)],
        "A": _ar1(rng, n, noise_true["sensor_A"], phis["A"]),
        "B": _ar1(rng, n, noise_true["sensor_B"], phis["B"]),
    }
    return phis, noises


def _signal_scale(u_cmd, baseline, module, noise_true) -> dict[str, float]:
    """Return the clean run's signal sizes that set an effect's strength (see _draw_effect)."""
    n = len(u_cmd)
    role = None if module is None else role_of(module)
    # the sensor's own noise; the last sensor's for another module (its effects read no sigma)
    channel = CONTRACTS[module if role == SENSOR else modules_with_role(SENSOR)[-1]].noise
    commanded = u_cmd if role == ACTUATOR else baseline["u_act"]
    return {
        # sizes from the first half, so that the effect shows in a default training part
        "u_max": float(np.max(np.abs(commanded[: n // 2]))),
        "u_std": float(np.std(u_cmd)),
        "x_max": float(np.max(np.abs(baseline["x"]))),
        "x_std": float(np.std(baseline["x"])),
        "v_max": float(np.max(np.abs(baseline["v"]))),
        "v_std": float(np.std(baseline["v"])),
        "sigma": noise_true[channel],
    }


def _effect_snr(asset, nominal, u_cmd, noises, specs, signals, module, t, noise_true) -> float:
    """Return the RMS of the effect's contribution over the module's noise floor.

    The floors are those of docs/gap.md §Noise floors for the asset's true parameters; M3 and
    M4 (no noise) use 1 % of the output's standard deviation.
    """
    contribution = _effect_contribution(asset, nominal, u_cmd, noises, specs, signals, module, t)
    return float(
        np.sqrt(np.mean(contribution**2)) / _module_floor(asset, module, signals, noise_true)
    )


def _module_floor(asset, module, signals, noise_true) -> float:
    """Return the module's noise floor for the asset's true parameters (output units)."""
    dt = asset["dt"]
    role = role_of(module)
    if role == ACTUATOR:
        return noise_true["actuator"] / math.sqrt(1 - math.exp(-2 * dt / asset["actuator"]["tau"]))
    if role == PLANT:
        return noise_true["plant"] * plant_noise_gain(**asset["plant"], dt=dt)[0]
    if role == SENSOR:
        return noise_true[CONTRACTS[module].noise]
    return float(np.std(signals[_MODULE_OUTPUT[module]])) * 0.01


def _snr_against(signals, baseline, asset, module, noise_true) -> float:
    """Return the RMS of ``signals − baseline`` at ``module``'s output over its noise floor.

    The continuous asset's signal-to-noise ratio: the run without the effect (and before a
    parameter mismatch) is the same asset with the same noise; floors as :func:`_effect_snr`.
    """
    out = _MODULE_OUTPUT[module]
    contribution = signals[out] - baseline[out]
    return float(
        np.sqrt(np.mean(contribution**2)) / _module_floor(asset, module, signals, noise_true)
    )


def _twin_file(nominal, noise_true, rng: np.random.Generator, noise_error: float) -> dict:
    """Return the twin file's content: the nominal twin, noise levels off by ±``noise_error``."""
    twin_noise = {
        k: float(v * (1 + rng.uniform(-noise_error, noise_error))) for k, v in noise_true.items()
    }
    sections = {k: v for k, v in nominal.items() if k != "noise"}
    # the asset is the paper's explicit-Euler simulator, and its twin says so
    return {"twin": {**sections, "noise": twin_noise, "discretisation": "euler"}}


def _effect_contribution(asset, nominal, u_cmd, noises, specs, signals, module, t):
    """RMS contribution of the effect to its module's output, the module driven identically."""
    out = _MODULE_OUTPUT[module]
    dt = asset["dt"]
    role = role_of(module)
    if role == ACTUATOR:
        other = _actuator(u_cmd, asset["actuator"]["tau"], dt, noises["actuator"], {})
        return signals[out] - other
    if role == PLANT:
        p = asset["plant"]
        other, _ = _plant(signals["u_act"], p["m"], p["c"], p["k"], dt, noises["plant"], {}, len(t))
        if not specs[module]:  # parameter mismatch: compare with the nominal plant
            q = nominal["plant"]
            other, _ = _plant(
                signals["u_act"], q["m"], q["c"], q["k"], dt, noises["plant"], {}, len(t)
            )
        return signals[out] - other
    if role == SENSOR:
        section = CONTRACTS[module].section  # sensor_A: its noise is noises["A"]
        s = asset[section] if specs[module] else nominal[section]
        other = _sensor(signals["x"], s["tau"], s["bias"], dt, noises[section[-1]], {}, t)
        return signals[out] - other
    if role == FUSION:
        return signals[out] - fuse(signals["y_A"], signals["y_B"], nominal["fusion"]["alpha"])
    k = nominal["kpi"]
    return signals[out] - kpi(signals["x"], signals["v"], k["w1"], k["w2"])


def case_spec(case: str, effects: Sequence[str], first_seed: int = 1000) -> dict[str, Any]:
    """Return ``{"case", "effect", "arm", "seed"}`` of a case name ``<effect>_<NN>``.

    ``effect`` is the case type as listed (``[<arm>__]<effect>``, or ``rig_<effect>``);
    ``arm`` is its arm (:func:`dtwin.gapbench.arms.split_case_type`; ``default`` without a prefix).

    The seed is ``first_seed + 1000·(index of effect in effects) + NN``, so adding cases keeps
    the earlier ones (docs/gap.md §Benchmark).

    Raises
    ------
    DtwinValueError
        If the name does not end in ``_<number>`` or its effect is not in ``effects``.
    """
    effect, _, number = case.rpartition("_")
    if not number.isdigit() or effect not in effects:
        raise DtwinValueError(
            f"case must be <effect>_<number> with effect in {', '.join(effects)} (got {case!r})"
        )
    index = list(effects).index(effect)
    return {
        "case": case,
        "effect": effect,
        "arm": split_case_type(effect)[0],
        "seed": int(first_seed) + 1000 * index + int(number),
    }
