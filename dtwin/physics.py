"""The physical asset: six discrete modules and the simulator (paper §3.1; r_notes.md §1).

The modules' laws are the contract of :mod:`dtwin.twin.paper_modules` (recursions, parameters,
signals), run with the paper's explicit-Euler discretisation; this module adds the noise and the
start at rest, and :func:`simulate_physics` runs them with the contract's chain runner
(:func:`dtwin.twin.paper_modules.run_modules`, the order of the wiring table).

Every module applies its input with a one-sample delay (``u[k-1]`` drives step ``k``), as the
paper's equations and the authors' R code do. Arrays are time-first, shape ``(n_steps,)``.

Random draws happen in module order with one generator, always as standard normals scaled by
the noise standard deviation, so the stream does not depend on the noise levels:
M0 ``n−1`` draws, M1 ``n−1``, M2a ``n``, M2b ``n`` (the R code's order; numpy cannot replay
R's stream itself).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
import pandas as pd

from dtwin._lfilter import lfilter
from dtwin._validation import DtwinValueError, require_finite_array, require_min_length
from dtwin.command import time_axis
from dtwin.params import TwinParams
from dtwin.twin.paper_modules import (
    EULER,
    PlantTrajectory,
    fuse,
    kpi,
    lag_coefficient,
    lag_response,
    plant_response,
    run_modules,
)
from dtwin.twin.wiring import MODULES, SIGNALS

__all__ = [
    "actuator_lpf",
    "plant_msd",
    "PlantTrajectory",
    "sensor_first_order",
    "fuse",
    "kpi",
    "backward_velocity",
    "simulate_physics",
]


def _noise_or_zeros(noise: np.ndarray | None, n_steps: int, name: str) -> np.ndarray:
    if noise is None:
        return np.zeros(n_steps)
    noise = require_finite_array(name, noise)
    if noise.shape != (n_steps,):
        raise DtwinValueError(f"{name} must have shape ({n_steps},) (got {noise.shape})")
    return noise


def actuator_lpf(
    u_cmd: np.ndarray, tau: float, dt: float, process_noise: np.ndarray | None = None
) -> np.ndarray:
    """Return the realised actuation ``u_act`` of M0, shape ``(n_steps,)``.

    Parameters
    ----------
    u_cmd : array, shape (n_steps,)
        Command.
    tau : float
        Time constant, s.
    dt : float
        Sample period, s.
    process_noise : array, shape (n_steps,), optional
        ``w_k`` added at step k (element 0 is unused because ``u_act[0] = 0``).

    Notes
    -----
    Paper §3.1 M0: ``u_act,k = a·u_act,k−1 + (1−a)·u_cmd,k−1 + w_k``, ``a = exp(−dt/τ)``,
    ``u_act,1 = 0``.

    Examples
    --------
    >>> y = actuator_lpf(np.ones(4), tau=0.15, dt=0.02)
    >>> np.round(y, 4).tolist()
    [0.0, 0.1248, 0.2341, 0.3297]
    """
    u_cmd = require_finite_array("u_cmd", u_cmd)
    noise = _noise_or_zeros(process_noise, len(u_cmd), "process_noise").copy()
    noise[0] = 0.0
    a = lag_coefficient(tau, dt)
    return lag_response(u_cmd, a) + lfilter([1.0], [1.0, -a], noise)


def plant_msd(
    u_act: np.ndarray,
    m: float,
    c: float,
    k: float,
    dt: float,
    accel_noise: np.ndarray | None = None,
) -> PlantTrajectory:
    """Return position and velocity of the M1 mass-spring-damper under explicit Euler.

    Parameters
    ----------
    u_act : array, shape (n_steps,)
        Force input (N).
    m, c, k : float
        Mass (kg), viscous damping (N·s/m), stiffness (N/m).
    dt : float
        Sample period, s.
    accel_noise : array, shape (n_steps,), optional
        ``ξ_k`` added to the acceleration of step k (element 0 unused), m/s².

    Notes
    -----
    Paper §3.1 M1: ``a_{k−1} = (u_{k−1} − c·v_{k−1} − k·x_{k−1})/m + ξ_k``,
    ``v_k = v_{k−1} + dt·a_{k−1}``, ``x_k = x_{k−1} + dt·v_{k−1}`` (position uses the old
    velocity), ``x_1 = v_1 = 0``. Noise-free this is the difference equation
    ``x_k = (2 − c·dt/m)·x_{k−1} − (1 − c·dt/m + k·dt²/m)·x_{k−2} + dt²/m·u_{k−2}``.
    """
    u_act = require_finite_array("u_act", u_act)
    n_steps = len(u_act)
    noise = _noise_or_zeros(accel_noise, n_steps, "accel_noise")
    return plant_response(u_act, m, c, k, dt, accel_noise=noise)


def sensor_first_order(
    x: np.ndarray,
    tau: float,
    dt: float,
    bias: float = 0.0,
    measurement_noise: np.ndarray | None = None,
) -> np.ndarray:
    """Return a sensor reading of M2a/M2b, shape ``(n_steps,)``.

    Notes
    -----
    Paper §3.1 M2: ``ỹ_k = a_s·ỹ_{k−1} + (1−a_s)·x_{k−1}``, ``ỹ_1 = 0``, then
    ``y_k = ỹ_k + b_s + ε_k`` (so ``y_1 = b_s + ε_1``).
    """
    x = require_finite_array("x", x)
    noise = _noise_or_zeros(measurement_noise, len(x), "measurement_noise")
    return lag_response(x, lag_coefficient(tau, dt)) + bias + noise


def backward_velocity(x: np.ndarray, dt: float) -> np.ndarray:
    """Return ``ẋ_k ≈ (x_k − x_{k−1})/dt`` with ``ẋ_1 = 0`` (the surrogate's velocity, §3.1 M4)."""
    x = np.asarray(x, dtype=float)
    velocity = np.zeros_like(x)
    velocity[1:] = np.diff(x) / dt
    return velocity


# --- the simulator: one step function per module, run by the contract's chain runner -------

Signals = dict[str, np.ndarray]
_Step = Callable[[Signals, TwinParams, np.random.Generator], Signals]


def _step_actuator(s: Signals, twin: TwinParams, rng: np.random.Generator) -> Signals:
    n_steps = len(s["u_cmd"])
    noise = np.concatenate([[0.0], twin.noise.actuator * rng.standard_normal(n_steps - 1)])
    return {"u_act": actuator_lpf(s["u_cmd"], twin.actuator.tau, twin.dt, noise)}


def _step_plant(s: Signals, twin: TwinParams, rng: np.random.Generator) -> Signals:
    n_steps = len(s["u_act"])
    noise = np.concatenate([[0.0], twin.noise.plant * rng.standard_normal(n_steps - 1)])
    p = twin.plant
    trajectory = plant_msd(s["u_act"], p.m, p.c, p.k, twin.dt, noise)
    return {"x": trajectory.x, "v": trajectory.v}


def _sensor_step(which: str) -> _Step:
    def step(s: Signals, twin: TwinParams, rng: np.random.Generator) -> Signals:
        sensor = getattr(twin, f"sensor_{which}")
        noise = getattr(twin.noise, f"sensor_{which}") * rng.standard_normal(len(s["x"]))
        return {f"y_{which}": sensor_first_order(s["x"], sensor.tau, twin.dt, sensor.bias, noise)}

    return step


def _step_fusion(s: Signals, twin: TwinParams, rng: np.random.Generator) -> Signals:
    return {"y_fused": fuse(s["y_A"], s["y_B"], twin.fusion.alpha)}


def _step_kpi(s: Signals, twin: TwinParams, rng: np.random.Generator) -> Signals:
    return {"z": kpi(s["x"], s["v"], twin.kpi.w1, twin.kpi.w2)}


PHYSICS_STEPS: dict[str, _Step] = {
    "M0": _step_actuator,
    "M1": _step_plant,
    "M2a": _sensor_step("A"),
    "M2b": _sensor_step("B"),
    "M3": _step_fusion,
    "M4": _step_kpi,
}


def simulate_physics(twin: TwinParams, u_cmd: np.ndarray, rng: np.random.Generator) -> pd.DataFrame:
    """Run the physical asset on a command and return every signal.

    Parameters
    ----------
    twin : TwinParams
        Complete twin parameters (every section present; ``discretisation`` None or
        ``"euler"``, the paper's).
    u_cmd : array, shape (n_steps,)
        Command (see :func:`dtwin.command.make_command`).
    rng : numpy.random.Generator
        Source of the process and measurement noise (draw order in the module docstring).

    Returns
    -------
    pandas.DataFrame
        One row per sample; columns ``t`` (s) and :data:`dtwin.twin.wiring.SIGNALS`
        (``u_cmd, u_act, x, v, y_A, y_B, y_fused, z``).
    """
    u_cmd = require_finite_array("u_cmd", u_cmd)
    require_min_length("u_cmd", u_cmd, 3)
    missing = [module.name for module in MODULES if getattr(twin, module.section) is None]
    if missing or twin.noise is None:
        raise DtwinValueError("simulate_physics needs every twin section (twin.noise included)")
    if twin.discretisation not in (None, EULER):
        raise DtwinValueError(
            "twin.discretisation must be euler for the paper's simulator "
            f"(got {twin.discretisation!r})"
        )
    steps = {name: partial(step, twin=twin, rng=rng) for name, step in PHYSICS_STEPS.items()}
    signals = {"u_cmd": u_cmd, **run_modules(steps, {"u_cmd": u_cmd})}
    table = pd.DataFrame({"t": time_axis(len(u_cmd), twin.dt)})
    for name in SIGNALS:
        table[name] = signals[name]
    return table
