"""The module twins of the gap diagnoser, each with an optional candidate effect (paper §3.1).

Specification: docs/gap.md §Modules (recursions) and §Candidate effects (stages).

One function, :func:`simulate_module`, drives one module's twin with given input signals and
returns its output, shape ``(n_samples,)``. The linear part of each module is the module contract
(:mod:`dtwin.twin.paper_modules`: :func:`~dtwin.twin.paper_modules.lag_response`,
:func:`~dtwin.twin.paper_modules.plant_response`, :func:`~dtwin.twin.paper_modules.fuse`,
:func:`~dtwin.twin.paper_modules.kpi`; the paper's laws of r_notes.md §1 with the Euler
discretisation), with one-sample input delays:

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
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy.signal import lfilter, savgol_filter

from dtwin._jit import HAVE_NUMBA
from dtwin.gap.effects import (
    ARRAY_OPS,
    FRICTION_SMOOTHING,
    SCALAR_OPS,
    Effect,
    Scales,
    fractional_delay,
)
from dtwin.gap.noise import robust_std
from dtwin.twin.exact import (
    exact_plant_response,
    force_substeps,
    free_response_basis,
    hold_matrices,
)
from dtwin.twin.paper_modules import (
    EULER,
    LINEAR_PARAMS,
    fuse,
    kpi,
    lag_coefficient,
    lag_response,
    plant_response,
)
from dtwin.twin.wiring import ACTUATOR, FUSION, KPI, PLANT, SENSOR, role_of

__all__ = [
    "LINEAR_PARAMS",
    "ModuleData",
    "module_part",
    "velocity_from_position",
    "plant_windows",
    "plant_horizon",
    "warmup_samples",
    "window_noise_gain",
    "held_noise_autocovariance",
    "window_error_covariance",
    "plant_bandwidth_hz",
    "plant_state_from_position",
    "simulate_module",
    "profiled_window_error",
    "first_order_lag",
]


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
        M1: ``"euler"`` (the paper's twin), ``"zoh"``, ``"foh"`` or ``"bandlimited"`` (exact;
        :func:`dtwin.twin.exact.exact_plant_response`).
    horizon : int or None
        M1 with an exact discretisation: simulate in windows of this many samples, each
        restarted from the recorded state (None: free run).
    restarts : tuple of int
        Samples where a new experiment starts (a separate held-out recording): every recursion
        restarts there from the recorded state.
    position : numpy.ndarray or None, shape (n_samples,)
        M1, Euler plant: the position the recursion starts from (the smoothed one when the
        recorded position is noisy; None: the recorded output).
    lead : int
        M1, Euler plant: samples each run skips at its start (unscored, NaN), so that it starts
        where the smoothed velocity is centred rather than at the edge of its window
        (:func:`plant_state_from_position`).
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
    position: np.ndarray | None = field(default=None, repr=False)
    lead: int = 0

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return len(self.output)

    @property
    def role(self) -> str:
        """The module's role (:data:`dtwin.twin.wiring.ROLES`; ``"plant"`` for M1)."""
        return role_of(self.name)


def module_part(data: ModuleData, start: int, stop: int) -> ModuleData:
    """Return the module's recorded signals over samples ``start … stop−1`` (each such a slice).

    Every model starts from the recorded state at the part's first sample, as at a recording's
    first sample; the times and scales stay the whole recording's, restarts inside the part
    move with it.
    """
    cut = slice(start, stop)

    def part(values):
        return None if values is None else values[cut]

    return replace(
        data,
        inputs={name: values[cut] for name, values in data.inputs.items()},
        output=data.output[cut],
        t=data.t[cut],
        velocity=part(data.velocity),
        position=part(data.position),
        restarts=tuple(r - start for r in data.restarts if start < r < stop),
    )


def velocity_from_position(
    x: np.ndarray, dt: float, discretisation: str = EULER, restarts: Sequence[int] = ()
) -> np.ndarray:
    """Return the plant velocity implied by a position record, shape ``(n_samples,)``, units/s.

    The Euler plant defines ``x[k+1] = x[k] + dt·v[k]``, so ``v[k] = (x[k+1] − x[k])/dt``; the
    position is first smoothed by a cubic Savitzky-Golay filter over 7 samples, or more when
    the position is noisy (:func:`_smoothing_window`: a position with 1 % white noise
    restarted the Euler twin from velocities 7 % off, and the transients read as a gap). The
    last sample repeats the one before. An exact discretisation needs the derivative at the
    sample itself: the 5-point central difference (a cubic Savitzky-Golay derivative, exact for
    cubics). Each experiment (split at ``restarts``) is differentiated on its own.
    """
    x = np.asarray(x, dtype=float)
    velocity = np.empty_like(x)
    for start, end in _pieces(len(x), restarts):
        velocity[start:end] = _piece_velocity(x[start:end], dt, discretisation)
    return velocity


def plant_state_from_position(
    x: np.ndarray, dt: float, discretisation: str = EULER, restarts: Sequence[int] = ()
) -> tuple[np.ndarray, np.ndarray, int]:
    """Return ``(position, velocity, lead)``: the state the plant's recursion starts from.

    ``velocity`` is :func:`velocity_from_position`. For the Euler plant with a noisy position
    (a smoothing window wider than the narrowest) ``position`` is the smoothed one and ``lead``
    half the widest window: a run starts ``lead`` samples into its piece, where the smoothing
    is centred. At the edge of the window the smoothed derivative extrapolates a cubic: on
    positions with 1 % white noise it started the Euler twin 0.06 units/s off, and the
    lightly damped transient raised the training part's gap of the *true* plant from 0.011 to
    0.015 (the floor: 0.011), which flagged M1 in 2 of 10 noisy-position cases without an
    effect. Otherwise ``position`` is ``x`` and ``lead`` 0. Shapes ``(n_samples,)``.
    """
    x = np.asarray(x, dtype=float)
    if discretisation != EULER:
        return x, velocity_from_position(x, dt, discretisation, restarts), 0
    position, velocity, lead = x.copy(), np.empty_like(x), 0
    for start, end in _pieces(len(x), restarts):
        smooth, window = _euler_smoothed(x[start:end])
        velocity[start:end] = _forward_difference(smooth, dt)
        if window > SMOOTHING_WINDOWS[0]:
            position[start:end] = smooth
            lead = max(lead, window // 2)
    return position, velocity, lead


#: Savitzky-Golay windows (samples) tried for the Euler plant's position smoothing.
SMOOTHING_WINDOWS = (7, 11, 15, 21, 31, 45, 65, 91)


def _smoothing_window(x: np.ndarray) -> int:
    """Return the widest cubic Savitzky-Golay window whose residual is still only noise.

    The noise's spread comes from fourth differences (``var(Δ⁴e) = 70·σ²`` for white noise; a
    smooth signal's are negligible); a window is accepted while the robust spread of
    ``x − smooth`` stays within 1.1 σ (a discrepancy principle). A noise-free position keeps
    the narrowest window.
    """
    if len(x) < 2 * SMOOTHING_WINDOWS[0]:
        return SMOOTHING_WINDOWS[0]
    sigma = robust_std(np.diff(x, 4)) / math.sqrt(70.0)
    if not sigma > 1e-6 * float(np.std(x)):
        return SMOOTHING_WINDOWS[0]
    window = SMOOTHING_WINDOWS[0]
    for candidate in SMOOTHING_WINDOWS[1:]:
        if len(x) < 2 * candidate:
            break
        residual = x - savgol_filter(x, candidate, 3)
        if robust_std(residual) > 1.1 * sigma:
            break
        window = candidate
    return window


def _euler_smoothed(x: np.ndarray) -> tuple[np.ndarray, int]:
    """Return ``(x smoothed for the Euler plant, its window)``; under 7 samples ``(x, 0)``."""
    if len(x) < 7:
        return x, 0
    window = _smoothing_window(x)
    return savgol_filter(x, window, 3), window


def _forward_difference(smooth: np.ndarray, dt: float) -> np.ndarray:
    """Return ``(x[k+1] − x[k])/dt``, the last sample repeating the one before."""
    velocity = np.empty_like(smooth)
    velocity[:-1] = np.diff(smooth) / dt
    velocity[-1] = velocity[-2]
    return velocity


def _piece_velocity(x: np.ndarray, dt: float, discretisation: str) -> np.ndarray:
    if discretisation != EULER and len(x) >= 5:
        return savgol_filter(x, 5, 3, deriv=1, delta=dt)
    return _forward_difference(_euler_smoothed(x)[0], dt)


def first_order_lag(u: np.ndarray, tau: float, dt: float, initial: float) -> np.ndarray:
    """Return ``y[k] = a·y[k−1] + (1−a)·u[k−1]``, ``y[0] = initial``, ``a = exp(−dt/tau)``.

    The contract's lag (:func:`dtwin.twin.paper_modules.lag_response`); ``tau ≤ 0`` (a fit's trial
    value) gives ``a = 0``, the input delayed by one sample.
    """
    a = lag_coefficient(tau, dt) if tau > 0 else 0.0
    return lag_response(u, a, initial)


def _effect_input(u: np.ndarray, effect: Effect | None, theta: Sequence[float], dt: float):
    if effect is None or effect.input_map is None:
        return u
    return effect.input_map(u, theta, dt)


def _pieces(stop: int, restarts: Sequence[int]) -> list[tuple[int, int]]:
    edges = [0, *(r for r in restarts if 0 < r < stop), stop]
    return list(itertools.pairwise(edges))


def _piecewise_lag(u: np.ndarray, tau: float, dt: float, initial: np.ndarray, restarts):
    """Return the lag restarted at each experiment boundary from ``initial[start]``."""
    out = np.empty(len(u))
    for start, end in _pieces(len(u), restarts):
        out[start:end] = first_order_lag(u[start:end], tau, dt, initial[start])
    return out


def _simulate_actuator(data, lin, effect, theta, stop, segments=None):
    u = _effect_input(data.inputs["u_cmd"][:stop], effect, theta, data.dt)
    return _piecewise_lag(u, lin["tau"], data.dt, data.output, data.restarts)


def _simulate_sensor(data, lin, effect, theta, stop, segments=None):
    x = _effect_input(data.inputs["x"][:stop], effect, theta, data.dt)
    lag = _piecewise_lag(x, lin["tau"], data.dt, x, data.restarts)
    bias = lin["bias"]
    if effect is None or effect.stage != "output":
        return lag + bias
    if effect.output_map is None:
        raise ValueError(f"effect {effect.name} cannot act on a sensor")
    return effect.output_map(lag, bias, data.t[:stop], theta)


def _force(effect: Effect | None, theta: Sequence[float], velocity_std: float, *, arrays: bool):
    """Return the candidate's plant force ``F(x, v)``, or None.

    With ``arrays`` it takes numpy arrays (ufuncs) and carries the same law on Python floats as
    its ``scalar`` attribute (:data:`dtwin.twin.exact.SCALAR_WINDOWS`), its largest velocity
    slope as its ``slope`` attribute (:func:`_velocity_slope`, which sets the exact plant's
    sub-steps) and, for a law the compiled loop knows, its name and parameters as its ``law``
    attribute (:mod:`dtwin.twin._force_kernels`).
    """
    if effect is None or effect.stage != "force":
        return None
    if effect.force_law is None:
        raise ValueError(f"effect {effect.name} cannot act on the plant")
    if arrays:
        force = effect.force_law(theta, velocity_std, ARRAY_OPS)
        force.scalar = effect.force_law(theta, velocity_std, SCALAR_OPS)
        force.law = _known_law(effect, theta, velocity_std)
        force.slope = _velocity_slope(force, velocity_std)
        return force
    return effect.force_law(theta, velocity_std, SCALAR_OPS)


def _velocity_slope(force, velocity_std: float) -> float:
    """Return the force's largest ``|∂F/∂v|`` at ``x = 0`` over ``|v| ≤ 4·std(v)``.

    Input units per velocity unit, by differences on a grid of 401 velocities over that range
    and 201 within five friction smoothings of rest (:data:`FRICTION_SMOOTHING`), fine enough
    for a friction's smoothed sign; 0 for a force that does not depend on the velocity.
    """
    spread = max(float(velocity_std), 1e-300)
    near = 5.0 * FRICTION_SMOOTHING * spread
    grid = np.unique(
        np.concatenate([np.linspace(-4.0, 4.0, 401) * spread, np.linspace(-near, near, 201)])
    )
    with np.errstate(all="ignore"):
        values = np.asarray(force(np.zeros_like(grid), grid), dtype=float)
        slopes = np.abs(np.diff(values) / np.diff(grid))
    slopes = slopes[np.isfinite(slopes)]
    return float(slopes.max()) if len(slopes) else 0.0


def _known_law(effect: Effect, theta: Sequence[float], velocity_std: float):
    """Return the effect's ``force_law`` as a :class:`~dtwin.twin._force_kernels.ForceLaw`, or None.

    The same law with the same parameters (the effect's ``compiled_law``), for the compiled
    loop.
    """
    from dtwin.twin._force_kernels import ForceLaw

    if effect.compiled_law is None:
        return None
    smooth = max(FRICTION_SMOOTHING * velocity_std, 1e-300)
    return ForceLaw(*effect.compiled_law([float(value) for value in theta], smooth))


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


#: A plant whose slowest mode decays this many times within the held-out part is stable enough
#: for long windows (a quarter of the held-out part).
STABLE_DECAYS = 10.0
#: Otherwise a window spans this many of the plant's fastest time constant.
HORIZON_TIME_CONSTANTS = 2.0
#: Shortest window, samples.
MIN_HORIZON = 20


def plant_horizon(lin: Mapping[str, float], dt: float, n_held: int) -> int:
    """Return the exact plant's simulation window in samples.

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
    int
        A quarter of the held-out part when the plant is stable, its slowest mode decaying
        ``STABLE_DECAYS`` times within the held-out part; otherwise (an integrating plant, or
        one too slow for the recording) ``HORIZON_TIME_CONSTANTS`` of its fastest time
        constant (the velocity's, for an integrating plant), at least ``MIN_HORIZON`` and at
        most a quarter of the held-out part.

    Notes
    -----
    docs/gap.md §Gaps. A free-run position error of an integrating plant grows without bound
    with any force error, and a closed-loop rig's free run is no prediction of anything, so the
    exact plant's gap is measured over windows restarted from the recording; a window of a few
    time constants is as long as a stable plant remembers its start, so for a stable plant the
    windows lose nothing a free run would show.
    """
    decay = -_plant_poles(lin).real
    longest = max(n_held // 4, MIN_HORIZON)
    if decay.min() * n_held * dt >= STABLE_DECAYS:
        return longest
    fastest = float(decay.max())
    if fastest <= 0:
        return longest
    return int(min(max(round(HORIZON_TIME_CONSTANTS / fastest / dt), MIN_HORIZON), longest))


def warmup_samples(horizon: int) -> int:
    """Return the samples at the start of a window that estimate its initial state.

    ``max(3, horizon // 5)``; they are not scored (docs/gap.md §Gaps). An initial velocity fitted
    to ``L`` noisy samples errs by ``∝ σ/(L^1.5·dt)``, carried for a time constant ``τ``: with
    ``L ∝ τ`` that error falls like ``1/√τ`` instead of growing like ``τ``.
    """
    return max(3, int(horizon) // 5)


def _window_states(data, u, m, c, k, windows, warmup, drive=None) -> tuple[np.ndarray, np.ndarray]:
    """Return the windows' initial states: least squares on each one's first ``warmup`` samples.

    The linear plant's forced response from rest is removed from the recorded position; the
    rest is the free response ``Φ·s₀`` (:func:`~dtwin.twin.exact.free_response_basis`). The
    forced response is simulated over the warm-ups only (it is causal: the same values as over
    the whole windows); ``drive`` is the hold's drive of ``u/m`` when the caller has it.
    """
    n = len(u)
    zeros = np.zeros(n)
    forced = exact_plant_response(
        u,
        m,
        c,
        k,
        data.dt,
        windows=[(a, a + warmup) for a, _ in windows],
        x_start=zeros,
        v_start=zeros,
        hold=data.discretisation,
        drive=drive,
    )
    solve = _warmup_solve(c / m, k / m, data.dt, data.discretisation, warmup)
    x0, v0 = zeros.copy(), zeros.copy()
    starts = np.array([a for a, _ in windows])
    rows = starts[:, None] + np.arange(warmup)
    states = (data.output[rows] - forced[rows]) @ solve.T
    x0[starts], v0[starts] = states[:, 0], states[:, 1]
    return x0, v0


@lru_cache(maxsize=256)
def _warmup_solve(c_per_m: float, k_per_m: float, dt: float, hold: str, warmup: int) -> np.ndarray:
    """Return ``Φ⁺``, shape ``(2, warmup)``: the warm-up's least-squares map to the initial state.

    ``Φ`` is the free response over the warm-up (:func:`~dtwin.twin.exact.free_response_basis`).
    Cached per argument tuple (both state estimates of a simulation, and every fit step that
    moves only the effect, ask for the same one): read-only.
    """
    solve = np.linalg.pinv(free_response_basis(hold_matrices(c_per_m, k_per_m, dt, hold), warmup))
    solve.flags.writeable = False
    return solve


def window_noise_gain(
    lin: Mapping[str, float], dt: float, hold: str, horizon: int, pole: float = 0.0
) -> float:
    """Return the variance factor of a window's error from measurement noise alone.

    Parameters
    ----------
    lin : mapping
        ``m, c, k`` of the plant.
    dt : float
        Sample period, s.
    hold : str
        The exact plant's hold.
    horizon : int
        Window length, samples.
    pole : float, default 0
        AR(1) pole ``a`` of the noise (correlation ``a^|i−j|`` between samples; 0: white).

    Returns
    -------
    float
        ``mean_k Var(e_k − φ_k·P·e_w)/σ²`` over the scored samples ``k`` of a window, with
        ``Φ`` the free response over the warm-up samples, ``P = Φ⁺`` the least-squares map from
        the warm-up noise ``e_w`` to the initial state and ``φ_k`` the free response at ``k``:
        ``1 + φ_k·P·R_ww·Pᵀ·φ_kᵀ − 2·φ_k·P·r_wk``. For white noise that is the prediction
        variance ``1 + φ_kᵀ(ΦᵀΦ)⁻¹φ_k``. Coloured noise counts fewer independent warm-up
        samples, so its initial state carries more of it forward (a rig with noise pole 0.7
        behind a 200-sample window: 1.26 white, more coloured).
    """
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    step = hold_matrices(c / m, k / m, dt, hold)
    warmup = warmup_samples(horizon)
    basis = free_response_basis(step, int(horizon))
    solve = np.linalg.pinv(basis[:warmup])  # (2, warmup): warm-up noise -> initial state
    scored = basis[warmup:]  # (scored, 2): free response at each scored sample
    if pole == 0.0:
        # φ_k·P·Pᵀ·φ_kᵀ with P·Pᵀ a 2×2 matrix: memory linear in the window
        return float(1.0 + np.mean(np.einsum("ij,jk,ik->i", scored, solve @ solve.T, scored)))
    a = float(pole)
    # P·R_ww·Pᵀ (2×2): the Toeplitz product R·x = Σ_j a^|i−j| x_j as two AR(1) recursions
    correlated = np.array([_ar1_toeplitz_product(row, a) for row in solve])  # (2, warmup)
    within = np.einsum("ij,jk,ik->i", scored, solve @ correlated.T, scored)
    # φ_k·P·r_wk with r_wk[j] = a^(warmup + k − j) = a^(k + 1)·a^(warmup − 1 − j)
    to_last = a ** np.arange(warmup - 1, -1, -1, dtype=float)  # (warmup,)
    ahead = a ** np.arange(1, scored.shape[0] + 1, dtype=float)  # (scored,)
    cross = (scored @ (solve @ to_last)) * ahead
    return float(1.0 + np.mean(within - 2.0 * cross))


def held_noise_autocovariance(
    lin: Mapping[str, float], dt: float, n_lags: int
) -> np.ndarray | None:
    """Return the position's autocovariance per unit acceleration noise held over each sample.

    Parameters
    ----------
    lin : mapping
        ``m, c, k`` of the plant.
    dt : float
        Sample period, s.
    n_lags : int
        Lags ``0 … n_lags−1`` returned.

    Returns
    -------
    numpy.ndarray, shape (n_lags,), or None
        ``(A^l·P)_xx`` (m² per (m/s²)²), with ``s[k+1] = A·s[k] + b·ξ[k]`` the zero-order hold
        of ``ẍ = ξ − (c/m)·ẋ − (k/m)·x`` (:func:`~dtwin.twin.exact.hold_matrices`: the
        continuous asset holds its acceleration noise over each sample) and ``P = A·P·Aᵀ +
        b·bᵀ`` its stationary covariance; None for a plant without one (integrating or
        unstable: no stationary variance).
    """
    from scipy.linalg import solve_discrete_lyapunov

    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    step = hold_matrices(c / m, k / m, dt, "zoh")
    if not np.max(np.abs(np.linalg.eigvals(step.a))) < 1.0 - 1e-9:
        return None
    b = step.taps[0][:, None]
    state = solve_discrete_lyapunov(step.a, b @ b.T)
    out = np.empty(int(n_lags))
    for lag in range(int(n_lags)):
        out[lag] = state[0, 0]
        state = step.a @ state
    return out


def window_error_covariance(
    lin: Mapping[str, float],
    dt: float,
    hold: str,
    horizon: int,
    length: int,
    autocovariance: np.ndarray,
) -> np.ndarray:
    """Return the covariance of a window's error on its scored samples from a stationary noise.

    Parameters
    ----------
    lin : mapping
        ``m, c, k`` of the plant.
    dt : float
        Sample period, s.
    hold : str
        The exact plant's hold.
    horizon : int
        The plant's window (sets the warm-up, :func:`warmup_samples`).
    length : int
        This window's length, samples (the last window of a recording may be longer).
    autocovariance : array, shape (≥ length,)
        The noise's autocovariance at lags ``0 … length−1`` (output units²).

    Returns
    -------
    numpy.ndarray, shape (length − warm-up, length − warm-up)
        ``G·T·Gᵀ`` with ``T`` the noise's Toeplitz covariance over the window and
        ``G = [−Φ_s·Φ_w⁺, I]``: the error at a scored sample is the noise there less the free
        response ``Φ_s`` of the initial state fitted to the warm-up's noise (``Φ_w⁺``), as over
        the windows of :func:`simulate_module`. Its mean diagonal over ``autocovariance[0]`` is
        :func:`window_noise_gain` for AR(1) noise.
    """
    from scipy.linalg import toeplitz

    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    warmup = warmup_samples(horizon)
    basis = free_response_basis(hold_matrices(c / m, k / m, dt, hold), int(length))
    carried = basis[warmup:] @ np.linalg.pinv(basis[:warmup])  # (scored, warmup)
    spread = np.hstack([-carried, np.eye(int(length) - warmup)])
    return spread @ toeplitz(np.asarray(autocovariance, dtype=float)[: int(length)]) @ spread.T


def _ar1_toeplitz_product(values: np.ndarray, pole: float) -> np.ndarray:
    """Return ``R·values`` with ``R[i, j] = pole^|i−j|`` without forming ``R`` (O(n) memory).

    ``Σ_{j≤i} pole^(i−j) x_j + Σ_{j≥i} pole^(j−i) x_j − x_i``: a forward and a backward
    first-order recursion.
    """
    forward = lfilter([1.0], [1.0, -pole], values)
    backward = lfilter([1.0], [1.0, -pole], values[::-1])[::-1]
    return forward + backward - values


#: Gauss–Newton steps, at most, of a window's initial state under a candidate force.
STATE_ITERATIONS = 8
#: The Gauss–Newton steps stop when one changes the warm-ups' fit by less than this share of
#: its RMS residual.
STATE_TOLERANCE = 1e-8
#: A window keeps the force-felt state when the velocity's memory under the force somewhere in
#: its warm-up, ``m/|∂F/∂v|``, is shorter than this share of the warm-up (docs/gap.md §Gaps).
STIFF_MEMORY = 0.1


def _velocity_memory(force, x: np.ndarray, v: np.ndarray, m: float, spread: float) -> np.ndarray:
    """Return each window's shortest velocity memory ``|m|/|∂F/∂v|`` over its warm-up, s.

    ``x``, ``v``: positions and velocities, shape ``(n_windows, warmup)``; ``spread`` is the
    velocity's scale (``std(v)``), whose friction smoothing (:data:`FRICTION_SMOOTHING`) the
    central difference resolves. A slope that is not finite counts as 0 (infinite memory).
    """
    step = 1e-3 * FRICTION_SMOOTHING * (spread or 1.0)
    with np.errstate(all="ignore"):
        slope = np.abs(force(x, v + step) - force(x, v - step)) / (2.0 * step)
        slope = np.max(np.where(np.isfinite(slope), slope, 0.0), axis=1)
        return np.where(slope > 0, abs(m) / slope, np.inf)


#: Width of the band, a factor in the velocity memory above :data:`STIFF_MEMORY` of the
#: warm-up, over which a window's state passes from the force-felt one to the fitted one.
STIFF_BAND = 2.0


def _stiff_weight(ratio: np.ndarray) -> np.ndarray:
    """Return the force-felt state's weight from ``memory / (STIFF_MEMORY·warm-up)``, shape kept.

    1 up to 1 (stiff), 0 from :data:`STIFF_BAND` on, a smoothstep in ``ln ratio`` between, so
    that a window's state, and the fit's error, do not jump as a candidate's parameters move
    its warm-up across the limit (a hard limit put steps of 0.7 % into a closed-loop rig's
    Coulomb training error, and its fit stopped at Fc 276 for a true 346).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.log(ratio) / np.log(STIFF_BAND), 0.0, 1.0)
    s = np.where(np.isnan(s), 1.0, s)  # no memory to measure: fitted, as not stiff
    return 1.0 - s * s * (3.0 - 2.0 * s)


def _force_window_states(data, u, mck, windows, warmup, force, drive, linear_states):
    """Return the windows' initial states fitted to the warm-ups with the force in the model.

    ``(x_start, v_start)``, each shape ``(n_samples,)``, set at the windows' first samples. The
    state minimises the warm-up's squared error of the simulation *with* the force (the
    least-squares estimate under the candidate's own model, as the linear
    :func:`_window_states` is under the linear one): a start from the linear states, a second
    from the force felt at the recorded position and that simulation's velocity, then
    Gauss–Newton steps with a finite-difference Jacobian, all windows at once, each window
    keeping a step only when it lowers its own error. One pass of the force felt alone (the
    former estimate) left a rig's strong quadratic damping (its force 1.2 times the viscous
    one) in a feedback loop, windows of 750 samples, at a gap of 0.28 with its true
    parameters against a noise floor of 0.015.

    A window whose warm-up passes where the force is stiff (its velocity memory
    ``m/|∂F/∂v|``, :func:`_velocity_memory`, below :data:`STIFF_MEMORY` of the warm-up: a
    friction's smoothed sign through rest) keeps the force-felt state: there the warm-up
    determines the initial velocity only through the law's steepest part, the catalogue's
    least faithful one, and its least-squares state carried that misfit into the friction
    level (the measured EMPS axis: 4 of 31 windows, memory 0.04 of the warm-up, against 84 or
    more for the rest and about 1 for the strong quadratic damping above, moved Fc from
    20.8 to 21.5 N).
    """
    m, c, k = mck
    starts = np.array([a for a, _ in windows])
    rows = starts[:, None] + np.arange(warmup)
    recorded = data.output[rows]

    def warm_errors(x0, v0, chosen):
        """Warm-up simulation of the ``chosen`` windows and each one's squared error."""
        x_from, v_from = np.zeros(len(u)), np.zeros(len(u))
        x_from[starts[chosen]], v_from[starts[chosen]] = x0, v0
        sim = exact_plant_response(
            u,
            m,
            c,
            k,
            data.dt,
            windows=[(int(a), int(a) + warmup) for a in starts[chosen]],
            x_start=x_from,
            v_start=v_from,
            hold=data.discretisation,
            force=force,
            drive=drive,
        )[rows[chosen]]
        sse = np.sum((recorded[chosen] - sim) ** 2, axis=1)
        return sim, np.where(np.isfinite(sse), sse, np.inf)

    every = np.arange(len(starts))
    x0, v0 = linear_states[0][starts], linear_states[1][starts]
    sim, sse = warm_errors(x0, v0, every)
    # the force felt during the warm-ups: at the recorded position (a simulated one from a
    # state that ignored the force fed back: a strong cubic spring's windows diverged, 0.48
    # for the true model against 0.06 so), at this simulation's velocity (a noisy position
    # differentiates badly)
    velocity = np.gradient(sim, axis=1) / data.dt
    felt = np.zeros(len(u))
    felt[rows] = force(recorded, velocity)
    felt = np.nan_to_num(felt, nan=0.0, posinf=0.0, neginf=0.0)
    x_felt, v_felt = _window_states(data, u - felt, m, c, k, windows, warmup)
    x_felt, v_felt = x_felt[starts], v_felt[starts]
    spread = data.scales.velocity_std if data.scales else 1.0
    memory = _velocity_memory(force, recorded, velocity, m, spread)
    felt_weight = _stiff_weight(memory / (STIFF_MEMORY * warmup * data.dt))
    refine = np.flatnonzero(felt_weight < 1.0)
    x_fit, v_fit = x0.copy(), v0.copy()
    if len(refine):
        x_fit[refine], v_fit[refine] = _gauss_newton_states(
            warm_errors,
            recorded[refine],
            refine,
            (x0[refine], v0[refine]),
            sim[refine],
            sse[refine],
            (x_felt[refine], v_felt[refine]),
            data,
            warmup,
        )
    x0 = felt_weight * x_felt + (1.0 - felt_weight) * x_fit
    v0 = felt_weight * v_felt + (1.0 - felt_weight) * v_fit
    x_start, v_start = np.zeros(len(u)), np.zeros(len(u))
    x_start[starts], v_start[starts] = x0, v0
    return x_start, v_start


def _gauss_newton_states(warm_errors, recorded, chosen, linear, sim, sse, felt, data, warmup):
    """Return ``(x0, v0)`` of the ``chosen`` windows: the better start, then Gauss–Newton steps.

    ``warm_errors(x0, v0, chosen)`` simulates their warm-ups; ``linear`` and ``felt`` are the
    two starts, ``sim`` and ``sse`` the linear start's simulation and errors.
    """
    x0, v0 = linear
    sim_felt, sse_felt = warm_errors(*felt, chosen)
    better = sse_felt <= sse
    x0, v0 = np.where(better, felt[0], x0), np.where(better, felt[1], v0)
    sim, sse = np.where(better[:, None], sim_felt, sim), np.minimum(sse, sse_felt)
    h_x = 1e-6 * (float(np.std(data.output)) or 1.0)
    h_v = h_x / (warmup * data.dt)
    for _ in range(STATE_ITERATIONS):
        residual = np.nan_to_num(recorded - sim, nan=0.0, posinf=0.0, neginf=0.0)
        d_x = (warm_errors(x0 + h_x, v0, chosen)[0] - sim) / h_x
        d_v = (warm_errors(x0, v0 + h_v, chosen)[0] - sim) / h_v
        jac = np.stack([d_x, d_v], axis=2)  # (n_windows, warmup, 2)
        normal = np.einsum("wki,wkj->wij", jac, jac)
        rhs = np.einsum("wki,wk->wi", jac, residual)
        finite = np.isfinite(normal).all(axis=(1, 2)) & np.isfinite(rhs).all(axis=1)
        step = np.zeros((len(chosen), 2))
        if finite.any():
            ridge = 1e-12 * np.trace(normal[finite], axis1=1, axis2=2)[:, None, None]
            system = normal[finite] + ridge * np.eye(2)
            step[finite] = np.linalg.solve(system, rhs[finite][:, :, None])[:, :, 0]
        moved = np.sqrt(np.sum(np.einsum("wki,wi->wk", np.nan_to_num(jac), step) ** 2))
        trial_sim, trial_sse = warm_errors(x0 + step[:, 0], v0 + step[:, 1], chosen)
        keep = trial_sse < sse
        x0, v0 = np.where(keep, x0 + step[:, 0], x0), np.where(keep, v0 + step[:, 1], v0)
        sim, sse = np.where(keep[:, None], trial_sim, sim), np.where(keep, trial_sse, sse)
        if not keep.any() or moved <= STATE_TOLERANCE * np.sqrt(np.sum(residual**2)):
            break
    return x0, v0


def _exact_plant(data, lin, u, force, stop, segments, keep_warmup=False):
    """Simulate the exact plant over its windows (NaN on unscored warm-up samples).

    ``keep_warmup``: the warm-up samples keep the simulation (:func:`profiled_window_error`).

    With a force, each window's initial state is the least-squares fit of the warm-up by the
    simulation with that force (:func:`_force_window_states`; the force acts during the
    warm-up too: ignoring it biased the state so much that a rig's true Coulomb friction fitted
    worse than none).
    """
    windows = segments or plant_windows(stop, data.horizon, data.restarts)
    windows = [(a, min(b, stop)) for a, b in windows if a < stop]
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    x_start, v_start = data.output, data.velocity
    warmup = None
    # the input's drive, once for the warm-ups' states and the windows (the same u, m, c, k)
    drive = hold_matrices(c / m, k / m, data.dt, data.discretisation).drive(
        np.asarray(u, dtype=float) / m, windows
    )
    if data.horizon is not None:
        warmup = warmup_samples(data.horizon)
        windows = [(a, b) for a, b in windows if b - a > warmup]
        x_start, v_start = _window_states(data, u, m, c, k, windows, warmup, drive)

    substeps = force_substeps(force.slope, m, data.dt) if force is not None else 1

    def run(x_from, v_from):
        return exact_plant_response(
            u,
            m,
            c,
            k,
            data.dt,
            windows=windows,
            x_start=x_from,
            v_start=v_from,
            hold=data.discretisation,
            force=force,
            drive=drive,
            substeps=substeps,
        )

    if warmup is not None and force is not None:
        with np.errstate(all="ignore"):  # a diverging trial step is rejected, not an error
            x_start, v_start = _force_window_states(
                data, u, (m, c, k), windows, warmup, force, drive, (x_start, v_start)
            )
    out = run(x_start, v_start)
    if warmup is not None:
        covered = np.zeros(len(out), dtype=bool)
        for a, b in windows:
            if not keep_warmup:
                out[a : a + warmup] = np.nan
            covered[a:b] = True
        out[~covered] = np.nan
    return out


def _simulate_plant(data, lin, effect, theta, stop, segments, keep_warmup=False):
    u = data.inputs["u_act"][:stop]
    delay = int(lin.get("delay_samples", 0))
    if delay:
        u = fractional_delay(u, delay)
    exact = data.discretisation != EULER
    velocity_std = data.scales.velocity_std if data.scales else 1.0
    force = _force(effect, theta, velocity_std, arrays=exact)
    if exact:
        u = u - lin.get("u_offset", 0.0)
        return _exact_plant(data, lin, u, force, stop, segments, keep_warmup)
    segments = segments or (plant_windows(stop, None, data.restarts) if data.restarts else None)
    u = u - lin.get("u_offset", 0.0)
    step = _euler_stepper(effect, theta, velocity_std, force)
    x_rec, v_rec = data.output, data.velocity
    x_start = data.position if data.position is not None else x_rec
    out = np.zeros(len(u))
    limit = 1e6 * (np.abs(x_rec).max() + 1e-12)
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    for start, end in segments or [(0, len(u))]:
        first = start + data.lead if end - start > 4 * data.lead else start
        out[start:first] = np.nan  # unscored lead (docs/gap.md §Gaps)
        out[first:end] = step(u[first:end], m, c, k, data.dt, x_start[first], v_rec[first], limit)
    return out


def _euler_stepper(effect: Effect | None, theta: Sequence[float], velocity_std: float, force):
    """Return ``step(u, m, c, k, dt, x0, v0, limit) → x``: the Euler plant's positions.

    :func:`~dtwin.twin.paper_modules.plant_response` (``force`` the candidate's scalar law, or
    None), or, where numba is installed and the force is None or a law the compiled loop knows, the
    same loop compiled (:func:`dtwin.twin._force_kernels.euler_response`: the same bits, ~30×
    faster).
    """
    law = _known_law(effect, theta, velocity_std) if force is not None and HAVE_NUMBA else None
    if HAVE_NUMBA and (force is None or law is not None):
        from dtwin.twin._force_kernels import euler_response

        def compiled(u, m, c, k, dt, x0, v0, limit):
            return euler_response(u, m, c, k, dt, x0, v0, law, limit)[0]

        return compiled

    def plain(u, m, c, k, dt, x0, v0, limit):
        return plant_response(u.tolist(), m, c, k, dt, x0=x0, v0=v0, force=force, limit=limit).x

    return plain


def profiled_window_error(
    data: ModuleData,
    lin: Mapping[str, float],
    effect: Effect | None = None,
    theta: Sequence[float] = (),
) -> np.ndarray:
    """Return the output error of a module's twin with each window's initial state profiled out.

    Parameters
    ----------
    data : ModuleData
        The module's recorded signals; the exact plant's windows are ``data.horizon`` samples
        (:func:`plant_windows`).
    lin : mapping
        The module's linear parameters.
    effect : Effect, optional
        A candidate effect, at ``theta``.
    theta : sequence of float
        The effect's parameters.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)
        ``recorded − predicted``. For the windowed exact plant: over every sample of each
        window, warm-up included, less its least-squares projection on the linear plant's free
        response from the window's start (``lin``'s ``c/m, k/m``:
        :func:`~dtwin.twin.exact.free_response_basis`), i.e. the error with the window's
        initial position and velocity fitted to the whole window (to first order in them when
        the effect's force depends on the state); NaN outside the windows. Any other module:
        the plain simulation error.

    Notes
    -----
    docs/gap.md §Where (the nested test). A window's initial state is a nuisance parameter of
    every model compared; estimated from the warm-up alone it errs, and the error's free
    response (a drift of an integrating plant, a ringing of a resonant one) is in every
    window, so a candidate force that damps it lowers a linear twin's error on clean data (a
    clean closed-loop rig: likelihood ratio 360 against a critical 9.1, -18 profiled).
    """
    if data.role != PLANT or data.discretisation == EULER or data.horizon is None:
        return data.output - simulate_module(data, lin, effect, theta)
    stop = data.n_samples
    error = data.output - _simulate_plant(data, lin, effect, theta, stop, None, keep_warmup=True)
    m, c, k = float(lin["m"]), float(lin["c"]), float(lin["k"])
    step = hold_matrices(c / m, k / m, data.dt, data.discretisation)
    warmup = warmup_samples(data.horizon)
    by_length: dict[int, list[int]] = {}
    for a, b in plant_windows(stop, data.horizon, data.restarts):
        if b - a > warmup:
            by_length.setdefault(b - a, []).append(a)
    for length, starts in by_length.items():
        rows = np.asarray(starts)[:, None] + np.arange(length)
        basis = free_response_basis(step, length)
        segments = error[rows]
        finite = np.all(np.isfinite(segments), axis=1)
        fitted = np.linalg.pinv(basis) @ segments[finite].T
        segments[finite] -= (basis @ fitted).T
        segments[~finite] = np.nan
        error[rows] = segments
    return error


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
    return _SIMULATORS[data.role](data, lin, effect, theta, stop, segments)


def _simulate_fusion(data, lin, effect, theta, stop, segments):
    return fuse(data.inputs["y_A"][:stop], data.inputs["y_B"][:stop], lin["alpha"])


def _simulate_kpi(data, lin, effect, theta, stop, segments):
    return kpi(data.inputs["x"][:stop], data.velocity[:stop], lin["w1"], lin["w2"])


#: Each role's simulator ``(data, lin, effect, theta, stop, segments) → (stop,)`` array.
_SIMULATORS = {
    ACTUATOR: _simulate_actuator,
    PLANT: _simulate_plant,
    SENSOR: _simulate_sensor,
    FUSION: _simulate_fusion,
    KPI: _simulate_kpi,
}
