"""The assets of the other-physics families: two tanks, a DC motor, a thermal network, a battery.

Specification: docs/gap.md §Benchmark. Each :class:`Family` holds one real asset's physics (its
states, derivative, state at rest and what its sensors read), the draw of its parameters and
excitation, the nominal twin it is modelled by (a ``modules:`` table,
docs/gap.md §Your own twin) and its withheld effects
(:mod:`dtwin.gapbench.family_effects`). The engine that integrates, records and keys a case
is :mod:`dtwin.gapbench.families`. A run starts from rest (empty tanks, a motor at
standstill, a body at ambient) when the input's first level is applied, as an experiment
does.

- ``tanks``: pump voltage ``u`` (V, 0–10) → pump lag → flow ``q`` (cm/s, as the upper tank's
  level rate) → upper tank ``h1`` (cm) → Torricelli orifice → lower tank ``h2`` (cm) →
  level sensor ``level = ks·h2 + b0`` (V); ``Ts`` 2–5 s.
- ``motor``: drive voltage ``V`` (V, bipolar) → armature ``i' = (V − R·i − Ke·w)/L`` (A) and
  rotor ``w' = (Kt·i − b·w)/J`` (rad/s), coupled through the back-EMF; ``Ts`` 0.5–2 ms.
- ``thermal``: heater command ``u`` (%, 0–100) → heater lag → power ``P`` (W) → two thermal
  nodes ``T1, T2`` (°C, ``C·T' = Σ flows``, ambient ``Ta``) → a lagging sensor ``y`` on
  ``T2`` (°C); ``Ts`` 1–5 s.
- ``battery``: current set-point ``I_set`` (A, bipolar, positive discharging) → cycler's
  current loop (lag) → current ``I`` → cell: state of charge ``soc' = −I/Q``, polarisation
  ``v1' = I/C1 − v1/(R1·C1)``, terminal voltage ``V = OCV(soc) − v1 − R0·I`` (V; an
  integrating state, an algebraic output with a nonlinear curve and a direct feed-through);
  ``Ts`` 0.5–2 s.

A derivative here is a plain-float closure ``f(t, x, u) -> list`` (``t`` s, ``x`` the state
list, ``u`` the input held over the sub-step), the fastest form the engine's Runge-Kutta loop
can call. Arrays are time-first.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtwin.gapbench.case_effects import log_between
from dtwin.gapbench.family_effects import (
    Context,
    FamilyEffect,
    Placed,
    input_deadzone,
    input_delay,
    input_saturation,
    output_bias_drift,
    output_delay,
    output_quantization,
    output_saturation,
    output_scale_error,
    parameter_drift,
    parameter_mismatch,
    parameter_step,
    rate_limiter,
    state_limit,
)

__all__ = ["Asset", "Family", "TANKS", "MOTOR", "THERMAL", "BATTERY"]

#: ``f(t, x, u) -> dx``: an asset's derivative on plain floats.
Derivative = Callable[[float, Sequence[float], float], list[float]]


@dataclass(frozen=True)
class Asset:
    """One drawn asset and its experiment.

    Attributes
    ----------
    dt : float
        Sampling step (s).
    u : numpy.ndarray, shape (n_samples,)
        The input, held over each sample (recording units).
    params : dict of str to float
        True params, by the twin's names (unique across the family's modules).
    tau_slow : float
        Slowest time constant (s).
    excitation : str
        The input's form (``steps``, ``steps+multisine``).
    """

    dt: float
    u: np.ndarray
    params: dict[str, float]
    tau_slow: float
    excitation: str

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(len(self.u))


@dataclass(frozen=True)
class Family:
    """One family of recordings: an asset's physics, its twin and its withheld effects.

    Attributes
    ----------
    name : str
        Case-type prefix without the underscore (``tanks``).
    input : str
        The recorded input column (noise-free: a command).
    internal : tuple of str
        Outputs recorded only with the internal signals.
    outputs : tuple of str
        Outputs always recorded.
    draw : callable
        ``draw(rng, n_samples) -> Asset`` (``n_samples`` None: drawn).
    states : callable
        ``states(placed) -> names``: the asset's states in integration order.
    derivative : callable
        ``derivative(params, placed) -> f(t, x, u)``.
    rest : callable
        ``rest(params, placed) -> x0``: the asset at rest (zero input), where a run starts.
    observe : callable
        ``observe(params, placed, X) -> {signal: (rows,)}`` from states ``X (rows, n_states)``.
    twin : callable
        ``twin(params) -> modules``: the ``modules:`` table with these params.
    effects : dict of str to FamilyEffect
        The withheld effects (``none`` apart).
    """

    name: str
    input: str
    internal: tuple[str, ...]
    outputs: tuple[str, ...]
    draw: Callable[[np.random.Generator, int | None], Asset]
    states: Callable[[Placed], tuple[str, ...]]
    derivative: Callable[[dict[str, float], Placed], Derivative]
    rest: Callable[[dict[str, float], Placed], list[float]]
    observe: Callable[[dict[str, float], Placed, np.ndarray], dict[str, np.ndarray]]
    twin: Callable[[dict[str, float]], dict[str, Any]]
    effects: dict[str, FamilyEffect]

    @property
    def noisy(self) -> tuple[str, ...]:
        """Every output a case may record (each with its own measurement noise)."""
        return (*self.internal, *self.outputs)


def _steps(
    rng: np.random.Generator, n: int, low: float, high: float, hold: tuple[float, float]
) -> np.ndarray:
    """Return random steps ``(n,)``: levels uniform in [low, high], each held ``hold`` samples.

    The second half plays the first half's steps (level and hold) again in another order, so
    both halves reach about the same extremes: an effect drawn to be reached in the training
    half is reached about as much in the rest.
    """
    low_hold, high_hold = max(int(hold[0]), 2), max(int(hold[1]), 3)
    steps, total = [], 0
    while total < n // 2:
        steps.append((rng.uniform(low, high), int(rng.integers(low_hold, high_hold + 1))))
        total += steps[-1][1]
    first = np.concatenate([np.full(length, level) for level, length in steps])[: n // 2]
    again = [steps[k] for k in rng.permutation(len(steps))] * 2
    second = np.concatenate([np.full(length, level) for level, length in again])
    return np.concatenate([first, second])[:n]


def _multisine(rng: np.random.Generator, n: int, dt: float, band: tuple[float, float]):
    """Return a multisine ``(n,)`` of unit peak, 12 lines log-spaced in ``band`` (Hz)."""
    freqs = np.exp(rng.uniform(math.log(band[0]), math.log(band[1]), 12))
    phases = rng.uniform(0.0, 2 * math.pi, 12)
    t = np.arange(n) * dt
    wave = np.sin(2 * math.pi * np.multiply.outer(t, freqs) + phases).sum(axis=1)
    return wave / (np.max(np.abs(wave)) or 1.0)


def _length(rng: np.random.Generator, low: int, high: int, n_samples: int | None) -> int:
    drawn = int(rng.integers(low, high + 1))
    return drawn if n_samples is None else int(n_samples)


# --- tanks ---------------------------------------------------------------------------------


def _draw_tanks(rng: np.random.Generator, n_samples: int | None) -> Asset:
    """Draw a two-tank process: orifices, pump, level sensor and random pump-voltage steps."""
    dt = rng.uniform(2.0, 5.0)
    n = _length(rng, 2000, 6000, n_samples)
    a1 = rng.uniform(0.04, 0.08)  # cm^0.5/s: q_out = a·sqrt(h)
    a2 = a1 * rng.uniform(0.8, 1.25)
    h_full = rng.uniform(20.0, 35.0)  # cm: the upper tank's level at u = 10 V
    params = {
        "tau": rng.uniform(4.0, 15.0),
        "kp": a1 * math.sqrt(h_full) / 10.0,
        "a1": a1,
        "a2": a2,
        "ks": rng.uniform(0.15, 0.35),
        "b0": rng.uniform(0.1, 0.6),
    }
    tau_slow = 2.0 * math.sqrt(0.5 * h_full) / min(a1, a2)
    u = _steps(rng, n, 0.0, 10.0, (0.3 * tau_slow / dt, 1.5 * tau_slow / dt))
    return Asset(dt, u, params, tau_slow, "steps")


def _tanks_states(placed: Placed) -> tuple[str, ...]:
    return ("q", "h1", "h2")


def _tanks_derivative(p: dict[str, float], placed: Placed) -> Derivative:
    tau, kp, a1, a2 = p["tau"], p["kp"], p["a1"], p["a2"]
    sqrt = math.sqrt

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        q, h1, h2 = x[0], x[1], x[2]
        out1 = a1 * sqrt(h1) if h1 > 0.0 else 0.0
        out2 = a2 * sqrt(h2) if h2 > 0.0 else 0.0
        return [(kp * u - q) / tau, q - out1, out1 - out2]

    return f


def _tanks_rest(p: dict[str, float], placed: Placed) -> list[float]:
    return [0.0, 0.0, 0.0]


def _tanks_observe(p: dict[str, float], placed: Placed, X: np.ndarray) -> dict[str, np.ndarray]:
    return {"q": X[:, 0], "h1": X[:, 1], "h2": X[:, 2], "level": p["ks"] * X[:, 2] + p["b0"]}


def _tanks_twin(p: dict[str, float]) -> dict[str, Any]:
    """Return the two-tank twin: pump (lag) → tanks (Torricelli equations) → sensor (gain)."""
    return {
        "pump": {
            "block": "lag",
            "inputs": ["u"],
            "outputs": ["q"],
            "params": {"tau": p["tau"], "gain": p["kp"]},
        },
        "tanks": {
            "inputs": ["q"],
            "outputs": ["h1", "h2"],
            "states": ["h1", "h2"],
            "params": {"a1": p["a1"], "a2": p["a2"]},
            "derivatives": {
                "h1": "q - a1*sqrt(max(h1, 0))",
                "h2": "a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))",
            },
        },
        "sensor": {
            "block": "gain",
            "inputs": ["h2"],
            "outputs": ["level"],
            "params": {"gain": p["ks"], "bias": p["b0"]},
        },
    }


TANKS = Family(
    name="tanks",
    input="u",
    internal=("q", "h1"),
    outputs=("level",),
    draw=_draw_tanks,
    states=_tanks_states,
    derivative=_tanks_derivative,
    rest=_tanks_rest,
    observe=_tanks_observe,
    twin=_tanks_twin,
    effects={
        "state_limit": FamilyEffect("state_limit", "tanks", "h1", state_limit("h1")),
        "input_saturation": FamilyEffect("input_saturation", "pump", "u", input_saturation()),
        "input_deadzone": FamilyEffect("input_deadzone", "pump", "u", input_deadzone()),
        "input_delay": FamilyEffect(
            "input_delay", "pump", "u", input_delay(), equivalent=("output_delay",)
        ),
        **{
            name: FamilyEffect(name, "sensor", "level", draw("level"))
            for name, draw in (
                ("output_saturation", output_saturation),
                ("output_bias_drift", output_bias_drift),
                ("output_quantization", output_quantization),
            )
        },
        "output_scale_error": FamilyEffect(  # the sensor's gain and bias scale alike
            "output_scale_error",
            "sensor",
            "level",
            output_scale_error("level"),
            equivalent=("parameter_mismatch",),
        ),
        "output_delay": FamilyEffect(
            "output_delay",
            "sensor",
            "level",
            output_delay("level"),
            equivalent=("input_delay",),
            equivalent_bare_only=True,
        ),
        "parameter_mismatch": FamilyEffect(
            "parameter_mismatch", "tanks", None, parameter_mismatch({"a1": "tanks", "a2": "tanks"})
        ),
        "rate_limiter": FamilyEffect("unexplained", "pump", "u", rate_limiter()),
        "clogging": FamilyEffect("unexplained", "tanks", "a2", parameter_drift("a2")),
    },
)


# --- motor ---------------------------------------------------------------------------------


def _draw_motor(rng: np.random.Generator, n_samples: int | None) -> Asset:
    """Draw a DC motor (armature and rotor) and a bipolar voltage: steps, or steps + multisine."""
    dt = rng.uniform(0.5e-3, 2e-3)
    n = _length(rng, 3000, 8000, n_samples)
    resistance = rng.uniform(0.5, 4.0)  # Ω
    constant = rng.uniform(0.02, 0.2)  # V·s/rad = N·m/A
    tau_m = rng.uniform(40.0, 250.0) * dt  # electromechanical time constant J·R/(Kt·Ke)
    params = {
        "R": resistance,
        "L": resistance * rng.uniform(2.0, 8.0) * dt,
        "Ke": constant,
        "Kt": constant,
        "J": tau_m * constant**2 / resistance,
        "b": rng.uniform(0.05, 0.3) * constant**2 / resistance,
    }
    v_max = rng.uniform(6.0, 24.0)
    steps = _steps(rng, n, -v_max, v_max, (0.5 * tau_m / dt, 3.0 * tau_m / dt))
    sines = _multisine(rng, n, dt, (0.2 / (2 * math.pi * tau_m), 5.0 / (2 * math.pi * tau_m)))
    mixed = rng.uniform() < 0.5
    u = 0.7 * steps + 0.3 * v_max * sines if mixed else steps
    return Asset(dt, u, params, tau_m, "steps+multisine" if mixed else "steps")


def _motor_states(placed: Placed) -> tuple[str, ...]:
    if "backlash" in placed.plant:
        return ("i", "w", "wl", "delta", "theta")
    return ("i", "w", "theta")


def _backlash_derivative(p: dict[str, float], lash: dict[str, float]) -> Derivative:
    """Return the motor with its load behind a gear with backlash and an elastic shaft.

    Motor side ``J·share``, load side ``J·(1 − share)`` (and ``b`` alike); the gear transmits
    ``k·(δ ∓ gap) + c·(w − wl)`` only in contact (``|δ| > gap``) and never pulls.
    """
    R, L, Ke, Kt = p["R"], p["L"], p["Ke"], p["Kt"]
    jm, jl = p["J"] * lash["share"], p["J"] * (1.0 - lash["share"])
    bm, bl = p["b"] * lash["share"], p["b"] * (1.0 - lash["share"])
    gap, k, c = lash["gap"], lash["k"], lash["c"]

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        i, w, wl, delta = x[0], x[1], x[2], x[3]
        torque = 0.0
        if delta > gap:
            torque = max(k * (delta - gap) + c * (w - wl), 0.0)
        elif delta < -gap:
            torque = min(k * (delta + gap) + c * (w - wl), 0.0)
        return [
            (u - R * i - Ke * w) / L,
            (Kt * i - bm * w - torque) / jm,
            (torque - bl * wl) / jl,
            w - wl,
            w,
        ]

    return f


def _motor_derivative(p: dict[str, float], placed: Placed) -> Derivative:
    if "backlash" in placed.plant:
        return _backlash_derivative(p, placed.plant["backlash"])
    R, L, Ke, Kt, J, b = p["R"], p["L"], p["Ke"], p["Kt"], p["J"], p["b"]

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        i, w = x[0], x[1]
        return [(u - R * i - Ke * w) / L, (Kt * i - b * w) / J, w]

    return f


def _motor_rest(p: dict[str, float], placed: Placed) -> list[float]:
    return [0.0] * len(_motor_states(placed))


def _motor_observe(p: dict[str, float], placed: Placed, X: np.ndarray) -> dict[str, np.ndarray]:
    return {"i": X[:, 0], "w": X[:, 1], "theta": X[:, -1]}


def _motor_twin(p: dict[str, float]) -> dict[str, Any]:
    """Return the motor twin: electrical (states i) and mechanical (state w) in a loop."""
    return {
        "electrical": {
            "inputs": ["V", "w"],
            "outputs": ["i"],
            "states": ["i"],
            "params": {"R": p["R"], "L": p["L"], "Ke": p["Ke"]},
            "derivatives": {"i": "(V - R*i - Ke*w)/L"},
        },
        "mechanical": {
            "inputs": ["i"],
            "outputs": ["w"],
            "states": ["w"],
            "params": {"Kt": p["Kt"], "J": p["J"], "b": p["b"]},
            "derivatives": {"w": "(Kt*i - b*w)/J"},
        },
    }


def _drive_torque(ctx: Context) -> float:
    """Return the standard deviation of the motor torque ``Kt·i`` of the run (N·m)."""
    return float(np.std(ctx.params["Kt"] * ctx.clean["i"])) or 1.0


def _friction(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a friction torque on the rotor: ``Fc`` 1–30 % of the drive torque's spread.

    Forms: ``tanh`` (``Fc·tanh(w/ws)``), ``stribeck`` (a breakaway 1.3–2.5 ``Fc`` decaying
    over ``vs`` 2–10 % of std(w)), ``coulomb_viscous`` (plus a viscous part of 20 % of ``Fc``
    at std(w)); ``ws`` 0.5–2 % of std(w).
    """
    form = str(rng.choice(["tanh", "stribeck", "coulomb_viscous"]))
    w_std = float(np.std(ctx.clean["w"])) or 1.0
    smooth = rng.uniform(0.005, 0.02) * w_std
    breakaway, vs = rng.uniform(1.3, 2.5), rng.uniform(0.02, 0.1) * w_std
    fc = log_between(0.01, 0.3, level) * _drive_torque(ctx)
    inertia, viscous = ctx.params["J"], 0.2 * fc / w_std if form == "coulomb_viscous" else 0.0
    bump = (breakaway - 1.0) * fc if form == "stribeck" else 0.0

    def term(t: float, x: Sequence[float]) -> float:
        w = x[1]
        level_ = fc + (bump * math.exp(-((w / vs) ** 2)) if bump else 0.0)
        return -(level_ * math.tanh(w / smooth) + viscous * w) / inertia

    params = {"Fc": fc, "Fs": fc + bump, "vs": vs, "smoothing": smooth, "viscous": viscous}
    return Placed(form, params, term=("w", term))


def _drag(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a fan's drag ``θ·|w|^p·sign(w)``, ``p`` 1.8–2.2: 1–50 % of the drive at rms(w)."""
    power = rng.uniform(1.8, 2.2)
    w_rms = float(np.sqrt(np.mean(ctx.clean["w"] ** 2))) or 1.0
    theta = log_between(0.01, 0.5, level) * _drive_torque(ctx) / w_rms**power
    inertia = ctx.params["J"]

    def term(t: float, x: Sequence[float]) -> float:
        w = x[1]
        return -theta * abs(w) ** power * math.copysign(1.0, w) / inertia

    return Placed("power", {"theta": theta, "power": power}, term=("w", term))


def _cogging(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a cogging torque ``Tc·sin(N·θ + φ)`` (out of the catalogue): 10–100 % of the drive.

    The drive is the spread of ``Kt·i``; a cogging torque averages out at speed, so it shows
    mostly near standstill.
    """
    poles = int(rng.choice([6, 8, 12, 16, 24]))
    phase = rng.uniform(0.0, 2 * math.pi)
    amplitude = log_between(0.1, 1.0, level) * _drive_torque(ctx)
    inertia = ctx.params["J"]

    def term(t: float, x: Sequence[float]) -> float:
        return -amplitude * math.sin(poles * x[2] + phase) / inertia

    return Placed("sinusoid", {"amplitude": amplitude, "poles": poles}, term=("w", term))


def _backlash(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a load behind a gear with backlash (out of the catalogue).

    The gap is 0.5–10 % of the angle the rotor turns in one electromechanical time constant
    at std(w); the shaft's resonance 0.8–1.5 / dt (rad/s), damping ratio 0.1–0.4; the motor
    side holds 30–60 % of the inertia. The speed is measured on the motor side.
    """
    share, omega = rng.uniform(0.3, 0.6), rng.uniform(0.8, 1.5) / ctx.dt
    zeta = rng.uniform(0.1, 0.4)
    w_std = float(np.std(ctx.clean["w"])) or 1.0
    tau_m = ctx.params["J"] * ctx.params["R"] / (ctx.params["Kt"] * ctx.params["Ke"])
    gap = log_between(0.005, 0.1, level) * w_std * tau_m
    reduced = ctx.params["J"] * share * (1.0 - share)
    lash = {"gap": gap, "share": share, "k": omega**2 * reduced, "c": 2 * zeta * omega * reduced}
    return Placed("gear", dict(lash), plant={"backlash": lash})


MOTOR = Family(
    name="motor",
    input="V",
    internal=("i",),
    outputs=("w",),
    draw=_draw_motor,
    states=_motor_states,
    derivative=_motor_derivative,
    rest=_motor_rest,
    observe=_motor_observe,
    twin=_motor_twin,
    effects={
        "state_sign": FamilyEffect("state_sign", "mechanical", "w", _friction),
        "state_abs_square": FamilyEffect("state_abs_square", "mechanical", "w", _drag),
        "input_saturation": FamilyEffect("input_saturation", "electrical", "V", input_saturation()),
        "input_deadzone": FamilyEffect("input_deadzone", "electrical", "V", input_deadzone()),
        "input_delay": FamilyEffect(
            "input_delay",
            "electrical",
            "V",
            input_delay(),
            equivalent=("output_delay",),
            equivalent_bare_only=True,
        ),
        **{
            name: FamilyEffect(name, "mechanical", "w", draw("w"))
            for name, draw in (
                ("output_quantization", output_quantization),
                ("output_bias_drift", output_bias_drift),
            )
        },
        "output_scale_error": FamilyEffect(  # Kt·g and Ke/g: the same recording
            "output_scale_error",
            "mechanical",
            "w",
            output_scale_error("w"),
            equivalent=("parameter_mismatch",),
        ),
        "output_delay": FamilyEffect(
            "output_delay",
            "mechanical",
            "w",
            output_delay("w"),
            equivalent=("input_delay",),
            equivalent_bare_only=True,
        ),
        "parameter_mismatch": FamilyEffect(
            "parameter_mismatch",
            "electrical",
            None,
            parameter_mismatch({"R": "electrical", "b": "mechanical"}),
        ),
        "rate_limiter": FamilyEffect("unexplained", "electrical", "V", rate_limiter()),
        "backlash": FamilyEffect("unexplained", "mechanical", None, _backlash),
        "cogging": FamilyEffect("unexplained", "mechanical", None, _cogging),
    },
)


# --- thermal -------------------------------------------------------------------------------


def _conductances(p: dict[str, float]) -> np.ndarray:
    """Return the two nodes' conductance matrix ``G`` (W/K): ``G·ΔT = [P, 0]`` at rest."""
    g12, g1a, g2a = 1.0 / p["R12"], 1.0 / p["R1a"], 1.0 / p["R2a"]
    return np.array([[g12 + g1a, -g12], [-g12, g12 + g2a]])


def _draw_thermal(rng: np.random.Generator, n_samples: int | None) -> Asset:
    """Draw a heater and two thermal nodes with a lagging sensor, and heater-command steps."""
    dt = rng.uniform(1.0, 5.0)
    n = _length(rng, 3000, 10000, n_samples)
    p = {"R12": rng.uniform(0.3, 1.5), "R1a": rng.uniform(1.0, 4.0), "R2a": rng.uniform(1.0, 5.0)}
    p["C1"] = rng.uniform(30.0, 150.0) * dt * (1.0 / p["R1a"] + 1.0 / p["R12"])  # J/K
    p["C2"] = rng.uniform(30.0, 200.0) * dt * (1.0 / p["R12"] + 1.0 / p["R2a"])
    p["Ta"] = rng.uniform(18.0, 26.0)
    p["tau_h"] = rng.uniform(2.0, 8.0) * dt
    p["tau_s"] = rng.uniform(1.0, 6.0) * dt
    rise = rng.uniform(40.0, 70.0)  # K: the first node's steady rise at u = 100 %
    p["kh"] = rise / (100.0 * float(np.linalg.inv(_conductances(p))[0, 0]))  # W per %
    rates = np.linalg.eigvals(np.diag([1.0 / p["C1"], 1.0 / p["C2"]]) @ _conductances(p))
    tau_slow = float(1.0 / np.min(rates.real))
    u = _steps(rng, n, 0.0, 100.0, (0.3 * tau_slow / dt, 1.5 * tau_slow / dt))
    return Asset(dt, u, p, tau_slow, "steps")


def _thermal_states(placed: Placed) -> tuple[str, ...]:
    return ("P", "T1", "T2", "y")


def _thermal_derivative(p: dict[str, float], placed: Placed) -> Derivative:
    tau_h, kh, tau_s, ta = p["tau_h"], p["kh"], p["tau_s"], p["Ta"]
    c1, c2, r12, r1a, r2a = p["C1"], p["C2"], p["R12"], p["R1a"], p["R2a"]

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        power, t1, t2, y = x[0], x[1], x[2], x[3]
        between = (t1 - t2) / r12
        return [
            (kh * u - power) / tau_h,
            (power - between - (t1 - ta) / r1a) / c1,
            (between - (t2 - ta) / r2a) / c2,
            (t2 - y) / tau_s,
        ]

    return f


def _thermal_rest(p: dict[str, float], placed: Placed) -> list[float]:
    return [0.0, p["Ta"], p["Ta"], p["Ta"]]


def _thermal_observe(p: dict[str, float], placed: Placed, X: np.ndarray) -> dict[str, np.ndarray]:
    return {"P": X[:, 0], "T1": X[:, 1], "T2": X[:, 2], "y": X[:, 3]}


def _thermal_twin(p: dict[str, float]) -> dict[str, Any]:
    """Return the thermal twin: heater (lag) → body (two RC nodes) → sensor (lag)."""
    return {
        "heater": {
            "block": "lag",
            "inputs": ["u"],
            "outputs": ["P"],
            "params": {"tau": p["tau_h"], "gain": p["kh"]},
        },
        "body": {
            "inputs": ["P"],
            "outputs": ["T1", "T2"],
            "states": ["T1", "T2"],
            "params": {k: p[k] for k in ("C1", "C2", "R12", "R1a", "R2a", "Ta")},
            "derivatives": {
                "T1": "(P - (T1 - T2)/R12 - (T1 - Ta)/R1a)/C1",
                "T2": "((T1 - T2)/R12 - (T2 - Ta)/R2a)/C2",
            },
        },
        "sensor": {
            "block": "lag",
            "inputs": ["T2"],
            "outputs": ["y"],
            "params": {"tau": p["tau_s"]},
        },
    }


def _convection(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a loss ``θ·|T1 − Ta|^p·sign`` of the first node, ``p`` 1.7–2.3 (convection-like).

    At rms(T1 − Ta) it is 1–60 % of the node's linear loss ``(T1 − Ta)/R1a``.
    """
    power = rng.uniform(1.7, 2.3)
    ta, r1a, c1 = ctx.params["Ta"], ctx.params["R1a"], ctx.params["C1"]
    rise_rms = float(np.sqrt(np.mean((ctx.clean["T1"] - ta) ** 2))) or 1.0
    theta = log_between(0.01, 0.6, level) * rise_rms / r1a / rise_rms**power

    def term(t: float, x: Sequence[float]) -> float:
        rise = x[1] - ta
        return -theta * abs(rise) ** power * math.copysign(1.0, rise) / c1

    return Placed("power", {"theta": theta, "power": power}, term=("T1", term))


THERMAL = Family(
    name="thermal",
    input="u",
    internal=("P", "T1"),
    outputs=("y",),
    draw=_draw_thermal,
    states=_thermal_states,
    derivative=_thermal_derivative,
    rest=_thermal_rest,
    observe=_thermal_observe,
    twin=_thermal_twin,
    effects={
        "state_limit": FamilyEffect("state_limit", "body", "T1", state_limit("T1")),
        "state_abs_square": FamilyEffect("state_abs_square", "body", "T1", _convection),
        "input_saturation": FamilyEffect("input_saturation", "heater", "u", input_saturation()),
        **{
            name: FamilyEffect(name, "sensor", "y", draw("y"))
            for name, draw in (
                ("output_bias_drift", output_bias_drift),
                ("output_saturation", output_saturation),
                ("output_quantization", output_quantization),
            )
        },
        **{  # without T1: temperatures scaled (C/g, Ta·g), a delay moved to the input
            name: FamilyEffect(
                name, "sensor", "y", draw("y"), equivalent=(other,), equivalent_bare_only=True
            )
            for name, draw, other in (
                ("output_scale_error", output_scale_error, "parameter_mismatch"),
                ("output_delay", output_delay, "input_delay"),
            )
        },
        "parameter_mismatch": FamilyEffect(
            "parameter_mismatch", "body", None, parameter_mismatch({"R1a": "body", "R2a": "body"})
        ),
        "rate_limiter": FamilyEffect("unexplained", "heater", "u", rate_limiter()),
        "fan_switch": FamilyEffect("unexplained", "body", "R1a", parameter_step("R1a")),
    },
)


# --- battery -------------------------------------------------------------------------------

#: The battery's state of charge is kept within these bounds by the experiment (a cycler's
#: profile turns a pulse's sign when it would leave them).
_SOC_BOUNDS = (0.2, 0.8)


def _current_pulses(rng, n, dt, i_max, capacity, soc0, hold) -> np.ndarray:
    """Return a current set-point of bipolar pulses ``(n,)`` (A, positive discharging).

    Levels uniform in ``[−i_max, i_max]``, each held ``hold`` samples; a pulse that would take
    the state of charge (from ``soc0``, capacity ``capacity`` A·s) out of :data:`_SOC_BOUNDS`
    is played with the other sign. The second half plays the first half's pulses again in
    another order (both halves reach about the same extremes, as :func:`_steps`).
    """
    low_hold, high_hold = max(int(hold[0]), 2), max(int(hold[1]), 3)
    drawn, total = [], 0
    while total < n // 2:
        drawn.append((rng.uniform(-i_max, i_max), int(rng.integers(low_hold, high_hold + 1))))
        total += drawn[-1][1]
    again = [drawn[k] for k in rng.permutation(len(drawn))]
    soc, levels = soc0, []
    for level, length in [*drawn, *again, *again]:
        after = soc - level * length * dt / capacity
        if not _SOC_BOUNDS[0] <= after <= _SOC_BOUNDS[1]:
            level = -level
            after = soc - level * length * dt / capacity
        if _SOC_BOUNDS[0] <= after <= _SOC_BOUNDS[1]:
            soc = after
        else:  # neither sign fits: rest
            level = 0.0
        levels.append(np.full(length, level))
        if sum(len(a) for a in levels) >= n:
            break
    return np.concatenate(levels)[:n]


def _draw_battery(rng: np.random.Generator, n_samples: int | None) -> Asset:
    """Draw a lithium-ion cell (Thevenin model) on a cycler, and current pulses."""
    dt = rng.uniform(0.5, 2.0)
    n = _length(rng, 3000, 10000, n_samples)
    capacity_ah = rng.uniform(2.0, 5.0)
    p = {
        "tau_c": rng.uniform(1.0, 4.0) * dt,  # s: the cycler's current loop
        "Q": capacity_ah * 3600.0,  # A·s
        "R0": rng.uniform(0.01, 0.08),  # ohm: ohmic resistance
        "R1": rng.uniform(0.01, 0.06),  # ohm: polarisation resistance
        "E0": rng.uniform(3.4, 3.8),  # V: open-circuit voltage at half charge
        "k1": rng.uniform(0.3, 0.8),  # V per unit of charge
        "k3": rng.uniform(2.0, 6.0),  # V: the curve's steep ends
        "soc0": rng.uniform(0.35, 0.65),
    }
    tau1 = rng.uniform(20.0, 120.0) * dt
    p["C1"] = tau1 / p["R1"]  # F
    i_max = rng.uniform(1.0, 3.0) * capacity_ah  # A: 1–3 C
    u = _current_pulses(rng, n, dt, i_max, p["Q"], p["soc0"], (0.2 * tau1 / dt, 2.0 * tau1 / dt))
    return Asset(dt, u, p, tau1, "pulses")


def _battery_states(placed: Placed) -> tuple[str, ...]:
    return ("I", "soc", "v1")


def _battery_derivative(p: dict[str, float], placed: Placed) -> Derivative:
    tau_c, q, r1, c1 = p["tau_c"], p["Q"], p["R1"], p["C1"]

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        current, v1 = x[0], x[2]
        return [(u - current) / tau_c, -current / q, current / c1 - v1 / (r1 * c1)]

    return f


def _battery_rest(p: dict[str, float], placed: Placed) -> list[float]:
    return [0.0, p["soc0"], 0.0]


def _ocv(p: dict[str, float], soc: np.ndarray) -> np.ndarray:
    """Return the open-circuit voltage (V) at state of charge ``soc``."""
    return p["E0"] + p["k1"] * (soc - 0.5) + p["k3"] * (soc - 0.5) ** 3


def _battery_observe(p: dict[str, float], placed: Placed, X: np.ndarray) -> dict[str, np.ndarray]:
    current, soc, v1 = X[:, 0], X[:, 1], X[:, 2]
    terminal = _ocv(p, soc) - v1 - p["R0"] * current
    return {"I": current, "soc": soc, "v1": v1, "V": terminal}


def _battery_twin(p: dict[str, float]) -> dict[str, Any]:
    """Return the battery twin: cycler (lag) → cell (charge, polarisation, terminal voltage)."""
    return {
        "cycler": {
            "block": "lag",
            "inputs": ["I_set"],
            "outputs": ["I"],
            "params": {"tau": p["tau_c"]},
        },
        "cell": {
            "inputs": ["I"],
            "outputs": ["V"],
            "states": ["soc", "v1"],
            "params": {k: p[k] for k in ("Q", "R0", "R1", "C1", "E0", "k1", "k3")},
            "derivatives": {"soc": "-I/Q", "v1": "I/C1 - v1/(R1*C1)"},
            "equations": {"V": "E0 + k1*(soc - 0.5) + k3*(soc - 0.5)**3 - v1 - R0*I"},
        },
    }


def _butler_volmer(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
    """Draw a polarisation current ``(v0/R1)·sinh(v1/v0)`` for the twin's linear ``v1/R1``.

    The missing term of ``v1``'s derivative, ``−(v0·sinh(v1/v0) − v1)/(R1·C1)``, is odd and
    about cubic (``v1³/(6·v0²)``) while ``v1 ≪ v0``; at rms(v1) it is 1–60 % of the linear
    relaxation (``v0 = rms(v1)/√(6·share)``).
    """
    share = log_between(0.01, 0.6, level)
    r1, c1 = ctx.params["R1"], ctx.params["C1"]
    spread = float(np.sqrt(np.mean(ctx.clean["v1"] ** 2))) or 1.0
    v0 = spread / math.sqrt(6.0 * share)

    def term(t: float, x: Sequence[float]) -> float:
        z = x[2] / v0
        return -(v0 * math.sinh(z) - x[2]) / (r1 * c1)

    return Placed("sinh", {"v0": v0, "share": share}, term=("v1", term))


BATTERY = Family(
    name="battery",
    input="I_set",
    internal=("I",),
    outputs=("V",),
    draw=_draw_battery,
    states=_battery_states,
    derivative=_battery_derivative,
    rest=_battery_rest,
    observe=_battery_observe,
    twin=_battery_twin,
    effects={
        "state_limit": FamilyEffect("state_limit", "cell", "soc", state_limit("soc")),
        "state_cubic": FamilyEffect("state_cubic", "cell", "v1", _butler_volmer),
        "input_saturation": FamilyEffect("input_saturation", "cycler", "I_set", input_saturation()),
        "input_delay": FamilyEffect(
            "input_delay",
            "cycler",
            "I_set",
            input_delay(),
            equivalent=("output_delay",),
            equivalent_bare_only=True,
        ),
        **{
            name: FamilyEffect(name, "cell", "V", draw("V"))
            for name, draw in (
                ("output_saturation", output_saturation),
                ("output_bias_drift", output_bias_drift),
                ("output_quantization", output_quantization),
            )
        },
        "output_scale_error": FamilyEffect(  # E0, k1, k3, R0, R1 times g and C1/g: the same
            "output_scale_error",
            "cell",
            "V",
            output_scale_error("V"),
            equivalent=("parameter_mismatch",),
        ),
        "output_delay": FamilyEffect(
            "output_delay",
            "cell",
            "V",
            output_delay("V"),
            equivalent=("input_delay",),
            equivalent_bare_only=True,
        ),
        "parameter_mismatch": FamilyEffect(
            "parameter_mismatch",
            "cell",
            None,
            parameter_mismatch({"R0": "cell", "R1": "cell", "Q": "cell"}),
        ),
        "rate_limiter": FamilyEffect("unexplained", "cycler", "I_set", rate_limiter()),
        "warming": FamilyEffect("unexplained", "cell", "R1", parameter_drift("R1")),
    },
)
