"""The module twins of the gap diagnoser, each with an optional candidate effect (paper §3.1).

Specification: docs/gap.md §Modules (recursions) and §Candidate effects (stages).

One function, :func:`simulate_module`, drives one module's twin with given input signals and
returns its output, shape ``(n_samples,)``. The linear part of each module is the module contract
(:mod:`dtwin.modules`: :func:`~dtwin.modules.lag_response`,
:func:`~dtwin.modules.plant_response`, :func:`~dtwin.modules.fuse`, :func:`~dtwin.modules.kpi`;
the paper's laws of r_notes.md §1 with the Euler discretisation), with one-sample input delays:

- M0 ``u_act[k] = a·u_act[k−1] + (1−a)·u_cmd[k−1]``, ``a = exp(−dt/tau)``;
- M1 explicit Euler ``a = (u[k−1] − u_offset − c·v[k−1] − k·x[k−1] − F(x, v))/m``,
  ``v[k] = v[k−1] + dt·a``, ``x[k] = x[k−1] + dt·v[k−1]``, with an optional extra input delay
  (``delay_samples``) and ``u_offset`` when the plant is calibrated from data;
- M2a/M2b ``lag[k] = a_s·lag[k−1] + (1−a_s)·x[k−1]``, ``y = lag + bias``;
- M3 ``y_fused = alpha·y_A + (1−alpha)·y_B``; M4 ``z = w1·x + w2·v``.

Unlike :mod:`dtwin.physics`, every recursion starts from the *recorded* initial state (a rig
is not at rest when the recording starts) and no noise is drawn: these are predictions.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from dtwin.gap.effects import (
    Effect,
    Scales,
    deadzone,
    fractional_delay,
    smooth_quantize,
    soft_saturation,
)
from dtwin.modules import (
    EULER,
    LINEAR_PARAMS,
    exact_plant_response,
    fuse,
    kpi,
    lag_coefficient,
    lag_response,
    plant_response,
)

__all__ = [
    "LINEAR_PARAMS",
    "ModuleData",
    "velocity_from_position",
    "plant_windows",
    "plant_horizon",
    "plant_bandwidth_hz",
    "simulate_module",
    "first_order_lag",
]

#: Friction smoothing velocity as a fraction of std(v) (the tanh in ``coulomb_friction``).
FRICTION_SMOOTHING = 0.01


@dataclass(frozen=True)
class ModuleData:
    """The recorded signals one module is driven with and compared against.

    Attributes
    ----------
    name : str
        ``"M0"`` … ``"M4"``.
    inputs : dict of str to numpy.ndarray
        The module's input signals, each shape ``(n_samples,)``.
    output : numpy.ndarray, shape (n_samples,)
        The recorded output.
    dt : float
        Sample period, s.
    t : numpy.ndarray, shape (n_samples,)
        Time from the first sample, s.
    velocity : numpy.ndarray, shape (n_samples,)
        M1: the velocity estimated from the recorded position; M4: the velocity input.
    scales : Scales
        Data scales for effect bounds.
    discretisation : str
        M1: ``"euler"`` (the paper's twin), ``"zoh"`` or ``"foh"`` (exact;
        :func:`dtwin.modules.exact_plant_response`).
    horizon : int or None
        M1 with an exact discretisation: simulate in windows of this many samples, each
        restarted from the recorded state (None: free run).
    restarts : tuple of int
        Samples where a new experiment starts (a separate held-out recording): every recursion
        restarts there from the recorded state.
    """

    name: str
    inputs: dict[str, np.ndarray] = field(repr=False)
    output: np.ndarray = field(repr=False)
    dt: float
    t: np.ndarray = field(repr=False)
    velocity: np.ndarray | None = field(default=None, repr=False)
    scales: Scales | None = None
    discretisation: str = EULER
    horizon: int | None = None
    restarts: tuple[int, ...] = ()

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return len(self.output)


def velocity_from_position(
    x: np.ndarray, dt: float, discretisation: str = EULER, restarts: Sequence[int] = ()
) -> np.ndarray:
    """Return the plant velocity implied by a position record, shape ``(n_samples,)``, units/s.

    The Euler plant defines ``x[k+1] = x[k] + dt·v[k]``, so ``v[k] = (x[k+1] − x[k])/dt``; the
    position is first smoothed by a cubic Savitzky-Golay filter over 7 samples (exact for
    smooth signals, it tames measurement noise). The last sample repeats the one before. An exact
    discretisation needs the derivative at the sample itself: the 5-point central difference
    (a cubic Savitzky-Golay derivative, exact for cubics). Each experiment (split at
    ``restarts``) is differentiated on its own.
    """
    x = np.asarray(x, dtype=float)
    velocity = np.empty_like(x)
    for start, end in _pieces(len(x), restarts):
        velocity[start:end] = _piece_velocity(x[start:end], dt, discretisation)
    return velocity


def _piece_velocity(x: np.ndarray, dt: float, discretisation: str) -> np.ndarray:
    if discretisation != EULER and len(x) >= 5:
        return savgol_filter(x, 5, 3, deriv=1, delta=dt)
    smooth = savgol_filter(x, 7, 3) if len(x) >= 7 else x
    velocity = np.empty_like(smooth)
    velocity[:-1] = np.diff(smooth) / dt
    velocity[-1] = velocity[-2]
    return velocity


def first_order_lag(u: np.ndarray, tau: float, dt: float, initial: float) -> np.ndarray:
    """Return ``y[k] = a·y[k−1] + (1−a)·u[k−1]``, ``y[0] = initial``, ``a = exp(−dt/tau)``.

    The contract's lag (:func:`dtwin.modules.lag_response`); ``tau ≤ 0`` (a fit's trial value)
    gives ``a = 0``, the input delayed by one sample.
    """
    a = lag_coefficient(tau, dt) if tau > 0 else 0.0
    return lag_response(u, a, initial)


def _effect_input(u: np.ndarray, effect: Effect | None, theta: Sequence[float], dt: float):
    if effect is None:
        return u
    if effect.name == "actuator_saturation":
        return soft_saturation(u, theta[0], theta[1])
    if effect.name == "actuator_deadzone":
        return deadzone(u, theta[0])
    if effect.stage == "delay":
        return fractional_delay(u, theta[0] / dt)
    return u


def _pieces(stop: int, restarts: Sequence[int]) -> list[tuple[int, int]]:
    edges = [0, *(r for r in restarts if 0 < r < stop), stop]
    return list(itertools.pairwise(edges))


def _piecewise_lag(u: np.ndarray, tau: float, dt: float, initial: np.ndarray, restarts):
    """Return the lag restarted at each experiment boundary from ``initial[start]``."""
    out = np.empty(len(u))
    for start, end in _pieces(len(u), restarts):
        out[start:end] = first_order_lag(u[start:end], tau, dt, initial[start])
    return out


def _simulate_actuator(data, lin, effect, theta, stop):
    u = _effect_input(data.inputs["u_cmd"][:stop], effect, theta, data.dt)
    return _piecewise_lag(u, lin["tau"], data.dt, data.output, data.restarts)


def _simulate_sensor(data, lin, effect, theta, stop):
    x = _effect_input(data.inputs["x"][:stop], effect, theta, data.dt)
    lag = _piecewise_lag(x, lin["tau"], data.dt, x, data.restarts)
    bias = lin["bias"]
    if effect is None or effect.stage != "output":
        return lag + bias
    if effect.name == "sensor_scale_error":
        return theta[0] * lag + bias
    if effect.name == "sensor_bias_drift":
        return lag + bias + theta[0] * data.t[:stop]
    if effect.name == "sensor_quantization":
        step, offset, before = theta
        return offset + smooth_quantize(lag + bias - offset, step, before)
    raise ValueError(f"effect {effect.name} cannot act on a sensor")


def _force(effect: Effect | None, theta: Sequence[float], velocity_std: float):
    if effect is None or effect.stage != "force":
        return None
    if effect.name == "coulomb_friction":
        fc = float(theta[0])
        vs = max(FRICTION_SMOOTHING * velocity_std, 1e-300)
        tanh = math.tanh
        return lambda x, v: fc * tanh(v / vs)
    if effect.name == "cubic_stiffness":
        k3 = float(theta[0])
        return lambda x, v: k3 * x * x * x
    if effect.name == "quadratic_damping":
        c2 = float(theta[0])
        return lambda x, v: c2 * v * abs(v)
    raise ValueError(f"effect {effect.name} cannot act on the plant")


def plant_windows(
    stop: int, horizon: int | None, restarts: Sequence[int] = ()
) -> list[tuple[int, int]]:
    """Return the plant's simulation windows over samples ``0 … stop−1``.

    Each experiment (split at ``restarts``) is cut into windows of ``horizon`` samples (the
    last one may be shorter, but at least ``horizon/2`` long: a shorter tail joins the window
    before); ``horizon=None`` is one window per experiment (free run).

    Examples
    --------
    >>> plant_windows(9, 4)
    [(0, 4), (4, 9)]
    >>> plant_windows(10, None, restarts=[6])
    [(0, 6), (6, 10)]
    """
    windows = []
    for start, end in _pieces(stop, restarts):
        length = end - start if horizon is None else max(int(horizon), 2)
        edges = [*range(start, end, length), end]
        if len(edges) > 2 and edges[-1] - edges[-2] < length / 2:
            del edges[-2]
        windows.extend(itertools.pairwise(edges))
    return windows


def _plant_poles(lin: Mapping[str, float]) -> np.ndarray:
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    return np.roots([1.0, c / m, k / m]).astype(complex)


def plant_bandwidth_hz(lin: Mapping[str, float]) -> float:
    """Return the plant's bandwidth, Hz: its largest pole magnitude over 2π."""
    return float(np.max(np.abs(_plant_poles(lin)))) / (2 * math.pi)


#: Free run needs the slowest plant mode to decay within this fraction of the held-out part.
FREE_RUN_DECAYS = 10.0
#: A window spans this many of the plant's fastest time constant.
HORIZON_TIME_CONSTANTS = 2.0
#: Shortest window, samples.
MIN_HORIZON = 20


def plant_horizon(lin: Mapping[str, float], dt: float, n_held: int) -> int | None:
    """Return the plant's simulation window in samples, or None where free run is meaningful.

    Parameters
    ----------
    lin : mapping
        ``m, c, k`` of the plant.
    dt : float
        Sample period, s.
    n_held : int
        Number of held-out samples.

    Returns
    -------
    int or None
        None when the plant is stable and its slowest mode decays ``FREE_RUN_DECAYS`` times
        within the held-out part (a free run then forgets its start). Otherwise (an integrating
        plant, ``k = 0``, or one too slow for the recording, as in closed-loop rigs)
        ``HORIZON_TIME_CONSTANTS`` of its fastest time constant, at least ``MIN_HORIZON``
        and at most a quarter of the held-out part.

    Notes
    -----
    docs/gap.md §Gaps. A free-run position error of an integrating plant grows without bound
    with any force error, so its gap is measured over windows restarted from the recorded
    state.
    """
    decay = -_plant_poles(lin).real
    if decay.min() * n_held * dt >= FREE_RUN_DECAYS:
        return None
    fastest = float(decay.max())
    longest = max(n_held // 4, MIN_HORIZON)
    if fastest <= 0:
        return longest
    return int(min(max(round(HORIZON_TIME_CONSTANTS / fastest / dt), MIN_HORIZON), longest))


def _exact_plant(data, lin, u, force, stop, segments):
    windows = segments or plant_windows(stop, data.horizon, data.restarts)
    windows = [(a, min(b, stop)) for a, b in windows if a < stop]
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    return exact_plant_response(
        u,
        m,
        c,
        k,
        data.dt,
        windows=windows,
        x_start=data.output,
        v_start=data.velocity,
        hold=data.discretisation,
        force=force,
    )


def _simulate_plant(data, lin, effect, theta, stop, segments):
    u = data.inputs["u_act"][:stop]
    delay = int(lin.get("delay_samples", 0))
    if delay:
        u = fractional_delay(u, delay)
    force = _force(effect, theta, data.scales.velocity_std if data.scales else 1.0)
    if data.discretisation != EULER:
        return _exact_plant(data, lin, u - lin.get("u_offset", 0.0), force, stop, segments)
    segments = segments or (plant_windows(stop, None, data.restarts) if data.restarts else None)
    u = (u - lin.get("u_offset", 0.0)).tolist()
    x_rec, v_rec = data.output, data.velocity
    out = np.zeros(len(u))
    limit = 1e6 * (np.abs(x_rec).max() + 1e-12)
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    for start, end in segments or [(0, len(u))]:
        out[start:end] = plant_response(
            u[start:end],
            m,
            c,
            k,
            data.dt,
            x0=x_rec[start],
            v0=v_rec[start],
            force=force,
            limit=limit,
        ).x
    return out


def simulate_module(
    data: ModuleData,
    lin: Mapping[str, float],
    effect: Effect | None = None,
    theta: Sequence[float] = (),
    *,
    stop: int | None = None,
    segments: Sequence[tuple[int, int]] | None = None,
) -> np.ndarray:
    """Return the twin's prediction of one module's output, shape ``(stop,)``.

    Parameters
    ----------
    data : ModuleData
        Recorded inputs (and the recorded output, whose first sample sets the initial state).
    lin : mapping
        The module's linear parameters (:data:`LINEAR_PARAMS`; M1 may add ``u_offset`` and
        ``delay_samples``).
    effect : Effect, optional
        A candidate effect; ``None`` or ``parameter_mismatch`` for the linear twin alone.
    theta : sequence of float
        The effect's parameters, in the order of ``effect.params``.
    stop : int, optional
        Simulate samples ``0 … stop−1`` only (all models are causal). Default: all.
    segments : sequence of (start, stop), optional
        M1 only: simulate each segment from the *recorded* state at its start (multiple
        shooting), which bounds the drift that process noise causes; samples outside the
        segments are 0.

    Returns
    -------
    numpy.ndarray, shape (stop,)
    """
    stop = data.n_samples if stop is None else stop
    name = data.name
    if name == "M0":
        return _simulate_actuator(data, lin, effect, theta, stop)
    if name == "M1":
        return _simulate_plant(data, lin, effect, theta, stop, segments)
    if name in ("M2a", "M2b"):
        return _simulate_sensor(data, lin, effect, theta, stop)
    if name == "M3":
        return fuse(data.inputs["y_A"][:stop], data.inputs["y_B"][:stop], lin["alpha"])
    if name == "M4":
        return kpi(data.inputs["x"][:stop], data.velocity[:stop], lin["w1"], lin["w2"])
    raise ValueError(f"unknown module {name!r}")
