"""Compiled step loop of the exact plant with a known force law (numba; docs/gap.md §Speed).

:func:`dtwin.twin.exact.exact_plant_response` steps a plant with a state-dependent force one
sample at a time, the force evaluated twice per step; on Python floats that costs ~1.5 µs per
step and was half of a 130,000-sample rig's diagnosis. A force that names its law
(:class:`ForceLaw`, attached by :func:`dtwin.gap.models` to the candidate's force as its
``law`` attribute) is stepped here instead, compiled by numba (``cache=True``: compiled once
per machine into ``__pycache__``), with the same arithmetic in the same order. Any other force
keeps the Python loop. :mod:`dtwin.twin.exact` imports this module (and numba, ~0.5 s) only
when it first steps such a force. Without numba the same loop runs in Python (:mod:`dtwin._jit`).

The paper's explicit-Euler plant (:func:`dtwin.twin.paper_modules.plant_response`, the loop of
``dtwin.twin.paper_modules._euler_loop``) is stepped here too, by :func:`euler_response`, when the
force is None or a known law: the same arithmetic in the same order on the same doubles, so the same
bits (tests/gap/test_gap_discretisation.py), at ~30 ns instead of ~1 µs per step. The
diagnoser's Euler twin uses it only where numba is installed (:data:`dtwin._jit.HAVE_NUMBA`).
The benchmark's continuous asset is integrated here (:func:`rk4_chain`, its one Runge-Kutta
loop, with or without a force), and its generator's Euler plant evaluates a case's force by
:func:`law_function`, the laws' arithmetic run by the interpreter. The rig families' plants
(:mod:`dtwin.gapbench.rigs`: a drive held or given at every Runge-Kutta instant, or a digital PD
loop) are integrated by :func:`rk4_plant`, with the same step (``_plant_rk4_step``).

The laws (``x`` position, ``v`` velocity, ``p`` the parameters):

- ``tanh_friction``: ``p[0]·tanh(v/p[1])`` (Coulomb friction smoothed over ``p[1]``);
- ``cubic_spring``: ``p[0]·(x − p[1])³``;
- ``quadratic_damping``: ``p[0]·v·|v|``;
- ``stribeck_friction``: ``(p[0] + p[1]·exp(−(v/p[2])²))·tanh(v/p[3])`` (sliding level, the
  breakaway bump above it, Stribeck velocity, smoothing);
- ``generalised_stribeck``: ``(p[0] + p[1]·exp(−|v/p[2]|^p[3]))·tanh(v/p[4]) + p[5]·v``
  (sliding level, bump, Stribeck velocity, exponent, smoothing, viscous coefficient);
- ``power_spring``: ``p[0]·sign(x)·|x/p[1]|^p[2]`` (gain, reference position, exponent);
- ``power_damping``: ``p[0]·sign(v)·|v/p[1]|^p[2]`` (gain, reference velocity, exponent);
- ``sine_in_position``: ``p[0]·sin(p[1]·x + p[2])`` (amplitude, wavenumber, phase; cogging).

The first four are the diagnoser's candidates' (:mod:`dtwin.gap.effects`), the others the
benchmark's real forms (:class:`dtwin.gap.effects.CaseEffect`'s ``force``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from dtwin._jit import HAVE_NUMBA, njit

__all__ = [
    "LAWS",
    "ForceLaw",
    "euler_response",
    "force_windows",
    "law_function",
    "PdLoop",
    "rk4_chain",
    "rk4_plant",
    "substepped_windows",
    "warm_up",
]

#: The laws the compiled loop knows, by name; the index is the law's code in the loop.
LAWS: tuple[str, ...] = (
    "tanh_friction",
    "cubic_spring",
    "quadratic_damping",
    "stribeck_friction",
    "generalised_stribeck",
    "power_spring",
    "power_damping",
    "sine_in_position",
)


class ForceLaw(NamedTuple):
    """A force law of :data:`LAWS` and its parameters (see the module docstring)."""

    name: str
    params: tuple[float, ...]


@njit(cache=True, inline="always")  # inlined in numba IR: its laws do not slow the loops
def _law_value(code, x, v, p):
    if code == 0:
        return p[0] * math.tanh(v / p[1])
    if code == 1:
        offset = x - p[1]
        return p[0] * offset * offset * offset
    if code == 2:
        return p[0] * v * abs(v)
    if code == 3:
        ratio = v / p[2]
        return (p[0] + p[1] * math.exp(-ratio * ratio)) * math.tanh(v / p[3])
    if code == 4:
        level = p[0] + p[1] * math.exp(-(abs(v / p[2]) ** p[3]))
        return level * math.tanh(v / p[4]) + p[5] * v
    if code == 5:
        return p[0] * math.copysign(abs(x / p[1]) ** p[2], x)
    if code == 6:
        return p[0] * math.copysign(abs(v / p[1]) ** p[2], v)
    return p[0] * math.sin(p[1] * x + p[2])


def _law_code(law: ForceLaw) -> int:
    """Return ``law``'s code in the loops, its index in :data:`LAWS` (an unknown law: error)."""
    if law.name not in LAWS:
        raise ValueError(f"force law must be one of {', '.join(LAWS)} (got {law.name!r})")
    return LAWS.index(law.name)


def law_function(law: ForceLaw) -> Callable[[float, float], float]:
    """Return the force ``F(x, v)`` of ``law`` (N) for a loop that stays in Python.

    The arithmetic the compiled loops step (:func:`_law_value`), run by the interpreter on the
    floats it is given: the same bits as the compiled law (tests/gapbench/test_gap_arms.py),
    without a call into compiled code at every step.
    """
    code = _law_code(law)
    params = tuple(float(value) for value in law.params)
    value = getattr(_law_value, "py_func", _law_value)  # the Python function numba compiled
    return lambda x, v: value(code, x, v, params)


@njit(cache=True)
def _force_step(x, v, drive_x, drive_v, steps, code, p, inv_m):
    """Return ``(x, v)`` one sample on under the force of law ``code``.

    The force at the start, the free step, then the force at the predicted end (``steps`` =
    ``a11, a12, a21, a22, q1, q2, r1, r2``); shared by the window loops.
    """
    a11, a12, a21, a22, q1, q2, r1, r2 = steps
    f_prev = _law_value(code, x, v, p) * inv_m
    x_free = a11 * x + a12 * v + drive_x - q1 * f_prev
    v_free = a21 * x + a22 * v + drive_v - q2 * f_prev
    f_next = _law_value(code, x_free - r1 * f_prev, v_free - r2 * f_prev, p) * inv_m
    return x_free - r1 * f_next, v_free - r2 * f_next


@njit(cache=True)
def _windows_loop(drive_x, drive_v, x0, v0, steps, code, p, inv_m, out):
    n_windows, length = drive_x.shape
    for w in range(n_windows):
        x, v = x0[w], v0[w]
        out[w, 0] = x
        broken = False
        for j in range(1, length):
            if broken:
                out[w, j] = np.inf
                continue
            x, v = _force_step(x, v, drive_x[w, j - 1], drive_v[w, j - 1], steps, code, p, inv_m)
            if not -1e300 < x < 1e300:
                broken = True
                out[w, j] = np.inf
            else:
                out[w, j] = x


@njit(cache=True)
def _euler_loop(u, x, v, m, c, k, dt, code, p, limit, xs, vs):
    xs[0], vs[0] = x, v
    n = len(u)
    for j in range(1, n):
        f = _law_value(code, x, v, p) if code >= 0 else 0.0
        a = (u[j - 1] - c * v - k * x - f) / m
        x, v = x + dt * v, v + dt * a
        xs[j], vs[j] = x, v
        if not -limit < x < limit:
            for i in range(j, n):
                xs[i], vs[i] = limit, 0.0
            break


def euler_response(
    u: np.ndarray,
    m: float,
    c: float,
    k: float,
    dt: float,
    x0: float,
    v0: float,
    law: ForceLaw | None,
    limit: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the explicit-Euler plant's position and velocity, each shape ``(n_steps,)``.

    :func:`dtwin.twin.paper_modules.plant_response` with ``force`` None (``law`` None) or the force
    of ``law``, no acceleration noise and the divergence guard ``limit`` (once ``|x|`` reaches it
    or is NaN, the rest of ``x`` is ``limit`` and of ``v`` 0): the same arithmetic, the same
    bits. ``u`` shape ``(n_steps,)``, input units; ``u[k−1]`` drives step ``k``.
    """
    code = -1 if law is None else _law_code(law)
    u = np.ascontiguousarray(u, dtype=float)
    xs, vs = np.zeros(len(u)), np.zeros(len(u))
    if len(u):
        params = np.asarray(law.params if law is not None else (0.0,), dtype=float)
        floats = (float(value) for value in (x0, v0, m, c, k, dt))
        _euler_loop(u, *floats, code, params, float(limit), xs, vs)
    return xs, vs


def force_windows(drive, x0, v0, steps, law: ForceLaw, inv_m: float) -> np.ndarray:
    """Return the positions of windows stepped with a known force law, ``(n_windows, length)``.

    The loop of :func:`dtwin.twin.exact._force_windows` (the same arguments: ``drive`` of
    shape (n_windows, length, 2), ``steps`` the eight step coefficients ``a11 … r2``), ``inf``
    from a window's first sample whose position is not finite or beyond ±1e300.
    """
    code = _law_code(law)
    drive = np.asarray(drive, dtype=float)
    out = np.empty(drive.shape[:2])
    _windows_loop(
        np.ascontiguousarray(drive[..., 0]),
        np.ascontiguousarray(drive[..., 1]),
        np.asarray(x0, dtype=float),
        np.asarray(v0, dtype=float),
        tuple(float(s) for s in steps),
        code,
        np.asarray(law.params, dtype=float),
        float(inv_m),
        out,
    )
    return out


@njit(cache=True)
def _substepped_loop(fine_drive, starts, stops, substeps, x0, v0, steps, code, p, inv_m, out):
    # the windows in lockstep, each with its own arithmetic: their chains overlap in the CPU
    n_windows = len(starts)
    xs, vs = np.empty(n_windows), np.empty(n_windows)
    n_fine, live = np.empty(n_windows, np.int64), np.ones(n_windows, np.bool_)
    longest = 0
    for w in range(n_windows):
        xs[w], vs[w] = x0[w], v0[w]
        out[starts[w]] = xs[w]
        n_fine[w] = (stops[w] - 1 - starts[w]) * substeps + 1
        longest = max(longest, n_fine[w])
    for j in range(1, longest):
        for w in range(n_windows):
            if j >= n_fine[w] or not live[w]:
                continue
            x, v = xs[w], vs[w]
            row = starts[w] * substeps + j - 1  # the fine drive of the window's step j
            x, v = _force_step(x, v, fine_drive[row, 0], fine_drive[row, 1], steps, code, p, inv_m)
            xs[w], vs[w] = x, v
            if not -1e300 < x < 1e300:
                # inf from the window's first sample at or after fine step j
                out[starts[w] + (j + substeps - 1) // substeps : stops[w]] = np.inf
                live[w] = False
            elif j % substeps == 0:
                out[starts[w] + j // substeps] = x


def substepped_windows(
    fine_drive, windows, substeps: int, x_start, v_start, steps, law: ForceLaw, inv_m: float
) -> np.ndarray:
    """Return the positions at the samples of windows stepped ``substeps`` times per sample.

    The loop of :func:`force_windows` over the fine grid of
    :func:`dtwin.twin.exact._substepped_response` (``fine_drive`` of shape
    ``(n_samples·substeps, 2)``; window ``(a, b)`` runs over fine steps ``a·substeps …
    (b−1)·substeps`` from ``(x_start[a], v_start[a])``), reading the fine drive in place and
    keeping every ``substeps``-th position: shape ``(n_samples,)``, 0 outside the windows,
    ``inf`` from a window's first sample at or after a fine step whose position is not finite
    or beyond ±1e300. ``windows`` must not overlap.
    """
    code = _law_code(law)
    out = np.zeros(len(fine_drive) // substeps)
    starts = np.array([a for a, _ in windows], dtype=np.int64)
    _substepped_loop(  # every array C-contiguous: the one specialisation warm_up compiled
        np.ascontiguousarray(fine_drive, dtype=float),
        starts,
        np.array([b for _, b in windows], dtype=np.int64),
        int(substeps),
        np.asarray(x_start, dtype=float)[starts],
        np.asarray(v_start, dtype=float)[starts],
        tuple(float(s) for s in steps),
        code,
        np.asarray(law.params, dtype=float),
        float(inv_m),
        out,
    )
    return out


@njit(cache=True, inline="always")  # inlined: one Runge-Kutta step for both loops below
def _plant_rk4_step(x, v, in1, in2, in3, in4, noise, m, c, k, h, half, sixth, code, p):
    """Return the plant's ``(x, v)`` one classical Runge-Kutta step ``h`` on.

    ``m·v̇ = u − c·v − k·x − F(x, v) + m·noise``, ``ẋ = v``: the input ``u`` is given at the
    four stages (``in1`` at ``t``, ``in2`` and ``in3`` at ``t + h/2``, ``in4`` at ``t + h``),
    ``F`` is the force of law ``code`` (negative: none), ``noise`` (m/s²) is held over the step.
    """
    f1 = _law_value(code, x, v, p) if code >= 0 else 0.0
    k1v = (in1 - c * v - k * x - f1) / m + noise
    x2, v2 = x + half * v, v + half * k1v
    f2 = _law_value(code, x2, v2, p) if code >= 0 else 0.0
    k2v = (in2 - c * v2 - k * x2 - f2) / m + noise
    x3, v3 = x + half * v2, v + half * k2v
    f3 = _law_value(code, x3, v3, p) if code >= 0 else 0.0
    k3v = (in3 - c * v3 - k * x3 - f3) / m + noise
    x4, v4 = x + h * v3, v + h * k3v
    f4 = _law_value(code, x4, v4, p) if code >= 0 else 0.0
    k4v = (in4 - c * v4 - k * x4 - f4) / m + noise
    # (h/6)·(v + 2·v2 + 2·v3 + v4) = h·(v + (h/6)·(k1v + k2v + k3v)): the rig loop's form (the
    # rig cases keep their bits; the continuous asset's moved by < 1e-14 of their spread)
    return x + h * (v + sixth * (k1v + k2v + k3v)), v + sixth * (k1v + 2 * k2v + 2 * k3v + k4v)


@njit(cache=True)
def _rk4_loop(u, eta, xi, tau, m, c, k, h, half, sixth, substeps, code, p, out):
    a, x, v = 0.0, 0.0, 0.0
    row = 1
    for j in range(1, len(u)):
        drive, noise = u[j - 1] + eta[j], xi[j]
        for _ in range(substeps):
            # the lag's stages do not depend on the plant's: the actuator's output at the four
            # stages is the plant's input there
            k1a = (drive - a) / tau
            a2 = a + half * k1a
            k2a = (drive - a2) / tau
            a3 = a + half * k2a
            k3a = (drive - a3) / tau
            a4 = a + h * k3a
            k4a = (drive - a4) / tau
            x, v = _plant_rk4_step(x, v, a, a2, a3, a4, noise, m, c, k, h, half, sixth, code, p)
            a += sixth * (k1a + 2 * k2a + 2 * k3a + k4a)
            out[row, 0], out[row, 1], out[row, 2] = a, x, v
            row += 1


def rk4_chain(
    u_in, tau, m, c, k, dt, eta, xi, substeps: int, law: ForceLaw | None = None
) -> np.ndarray:
    """Return the continuous asset's states ``(u, x, v)`` at every sub-step, ``((n−1)·S + 1, 3)``.

    Classical Runge-Kutta (``S = substeps`` steps of ``h = dt/S`` per sample, from rest) of
    ``τ·u̇ = u_in + η − u``, ``ẋ = v``, ``m·v̇ = u − c·v − k·x − F(x, v) + m·ξ``, ``F`` the force
    of ``law`` (None: no force). The inputs ``u_in[j−1] + η[j]`` and ``ξ[j]`` are held over step
    ``j`` (from sample ``j−1`` to ``j``); ``u_in``, ``eta``, ``xi`` shape ``(n,)``; ``tau`` s,
    ``m, c, k`` the plant's parameters. Compiled where numba is installed; without it the same
    loop runs in Python on Python floats, the same bits (tests/concepts/test_without_numba.py).
    """
    code = -1 if law is None else _law_code(law)
    params = np.asarray(law.params if law is not None else (0.0,), dtype=float)
    u, eta, xi = (np.ascontiguousarray(s, dtype=float) for s in (u_in, eta, xi))
    if not HAVE_NUMBA:  # the interpreter runs the loop faster on floats than on numpy scalars
        u, eta, xi, params = u.tolist(), eta.tolist(), xi.tolist(), params.tolist()
    h = dt / substeps
    out = np.zeros((max(len(u) - 1, 0) * substeps + 1, 3))
    floats = (float(value) for value in (tau, m, c, k, h, h / 2, h / 6))
    _rk4_loop(u, eta, xi, *floats, int(substeps), code, params, out)
    return out


class PdLoop(NamedTuple):
    """A digital PD position loop: the force it holds over sample ``j`` (N).

    ``kp·(r[j] − y[j] + d[j]) − kd·(y[j] − y[j−1])/dt`` (the velocity term 0 at ``j = 0``), ``y``
    the measured position (the plant's plus the measurement noise), ``r`` the ``reference``
    and ``d`` the ``dither``, each shape ``(n,)``.
    """

    kp: float
    kd: float
    reference: np.ndarray
    dither: np.ndarray


@njit(cache=True)
def _plant_loop(
    stages, held, closed, gains, reference, dither, noise, steps, substeps, code, p, out
):
    dt, m, c, k, h, half, sixth = steps
    kp, kd = gains
    x, v, previous = 0.0, 0.0, 0.0
    for j in range(len(held)):
        out[j, 0], out[j, 1] = x, v
        if closed:  # the PD loop on the position measured at the sample
            measured = x + noise[j]
            velocity = (measured - previous) / dt if j else 0.0
            previous = measured
            held[j] = kp * (reference[j] - measured + dither[j]) - kd * velocity
        for s in range(substeps):
            f0 = f_half = f1 = held[j]
            if len(stages):  # the drive at the step's Runge-Kutta instants
                at = (j * substeps + s) * 3
                f0, f_half, f1 = stages[at], stages[at + 1], stages[at + 2]
            x, v = _plant_rk4_step(
                x, v, f0, f_half, f_half, f1, 0.0, m, c, k, h, half, sixth, code, p
            )


def rk4_plant(
    force: np.ndarray,
    m: float,
    c: float,
    k: float,
    dt: float,
    substeps: int,
    law: ForceLaw | None = None,
    loop: PdLoop | None = None,
    noise: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Return a driven plant's states ``(x, v)`` at the samples, ``(n, 2)``, and its held force.

    Classical Runge-Kutta (``substeps`` steps of ``h = dt/substeps`` per sample, from rest) of
    ``ẋ = v``, ``m·v̇ = f(t) − c·v − k·x − F(x, v)``, ``F`` the force of ``law`` (None: none), by
    the step of :func:`rk4_chain`. The drive ``f`` (N) is ``force``: shape ``(n,)``, held over
    each sample (a DAC), or ``(n, substeps, 3)``, its values at each step's instants ``t``,
    ``t + h/2`` and ``t + h``; with ``loop``, the force a digital PD loop holds over each sample,
    computed from the position at the sample plus ``noise`` (shape ``(n,)``, default zeros;
    ``force`` then gives only ``n``). The second array, shape ``(n,)``, is the force held over
    each sample (zeros for a drive of shape ``(n, substeps, 3)``). Compiled where numba is
    installed; without it the same loop runs in Python, the same bits.
    """
    force = np.asarray(force, dtype=float)
    n = len(force)
    held = np.array(force) if force.ndim == 1 and loop is None else np.zeros(n)
    stages = force.ravel() if force.ndim == 3 else np.zeros(0)
    gains, reference, dither = (0.0, 0.0), np.zeros(n), np.zeros(n)
    if loop is not None:
        gains = (float(loop.kp), float(loop.kd))
        reference, dither = loop.reference, loop.dither
    noise = np.zeros(n) if noise is None else noise
    law_params = law.params if law is not None else (0.0,)
    arrays = [
        np.ascontiguousarray(a, dtype=float)
        for a in (stages, held, reference, dither, noise, law_params)
    ]
    if not HAVE_NUMBA:  # the interpreter runs the loop faster on floats than on numpy scalars
        arrays = [a.tolist() for a in arrays]
    stages, held, reference, dither, noise, law_params = arrays
    h = dt / substeps
    steps = tuple(float(value) for value in (dt, m, c, k, h, h / 2, h / 6))
    code = -1 if law is None else _law_code(law)
    out = np.zeros((n, 2))
    closed = loop is not None
    _plant_loop(
        stages,
        held,
        closed,
        gains,
        reference,
        dither,
        noise,
        steps,
        int(substeps),
        code,
        law_params,
        out,
    )
    return out, np.asarray(held, dtype=float)


def warm_up() -> None:
    """Compile the loops for the argument types their callers pass, or load them from the cache.

    ``make venv`` runs this once (~1 s), so no diagnosis pays the compilation; one
    specialisation of each loop serves every law (the law is an integer code).
    """
    steps = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    force_windows(
        np.zeros((1, 3, 2)), np.zeros(1), np.zeros(1), steps, ForceLaw(LAWS[0], (1.0, 1.0)), 1.0
    )
    euler_response(np.zeros(3), 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, ForceLaw(LAWS[0], (1.0, 1.0)), 1.0)
    substepped_windows(
        np.zeros((4, 2)),
        [(0, 2)],
        2,
        np.zeros(2),
        np.zeros(2),
        steps,
        ForceLaw(LAWS[0], (1.0, 1.0)),
        1.0,
    )
    rk4_chain(np.zeros(2), 1.0, 1.0, 0.0, 0.0, 1.0, np.zeros(2), np.zeros(2), 1)
    rk4_plant(np.zeros(2), 1.0, 0.0, 0.0, 1.0, 1, ForceLaw(LAWS[0], (1.0, 1.0)))
