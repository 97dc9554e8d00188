"""The module contract: each module's parameters, signals, noise and recursion, defined once.

The six modules of the paper's pipeline (§3.1, r_notes.md §1) are written here once and used by
the paper simulator (:mod:`dtwin.physics`), the gap diagnoser's module twins
(:mod:`dtwin.gap.models`, :mod:`dtwin.gap.noise`) and the gap generator's asset
(:mod:`dtwin.gapbench.generator`), in the way python-control's interconnected systems keep each
subsystem's law apart from the wiring (:data:`dtwin.twin.wiring.MODULES`). Arrays are time-first,
shape ``(n_steps,)``.

Each :class:`ModuleContract` names the module's linear parameters (the fields of its
:class:`dtwin.params.TwinParams` section), its noise channel and its law; the laws are:

- ``lag`` (M0, M2a, M2b): ``y[k] = a·y[k−1] + (1−a)·u[k−1]`` with ``a = exp(−dt/τ)``
  (:func:`lag_coefficient`, :func:`lag_response`); a sensor adds its ``bias``;
- ``plant`` (M1): ``m·ẍ = u − c·ẋ − k·x − F(x, ẋ)`` discretised by :func:`plant_response`;
- ``fusion`` (M3): :func:`fuse`; ``kpi`` (M4): :func:`kpi`.

**Discretisation** is a property of the contract, chosen per call: :data:`EULER`, the paper's
scheme and what every current user gets (explicit Euler for the plant; the lag's
``exp(−dt/τ)`` is already the exact zero-order-hold coefficient), or :data:`ZOH`, the exact
zero-order-hold discretisation of the plant (matrix exponential; :func:`plant_matrices`), which
the diagnoser will need for measured rigs sampled fast.

**Hooks** (:attr:`ModuleContract.hooks`) are the points where an unmodelled effect enters:
``input`` (a map or delay on the module input, applied by the caller before the law), ``force``
(an extra force ``F(x, v)`` in the plant, the ``force`` argument of :func:`plant_response`) and
``output`` (a map on the module output, applied by the caller after the law). The generator
injects its real effects there; the diagnoser's candidates use the same points.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from dtwin._lfilter import lfilter
from dtwin.twin.wiring import MODULES, Module

__all__ = [
    "EULER",
    "ZOH",
    "FOH",
    "DISCRETISATIONS",
    "BANDLIMITED",
    "require_discretisation",
    "Force",
    "ModuleContract",
    "CONTRACTS",
    "LINEAR_PARAMS",
    "Step",
    "run_modules",
    "lag_coefficient",
    "lag_response",
    "PlantMatrices",
    "plant_matrices",
    "PlantTrajectory",
    "plant_response",
    "fuse",
    "kpi",
]

#: The paper's discretisation: explicit Euler for the plant, ``exp(−dt/τ)`` for the lags.
EULER = "euler"
#: Exact zero-order-hold discretisation (the plant through the matrix exponential).
ZOH = "zoh"
#: Exact first-order-hold discretisation: the input linear between samples.
FOH = "foh"
#: Exact discretisation of a band-limited input (a windowed-sinc interpolation of the samples).
BANDLIMITED = "bandlimited"
#: Every discretisation a twin file may name (the exact ones: :mod:`dtwin.twin.exact`).
DISCRETISATIONS: tuple[str, ...] = (EULER, ZOH, FOH, BANDLIMITED)


@dataclass(frozen=True)
class ModuleContract:
    """What one module is: its wiring entry, parameters, noise channel, law and effect hooks.

    Attributes
    ----------
    module : dtwin.twin.wiring.Module
        The wiring entry (name, input and output signals, parameter section).
    law : str
        ``"lag"``, ``"plant"``, ``"fusion"`` or ``"kpi"`` (see the module docstring).
    params : tuple of str
        The linear parameters, fields of the module's :class:`dtwin.params.TwinParams` section.
    dynamic_params : tuple of str
        The parameters of the recursion (time constants, ``m, c, k``), a subset of ``params``.
    noise : str or None
        The module's field of :class:`dtwin.params.NoiseParams`, named as its section (None: the
        module is noise-free).
    hooks : tuple of str
        Where an unmodelled effect may enter: ``"input"``, ``"force"``, ``"output"``.
    """

    module: Module
    law: str
    params: tuple[str, ...]
    dynamic_params: tuple[str, ...]
    noise: str | None
    hooks: tuple[str, ...]

    @property
    def name(self) -> str:
        """The paper label (``"M1"``)."""
        return self.module.name

    @property
    def section(self) -> str:
        """The module's section of :class:`dtwin.params.TwinParams` (``"plant"``)."""
        return self.module.section

    @property
    def output(self) -> str:
        """The module's output signal proper (``"x"`` for the plant)."""
        return self.module.output


#: Each module's law, linear parameters, parameters of its recursion, whether it has a noise
#: channel (named as its section) and its effect hooks; keyed by :data:`dtwin.twin.wiring.MODULES`.
_LAWS: dict[str, tuple[str, tuple[str, ...], tuple[str, ...], bool, tuple[str, ...]]] = {
    "M0": ("lag", ("tau",), ("tau",), True, ("input",)),
    "M1": ("plant", ("m", "c", "k"), ("m", "c", "k"), True, ("input", "force")),
    "M2a": ("lag", ("tau", "bias"), ("tau",), True, ("input", "output")),
    "M2b": ("lag", ("tau", "bias"), ("tau",), True, ("input", "output")),
    "M3": ("fusion", ("alpha",), (), False, ()),
    "M4": ("kpi", ("w1", "w2"), (), False, ()),
}


def _contract(module: Module) -> ModuleContract:
    law, params, dynamic_params, noisy, hooks = _LAWS[module.name]
    noise = module.section if noisy else None
    return ModuleContract(module, law, params, dynamic_params, noise, hooks)


#: The contract of every module, keyed and ordered as :data:`dtwin.twin.wiring.MODULES`.
CONTRACTS: dict[str, ModuleContract] = {module.name: _contract(module) for module in MODULES}

#: The linear parameters of each module (a view of :data:`CONTRACTS`).
LINEAR_PARAMS: dict[str, tuple[str, ...]] = {name: c.params for name, c in CONTRACTS.items()}


#: One module's step in a chain: the signals so far (by name, each ``(n_steps,)``) → the
#: module's outputs (some of its :attr:`dtwin.twin.wiring.Module.outputs`), or None when it cannot
#: run (an input is missing).
Step = Callable[[Mapping[str, np.ndarray]], Mapping[str, np.ndarray] | None]


def run_modules(
    steps: Mapping[str, Step], given: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Run the modules that have a step, in the wiring's order; return the signals they wrote.

    The one chain runner: the paper simulator (:func:`dtwin.physics.simulate_physics`), every
    generated asset (:mod:`dtwin.gapbench.generator`) and the diagnoser's chain
    (:func:`dtwin.gap.localise.run_chain`) differ only in their steps.

    Parameters
    ----------
    steps : mapping of module name to Step
        What each module does; a module without a step is not run.
    given : mapping of str to array
        The signals known before the chain runs (a command, a recording).

    Returns
    -------
    dict of str to numpy.ndarray
        Every signal a step wrote, in module order. Each step sees ``given`` overlaid by the
        signals written before it.

    Raises
    ------
    ValueError
        If a step writes a signal that is not one of its module's outputs.

    Examples
    --------
    >>> steps = {"M3": lambda s: {"y_fused": fuse(s["y_A"], s["y_B"], 0.5)}}
    >>> run_modules(steps, {"y_A": np.ones(2), "y_B": np.zeros(2)})["y_fused"].tolist()
    [0.5, 0.5]
    """
    written: dict[str, np.ndarray] = {}
    for module in MODULES:
        step = steps.get(module.name)
        if step is None:
            continue
        outputs = step({**given, **written})
        if outputs is None:
            continue
        stray = sorted(set(outputs) - set(module.outputs))
        if stray:
            raise ValueError(f"module {module.name} may write {module.outputs}, not {stray}")
        written.update(outputs)
    return written


def require_discretisation(discretisation: str, allowed: tuple[str, ...] = DISCRETISATIONS) -> None:
    """Raise ValueError unless ``discretisation`` is one of ``allowed``."""
    if discretisation not in allowed:
        raise ValueError(
            f"discretisation must be one of {', '.join(allowed)} (got {discretisation!r})"
        )


# --- the lag (M0, M2a, M2b) ---------------------------------------------------------------


def lag_coefficient(tau: float, dt: float, discretisation: str = EULER) -> float:
    """Return the first-order lag's pole ``a = exp(−dt/τ)``.

    Parameters
    ----------
    tau : float
        Time constant, s (> 0).
    dt : float
        Sample period, s.
    discretisation : {"euler", "zoh"}, default "euler"
        Both give ``exp(−dt/τ)``: the paper's lag is already the exact zero-order-hold one.

    Returns
    -------
    float

    Notes
    -----
    Computed with :func:`math.exp`, the one lag pole of dtwin (the paper simulator, the gap
    diagnoser and its generator). ``numpy.exp`` can differ from it in the last bit for a few
    percent of arguments, not for the paper's time constants (0.15, 0.08 and 0.25 s at 0.02 s).

    Examples
    --------
    >>> round(lag_coefficient(0.15, 0.02), 6)
    0.875173
    """
    require_discretisation(discretisation)
    return math.exp(-dt / tau)


def lag_response(u: np.ndarray, a: float, initial: float | None = None) -> np.ndarray:
    """Return the delayed first-order lag of ``u``, shape ``(n_steps,)``.

    Parameters
    ----------
    u : array, shape (n_steps,)
        Input (any unit).
    a : float
        Pole (:func:`lag_coefficient`).
    initial : float, optional
        ``y[0]``; its free response ``initial·a^k`` is added. None: ``y[0] = 0`` and nothing is
        added (the paper simulator's start at rest).

    Returns
    -------
    numpy.ndarray, shape (n_steps,)

    Notes
    -----
    Paper §3.1 M0/M2: ``y[k] = a·y[k−1] + (1−a)·u[k−1]`` (one-sample input delay), as one
    linear filter.

    Examples
    --------
    >>> np.round(lag_response(np.ones(4), 0.5), 4).tolist()
    [0.0, 0.5, 0.75, 0.875]
    """
    response = lfilter([0.0, 1.0 - a], [1.0, -a], u)
    if initial is None:
        return response
    return response + initial * np.power(a, np.arange(len(u)))


# --- the plant (M1) -----------------------------------------------------------------------


class PlantMatrices(NamedTuple):
    """The discrete plant ``s[k] = A·s[k−1] + b_force·u[k−1] + b_accel·ξ[k]``, ``s = (x, v)``.

    ``a`` has shape (2, 2); ``b_force`` (2, 1) per unit force; ``b_accel`` (2, 1) per unit
    acceleration (the process noise ``ξ``).
    """

    a: np.ndarray
    b_force: np.ndarray
    b_accel: np.ndarray


def plant_matrices(
    m: float, c: float, k: float, dt: float, discretisation: str = EULER
) -> PlantMatrices:
    """Return the discrete state-space matrices of the mass-spring-damper.

    Parameters
    ----------
    m, c, k : float
        Mass (kg), viscous damping (N·s/m), stiffness (N/m).
    dt : float
        Sample period, s.
    discretisation : {"euler", "zoh"}, default "euler"
        Explicit Euler (the paper's) or the exact zero-order hold.

    Returns
    -------
    PlantMatrices

    Notes
    -----
    Continuous ``ṡ = F·s + g·(u/m + ξ)``, ``F = [[0, 1], [−k/m, −c/m]]``, ``g = (0, 1)ᵀ``.
    Euler: ``A = I + dt·F``, ``b_accel = dt·g``. Zero-order hold: ``A = exp(F·dt)``,
    ``b_accel = ∫₀^dt exp(F·s) ds·g`` (one matrix exponential of the augmented matrix).
    In both ``b_force = b_accel/m``. Other holds: :func:`dtwin.twin.exact.hold_matrices`.
    """
    require_discretisation(discretisation, (EULER, ZOH))
    if discretisation == EULER:
        a = np.array([[1.0, dt], [-dt * k / m, 1.0 - dt * c / m]])
        b_accel = np.array([[0.0], [dt]])
    else:
        augmented = np.zeros((3, 3))
        augmented[:2, :2] = [[0.0, 1.0], [-k / m, -c / m]]
        augmented[1, 2] = 1.0
        from scipy.linalg import expm  # on first use: figures import this module for fuse/kpi

        exact = expm(augmented * dt)
        a, b_accel = exact[:2, :2], exact[:2, 2:]
    return PlantMatrices(a, b_accel / m, b_accel)


class PlantTrajectory(NamedTuple):
    """Plant states, each shape ``(n_steps,)``: position ``x`` (m) and velocity ``v`` (m/s)."""

    x: np.ndarray
    v: np.ndarray


Force = Callable[[float, float], float]


def plant_response(
    u: Sequence[float],
    m: float,
    c: float,
    k: float,
    dt: float,
    *,
    x0: float = 0.0,
    v0: float = 0.0,
    force: Force | None = None,
    accel_noise: Sequence[float] | None = None,
    limit: float | None = None,
    discretisation: str = EULER,
) -> PlantTrajectory:
    """Return the plant's position and velocity driven by the force ``u``.

    Parameters
    ----------
    u : sequence of float, length n_steps
        Force input, N; ``u[k−1]`` drives step ``k``.
    m, c, k : float
        Mass (kg), viscous damping (N·s/m), stiffness (N/m).
    dt : float
        Sample period, s.
    x0, v0 : float, default 0
        State at step 0 (the paper starts at rest; the diagnoser from the recorded state).
    force : callable, optional
        The ``force`` hook: an extra force ``F(x, v)`` (N) opposing the motion.
    accel_noise : sequence of float, length n_steps, optional
        ``ξ[k]`` added to the acceleration of step ``k`` (element 0 unused), m/s².
    limit : float, optional
        Divergence guard: once ``|x|`` reaches ``limit`` (or is NaN) the rest of ``x`` is
        ``limit`` and ``v`` is left at 0.
    discretisation : {"euler", "zoh"}, default "euler"
        Explicit Euler (the paper's; every current user) or the exact zero-order hold.

    Returns
    -------
    PlantTrajectory
        ``x`` and ``v``, each shape ``(n_steps,)``.

    Notes
    -----
    Paper §3.1 M1 with explicit Euler:
    ``acc = (u[k−1] − c·v[k−1] − k·x[k−1] − F(x[k−1], v[k−1]))/m + ξ[k]``,
    ``v[k] = v[k−1] + dt·acc``, ``x[k] = x[k−1] + dt·v[k−1]`` (position uses the old
    velocity). The arithmetic is done in this order, on the element types given, so every user
    gets the same bits as its former copy of the loop. The gap diagnoser's exact plant is
    :func:`dtwin.twin.exact.exact_plant_response`.
    """
    require_discretisation(discretisation, (EULER, ZOH))
    n_steps = len(u)
    xs = np.zeros(n_steps)
    vs = np.zeros(n_steps)
    if n_steps == 0:
        return PlantTrajectory(xs, vs)
    xs[0], vs[0] = x0, v0
    if discretisation == ZOH:
        _zoh_loop(u, plant_matrices(m, c, k, dt, ZOH), k, force, accel_noise, xs, vs)
    elif accel_noise is None:
        _euler_loop(u, m, c, k, dt, force, limit, xs, vs)
    else:
        _euler_noise_loop(u, m, c, k, dt, force, accel_noise, xs, vs)
    return PlantTrajectory(xs, vs)


def _euler_loop(u, m, c, k, dt, force, limit, xs, vs) -> None:
    """Noise-free explicit Euler from ``(xs[0], vs[0])``, with the divergence guard."""
    x, v = xs[0].item(), vs[0].item()
    positions = [x] * len(u)
    velocities = [v] * len(u)
    for j in range(1, len(u)):
        f = force(x, v) if force is not None else 0.0
        a = (u[j - 1] - c * v - k * x - f) / m
        x, v = x + dt * v, v + dt * a
        positions[j], velocities[j] = x, v
        if limit is not None and not -limit < x < limit:
            positions[j:] = [limit] * (len(u) - j)
            velocities[j:] = [0.0] * (len(u) - j)
            break
    xs[:] = positions
    vs[:] = velocities


def _euler_noise_loop(u, m, c, k, dt, force, noise, xs, vs) -> None:
    """Explicit Euler with acceleration noise ``noise[j]`` added at step ``j``."""
    x, v = xs[0], vs[0]
    for j in range(1, len(u)):
        f = force(x, v) if force is not None else 0.0
        accel = (u[j - 1] - c * v - k * x - f) / m + noise[j]
        x, v = x + dt * v, v + dt * accel
        xs[j], vs[j] = x, v


def _zoh_loop(u, matrices: PlantMatrices, k, force, noise, xs, vs) -> None:
    """Zero-order-hold steps ``s[j] = A·s[j−1] + b_force·(u[j−1] − F) + b_accel·ξ[j]``."""
    a, b_force, b_accel = (np.asarray(x, dtype=float) for x in matrices)
    state = np.array([xs[0], vs[0]], dtype=float)
    for j in range(1, len(u)):
        f = force(state[0], state[1]) if force is not None else 0.0
        state = a @ state + b_force[:, 0] * (u[j - 1] - f)
        if noise is not None:
            state = state + b_accel[:, 0] * noise[j]
        xs[j], vs[j] = state


# --- the algebraic modules (M3, M4) -------------------------------------------------------


def fuse(y_a: np.ndarray, y_b: np.ndarray, alpha: float) -> np.ndarray:
    """Return the M3 fused measurement ``α·y_A + (1−α)·y_B`` (paper §3.1 M3), ``(n_steps,)``."""
    return alpha * np.asarray(y_a, dtype=float) + (1.0 - alpha) * np.asarray(y_b, dtype=float)


def kpi(x: np.ndarray, v: np.ndarray, w1: float, w2: float) -> np.ndarray:
    """Return the M4 KPI ``z = w1·x + w2·v`` (paper §3.1 M4), shape ``(n_steps,)``."""
    return w1 * np.asarray(x, dtype=float) + w2 * np.asarray(v, dtype=float)
