"""Compiled loops of the twin package: the postfix interpreter and the windowed RK4 integrator.

:func:`run_program` executes one expression's postfix program (:mod:`dtwin.twin.expressions`:
opcodes ``OP_CONST`` … ``OP_IPOW``) over a vector of named slots; :func:`simulate_windows`
integrates a unit's states with the classical Runge-Kutta method over each window, every window
restarted from given states, and records the unit's outputs at every sample. Without numba the
same functions run in Python (:mod:`dtwin._jit`), with the same arithmetic.

Slots: one float64 vector per run holding ``t``, the unit's inputs, states, params, algebraic
signals and state derivatives (:class:`dtwin.twin.simulate.UnitModel` lays it out). Arrays are
time-first.
"""

from __future__ import annotations

import math

import numpy as np

from dtwin._jit import njit

__all__ = ["run_program", "simulate_windows", "warm_up"]


@njit(cache=True, inline="always")
def _unary(code: int, x: float) -> float:  # pragma: no cover - compiled
    if code == 0:
        return math.sqrt(x) if x >= 0.0 else math.nan
    if code == 1:
        return math.exp(x) if x < 709.0 else math.inf
    if code == 2:
        if x > 0.0:
            return math.log(x)
        return -math.inf if x == 0.0 else math.nan
    if code == 3:
        return math.sin(x)
    if code == 4:
        return math.cos(x)
    if code == 5:
        return math.tan(x)
    if code == 6:
        return math.tanh(x)
    if code == 7:
        return abs(x)
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x  # sign(0) = 0, sign(nan) = nan


@njit(cache=True)
def _power(base: float, exponent: float) -> float:  # pragma: no cover - compiled
    if base < 0.0 and exponent != math.floor(exponent):
        return math.nan
    if base == 0.0 and exponent < 0.0:
        return math.inf
    try_value = abs(exponent) * math.log(abs(base)) if base != 0.0 else 0.0
    if try_value > 709.0 and exponent > 0.0:
        return math.inf if base > 0.0 or exponent % 2.0 == 0.0 else -math.inf
    return base**exponent


@njit(cache=True, inline="always")
def run_program(code, consts, start, stop, slots, stack) -> float:  # pragma: no cover - compiled
    """Run ``code[start:stop]`` (postfix, slot-bound) over ``slots``; return the top of stack.

    ``OP_STORE`` (11) pops the top into ``slots[arg]``: a unit's whole program of assignments
    runs as one pass.
    """
    sp = 0
    for pc in range(start, stop):
        op = code[2 * pc]
        arg = code[2 * pc + 1]
        if op == 1:
            stack[sp] = slots[arg]
            sp += 1
        elif op == 0:
            stack[sp] = consts[arg]
            sp += 1
        elif op == 11:
            sp -= 1
            slots[arg] = stack[sp]
        elif op == 7:
            stack[sp - 1] = -stack[sp - 1]
        elif op == 8:
            stack[sp - 1] = _unary(arg, stack[sp - 1])
        elif op == 10:
            base = stack[sp - 1]
            value = base
            for _ in range(arg - 1):
                value = value * base
            stack[sp - 1] = value
        else:
            sp -= 1
            left = stack[sp - 1]
            right = stack[sp]
            if op == 2:
                stack[sp - 1] = left + right
            elif op == 3:
                stack[sp - 1] = left - right
            elif op == 4:
                stack[sp - 1] = left * right
            elif op == 5:
                stack[sp - 1] = (
                    left / right
                    if right != 0.0
                    else (
                        math.nan
                        if left == 0.0
                        else math.copysign(math.inf, left) * math.copysign(1.0, right)
                    )
                )
            elif op == 6:
                stack[sp - 1] = _power(left, right)
            elif arg == 0:
                stack[sp - 1] = left if left < right else right
            else:
                stack[sp - 1] = left if left > right else right
    return stack[0]


@njit(cache=True, inline="always")
def _slope(code, consts, slots, stack, t, work, src, dst, layout, u, k, frac):  # pragma: no cover
    """Write the derivatives at state ``work[src]`` (time ``t``) into ``work[dst]``.

    Arrays are indexed, never sliced: a view in the loop costs a reference count each time.
    """
    state_slots, deriv_slots, in_slots, linear = layout
    slots[0] = t
    last = u.shape[0] - 1
    for i in range(in_slots.shape[0]):
        value = u[k, i]
        if linear[i] and frac > 0.0 and k < last:
            value = value + frac * (u[k + 1, i] - value)
        slots[in_slots[i]] = value
    for j in range(state_slots.shape[0]):
        slots[state_slots[j]] = work[src, j]
    run_program(code, consts, 0, code.shape[0] // 2, slots, stack)
    for j in range(deriv_slots.shape[0]):
        work[dst, j] = slots[deriv_slots[j]]


@njit(cache=True, inline="always")
def _clamp(work, row, lo, hi):  # pragma: no cover - compiled
    for j in range(work.shape[1]):
        if work[row, j] < lo[j]:
            work[row, j] = lo[j]
        elif work[row, j] > hi[j]:
            work[row, j] = hi[j]


@njit(cache=True, inline="always")
def _rk4_sample(code, consts, slots, stack, work, layout, u, k, dt, t0, substeps, lo, hi):
    """Advance the state (``work[0]``) from sample ``k`` to ``k + 1`` in ``substeps`` steps.

    ``work`` rows: 0 the state, 1–4 the four slopes, 5 the trial state. Clamped to
    ``[lo, hi]`` after each step.
    """
    h = dt / substeps
    n = work.shape[1]
    for j in range(substeps):
        f0 = j / substeps
        fm = (j + 0.5) / substeps
        f1 = (j + 1.0) / substeps
        t_start = t0 + (k + f0) * dt
        _slope(code, consts, slots, stack, t_start, work, 0, 1, layout, u, k, f0)
        for i in range(n):
            work[5, i] = work[0, i] + 0.5 * h * work[1, i]
        _slope(code, consts, slots, stack, t_start + 0.5 * h, work, 5, 2, layout, u, k, fm)
        for i in range(n):
            work[5, i] = work[0, i] + 0.5 * h * work[2, i]
        _slope(code, consts, slots, stack, t_start + 0.5 * h, work, 5, 3, layout, u, k, fm)
        for i in range(n):
            work[5, i] = work[0, i] + h * work[3, i]
        _slope(code, consts, slots, stack, t_start + h, work, 5, 4, layout, u, k, f1)
        for i in range(n):
            work[0, i] += h / 6.0 * (work[1, i] + 2.0 * work[2, i] + 2.0 * work[3, i] + work[4, i])
        _clamp(work, 0, lo, hi)


@njit(cache=True, inline="always")
def _record(code, consts, slots, stack, t, work, layout, u, k, out_slots, y, states):
    """Write the outputs and the state at sample ``k`` (time ``t``)."""
    _slope(code, consts, slots, stack, t, work, 0, 5, layout, u, k, 0.0)
    for o in range(out_slots.shape[0]):
        y[k, o] = slots[out_slots[o]]
    for j in range(work.shape[1]):
        states[k, j] = work[0, j]


@njit(cache=True)
def simulate_windows(
    program, base, layout, u, out_slots, lo, hi, starts, stops, x0, dt, t0, substeps, depth
):  # pragma: no cover - compiled
    """Integrate a unit over windows; return its outputs and states at every sample.

    Returns ``(outputs, states)``, shapes ``(n_samples, n_outputs)`` and ``(n_samples,
    n_states)``.

    ``program`` is ``(code, consts, bounds, targets)``; ``layout`` is ``(state_slots,
    deriv_slots, in_slots, linear)``; ``base`` the slot vector with params filled; ``u`` the
    inputs at the samples ``(n_samples, n_inputs)``; window ``w`` runs from sample
    ``starts[w]`` (state ``x0[w]``) to ``stops[w] - 1``; samples outside every window are NaN.
    """
    code, consts = program[0], program[1]
    n_samples = u.shape[0]
    y = np.full((n_samples, out_slots.shape[0]), np.nan)
    states = np.full((n_samples, x0.shape[1]), np.nan)
    slots = base.copy()
    stack = np.empty(depth + 1)
    work = np.empty((6, x0.shape[1]))
    for w in range(starts.shape[0]):
        a = starts[w]
        for j in range(x0.shape[1]):
            work[0, j] = x0[w, j]
        _clamp(work, 0, lo, hi)
        _record(code, consts, slots, stack, t0 + a * dt, work, layout, u, a, out_slots, y, states)
        for k in range(a, stops[w] - 1):
            _rk4_sample(code, consts, slots, stack, work, layout, u, k, dt, t0, substeps, lo, hi)
            t = t0 + (k + 1) * dt
            _record(code, consts, slots, stack, t, work, layout, u, k + 1, out_slots, y, states)
    return y, states


def warm_up() -> None:
    """Compile the loops into numba's on-disk cache (``make venv`` calls this once)."""
    code = np.array([1, 2, 1, 1, 3, 0, 0, 0, 4, 0, 11, 3], dtype=np.int64)
    program = (
        code,
        np.array([0.5]),
        np.array([0, 5], dtype=np.int64),
        np.array([3], dtype=np.int64),
    )
    layout = (
        np.array([2], dtype=np.int64),
        np.array([3], dtype=np.int64),
        np.array([1], dtype=np.int64),
        np.array([True]),
    )
    u = np.ones((4, 1))
    inf = np.full(1, np.inf)
    starts, stops = np.array([0], dtype=np.int64), np.array([4], dtype=np.int64)
    simulate_windows(
        program, np.zeros(4), layout, u, np.array([2], dtype=np.int64), -inf, inf,
        starts, stops, np.zeros((1, 1)), 0.1, 0.0, 2, 3,
    )  # fmt: skip
