"""Compiled loops of the twin package: the postfix interpreter and the windowed RK4 integrator.

:func:`run_program` executes a unit's postfix program (:mod:`dtwin.twin.expressions`: opcodes
``OP_CONST`` … ``OP_STORE``) over a matrix of named slots, one column per **lane**;
:func:`simulate_lanes` integrates a unit's states with the classical Runge-Kutta method over windows
(a unit of discrete modules: one :func:`_discrete_step` per sample), every window restarted from
given states, for a batch of param vectors at once, and records the unit's outputs at every sample.
A lane is one (param vector, window) pair: all lanes advance in lockstep, so each opcode is
dispatched once per step for every lane and the loop over lanes is tight (the interpreter's dispatch
is paid once for the whole batch). Each lane's arithmetic is the same, in the same order, as a lane
run alone. Without numba the same functions run in Python (:mod:`dtwin._jit`), with the same
arithmetic.

Slots: one float64 row per named slot (``t``, the unit's inputs, states, params, algebraic
signals and state derivatives; :class:`dtwin.twin.simulate.UnitModel` lays it out), one column
per lane. Arrays are time-first.
"""

from __future__ import annotations

import math

import numpy as np

from dtwin._jit import HAVE_NUMBA, njit

if HAVE_NUMBA:  # njit has imported numba already
    from numba import literally
else:

    def literally(value):
        """Without numba: nothing to compile, the value as it is."""
        return value


__all__ = ["run_program", "simulate_lanes", "chain_windows", "slew_limited", "warm_up"]


@njit(cache=True)
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


@njit(cache=True)
def _divide(left: float, right: float) -> float:  # pragma: no cover - compiled
    if right != 0.0:
        return left / right
    if left == 0.0:
        return math.nan
    return math.copysign(math.inf, left) * math.copysign(1.0, right)


@njit(cache=True, inline="always")
def run_program(code, consts, slots, stack, n_lanes) -> None:  # pragma: no cover - compiled
    """Run the postfix program ``code`` (slot-bound) over the first ``n_lanes`` lanes of ``slots``.

    ``slots`` has shape ``(n_slots, n_lanes)``, ``stack`` ``(depth + 1, n_lanes)``. ``OP_STORE``
    (11) pops the top into ``slots[arg]``: a unit's whole program of assignments runs as one
    pass. Each opcode is dispatched once; the loop over lanes does the arithmetic.
    """
    sp = 0
    for pc in range(code.shape[0] // 2):
        op = code[2 * pc]
        arg = code[2 * pc + 1]
        if op == 1:
            for lane in range(n_lanes):
                stack[sp, lane] = slots[arg, lane]
            sp += 1
        elif op == 0:
            value = consts[arg]
            for lane in range(n_lanes):
                stack[sp, lane] = value
            sp += 1
        elif op == 11:
            sp -= 1
            for lane in range(n_lanes):
                slots[arg, lane] = stack[sp, lane]
        elif op == 7:
            for lane in range(n_lanes):
                stack[sp - 1, lane] = -stack[sp - 1, lane]
        elif op == 8:
            for lane in range(n_lanes):
                stack[sp - 1, lane] = _unary(arg, stack[sp - 1, lane])
        elif op == 10:
            for lane in range(n_lanes):
                base = stack[sp - 1, lane]
                value = base
                for _ in range(arg - 1):
                    value = value * base
                stack[sp - 1, lane] = value
        else:
            sp -= 1
            top = sp - 1
            if op == 2:
                for lane in range(n_lanes):
                    stack[top, lane] = stack[top, lane] + stack[sp, lane]
            elif op == 3:
                for lane in range(n_lanes):
                    stack[top, lane] = stack[top, lane] - stack[sp, lane]
            elif op == 4:
                for lane in range(n_lanes):
                    stack[top, lane] = stack[top, lane] * stack[sp, lane]
            elif op == 5:
                for lane in range(n_lanes):
                    stack[top, lane] = _divide(stack[top, lane], stack[sp, lane])
            elif op == 6:
                for lane in range(n_lanes):
                    stack[top, lane] = _power(stack[top, lane], stack[sp, lane])
            elif arg == 0:
                for lane in range(n_lanes):
                    left, right = stack[top, lane], stack[sp, lane]
                    stack[top, lane] = left if left < right else right
            else:
                for lane in range(n_lanes):
                    left, right = stack[top, lane], stack[sp, lane]
                    stack[top, lane] = left if left > right else right


@njit(cache=True, inline="always")
def _slope(code, consts, slots, stack, times, f, work, src, dst, layout, u, lane_set, k, n_lanes):
    # pragma: no cover - compiled
    """Write the derivatives at ``work[src]`` (each lane at sample ``k + f``) to ``work[dst]``.

    Lane ``l`` reads the input set ``u[lane_set[l]]`` at its own sample ``k[l]``, linear to the
    next sample by ``f`` where ``linear``, and the time ``times = (t0, dt, f_t, extra)`` as
    ``t0 + (k + f_t)·dt + extra`` (a sub-step's start plus a part of the step, rounded as a
    lane run alone). Arrays are indexed, never sliced: a view in the loop costs a reference
    count each time.
    """
    state_slots, deriv_slots, in_slots, linear = layout
    last = u.shape[1] - 1
    t0, dt, f_t, extra = times
    for lane in range(n_lanes):
        slots[0, lane] = t0 + (k[lane] + f_t) * dt + extra
    for i in range(in_slots.shape[0]):
        row = in_slots[i]
        for lane in range(n_lanes):
            s = lane_set[lane]
            kk = k[lane]
            value = u[s, kk, i]
            if linear[i] and f > 0.0 and kk < last:
                value = value + f * (u[s, kk + 1, i] - value)
            slots[row, lane] = value
    for j in range(state_slots.shape[0]):
        row = state_slots[j]
        for lane in range(n_lanes):
            slots[row, lane] = work[src, j, lane]
    run_program(code, consts, slots, stack, n_lanes)
    for j in range(deriv_slots.shape[0]):
        row = deriv_slots[j]
        for lane in range(n_lanes):
            work[dst, j, lane] = slots[row, lane]


@njit(cache=True, inline="always")
def _clamp(work, lo, hi, lane_member, n_lanes):  # pragma: no cover - compiled
    """Clamp each lane's state (``work[0]``) to its batch member's ``[lo, hi]``."""
    for j in range(work.shape[1]):
        for lane in range(n_lanes):
            b = lane_member[lane]
            if work[0, j, lane] < lo[b, j]:
                work[0, j, lane] = lo[b, j]
            elif work[0, j, lane] > hi[b, j]:
                work[0, j, lane] = hi[b, j]


@njit(cache=True)
def _hold_integral(jac, dt, aug, power, term, out):  # pragma: no cover - compiled
    """Write ``Γ = ∫₀^dt exp(J·s) ds`` of ``jac`` ``(n, n)`` to ``out`` ``(n, n)``.

    The upper right block of ``exp([[J, I], [0, 0]]·dt)`` (Van Loan), by scaling the augmented
    matrix to a 1-norm at most 0.5, 18 Taylor terms in Horner form (truncation below 1e-21 of
    the norm) and as many squarings. ``aug``, ``power`` and ``term`` are ``(2n, 2n)`` scratch.
    """
    n = jac.shape[0]
    m = 2 * n
    for i in range(m):
        for j in range(m):
            aug[i, j] = 0.0
    for i in range(n):
        for j in range(n):
            aug[i, j] = jac[i, j] * dt
        aug[i, n + i] = dt
    norm = 0.0
    for j in range(m):
        column = 0.0
        for i in range(m):
            column += abs(aug[i, j])
        norm = max(norm, column)
    squarings = 0
    while norm > 0.5 and squarings < 1000:
        norm *= 0.5
        squarings += 1
    scale = 0.5**squarings
    for i in range(m):
        for j in range(m):
            aug[i, j] *= scale
            power[i, j] = 1.0 if i == j else 0.0
    for order in range(18, 0, -1):  # power = I + aug·power/order
        for i in range(m):
            for j in range(m):
                total = 0.0
                for r in range(m):
                    total += aug[i, r] * power[r, j]
                term[i, j] = total / order
        for i in range(m):
            for j in range(m):
                power[i, j] = term[i, j] + (1.0 if i == j else 0.0)
    for _ in range(squarings):
        for i in range(m):
            for j in range(m):
                total = 0.0
                for r in range(m):
                    total += power[i, r] * power[r, j]
                term[i, j] = total
        for i in range(m):
            for j in range(m):
                power[i, j] = term[i, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = power[i, n + j]


@njit(cache=True, inline="always")
def _discrete_step(code, consts, slots, stack, times, work, layout, u, lane_set, k, n_lanes,
                   stepping, jac, scratch):  # fmt: skip
    # pragma: no cover - compiled
    """Advance every lane's states by one sample of a discrete unit, in place in ``work[0]``.

    ``work[5]`` holds the derivatives ``f(s[k], u[k])`` at the sample (each lane's). A state of
    kind 1 (``euler``) becomes ``s + dt·f``; the states of a kind-2 module (``zoh``, states
    ``first[j] … last[j] − 1``) become ``s + Γ·f`` with ``Γ = ∫₀^dt exp(J·s) ds`` and ``J`` the
    module's Jacobian at the sample (one difference per state, exact for derivatives affine
    in the module's states): the exact step of a linear module with its inputs held.
    ``jac`` ``(n_states, n_states, n_lanes)`` and ``scratch`` are work space.
    """
    kinds, first, last = stepping
    t0, dt = times[0], times[1]
    n_states = work.shape[1]
    for j in range(n_states):  # Jacobian columns of the zoh states
        if kinds[j] != 2:
            continue
        for i in range(n_states):
            for lane in range(n_lanes):
                work[1, i, lane] = work[0, i, lane]
        for lane in range(n_lanes):
            work[1, j, lane] = work[0, j, lane] + (1.0 + abs(work[0, j, lane]))
        _slope(code, consts, slots, stack, (t0, dt, 0.0, 0.0), 0.0, work, 1, 2, layout, u,
               lane_set, k, n_lanes)  # fmt: skip
        for i in range(first[j], last[j]):
            for lane in range(n_lanes):
                step = work[1, j, lane] - work[0, j, lane]
                jac[i, j, lane] = (work[2, i, lane] - work[5, i, lane]) / step
    aug, power, term, block, gamma = scratch
    j = 0
    while j < n_states:
        if kinds[j] == 1:
            for lane in range(n_lanes):
                work[0, j, lane] = work[0, j, lane] + dt * work[5, j, lane]
            j += 1
            continue
        a, b = first[j], last[j]
        n = b - a
        for lane in range(n_lanes):
            if n == 1:
                slope = jac[a, a, lane]
                g = math.expm1(slope * dt) / slope if slope != 0.0 else dt
                work[0, a, lane] = work[0, a, lane] + g * work[5, a, lane]
                continue
            for r in range(n):
                for c in range(n):
                    block[r, c] = jac[a + r, a + c, lane]
            _hold_integral(block[:n, :n], dt, aug[: 2 * n, : 2 * n], power[: 2 * n, : 2 * n],
                           term[: 2 * n, : 2 * n], gamma[:n, :n])  # fmt: skip
            for r in range(n):
                total = 0.0
                for c in range(n):
                    total += gamma[r, c] * work[5, a + c, lane]
                work[2, r, lane] = total
            for r in range(n):
                work[0, a + r, lane] = work[0, a + r, lane] + work[2, r, lane]
        j = b


@njit(cache=True)
def _integrate(code, consts, layout, u, lanes, out_slots, lo, hi, times, depth, slots, work, y,
               states, one, stepping):  # fmt: skip
    # pragma: no cover - compiled
    """Advance every lane over its samples in lockstep, recording outputs and states.

    ``lanes = (member, input_set, start, length, row)`` per lane: its batch member (row of
    ``lo``, ``hi``, ``y``, ``states``), input set, first sample, number of samples and first
    output row. ``slots`` ``(n_slots, n_lanes)`` holds each lane's params, ``work[0]``
    ``(n_states, n_lanes)`` its start state; ``times = (t0, dt, substeps)``; ``depth`` the
    program's deepest stack. Each sample
    advances by ``substeps`` classical Runge-Kutta steps, the state clamped to ``[lo, hi]``
    after each. A lane whose samples have ended repeats its last one (computed, not recorded).

    ``one`` (a compile-time constant: ``True`` or ``False`` written at the call) says there is
    a single lane: its loops over lanes are then compiled away, which halves a lone window's
    time (a live stream's step, a chain of windows); the arithmetic is the same.

    ``stepping = (kinds, first, last)`` per state: kind 0 continuous, 1 ``euler``, 2 ``zoh``
    and the span of the state's module (:func:`_discrete_step`). A unit whose states are all
    of kind 1 or 2 is **discrete**: each sample is one :func:`_discrete_step` from the states
    and inputs of the previous sample instead of the Runge-Kutta steps (``substeps`` unused).
    """
    literally(one)
    member, lane_set, start, length, row = lanes
    t0, dt, substeps = times
    n_lanes = 1 if one else slots.shape[1]
    n_states = work.shape[1]
    stack = np.empty((depth + 1, n_lanes))
    k = np.empty(n_lanes, dtype=np.int64)
    longest = 0
    for lane in range(n_lanes):
        longest = max(longest, length[lane])
    _clamp(work, lo, hi, member, n_lanes)
    h = dt / substeps
    kinds = stepping[0]
    discrete = n_states > 0
    width = 1
    for j in range(n_states):
        if kinds[j] == 0:
            discrete = False
        else:
            width = max(width, stepping[2][j] - stepping[1][j])
    size = n_states if discrete else 0
    jac = np.zeros((size, size, n_lanes))
    scratch = (np.empty((2 * width, 2 * width)), np.empty((2 * width, 2 * width)),
               np.empty((2 * width, 2 * width)), np.empty((width, width)),
               np.empty((width, width)))  # fmt: skip
    for i in range(longest):
        for lane in range(n_lanes):
            k[lane] = start[lane] + min(i, length[lane] - 1)
        _slope(code, consts, slots, stack, (t0, dt, 0.0, 0.0), 0.0, work, 0, 5, layout, u,
               lane_set, k, n_lanes)  # fmt: skip
        for lane in range(n_lanes):
            if i < length[lane]:
                b, r = member[lane], row[lane] + i
                for o in range(out_slots.shape[0]):
                    y[b, r, o] = slots[out_slots[o], lane]
                for j in range(n_states):
                    states[b, r, j] = work[0, j, lane]
        if i == longest - 1:
            break
        if discrete:
            _discrete_step(code, consts, slots, stack, times, work, layout, u, lane_set, k,
                           n_lanes, stepping, jac, scratch)  # fmt: skip
            _clamp(work, lo, hi, member, n_lanes)
            continue
        for step in range(substeps):
            f0 = step / substeps
            fm = (step + 0.5) / substeps
            f1 = (step + 1.0) / substeps
            _slope(code, consts, slots, stack, (t0, dt, f0, 0.0), f0, work, 0, 1, layout, u,
                   lane_set, k, n_lanes)  # fmt: skip
            for j in range(n_states):
                for lane in range(n_lanes):
                    work[5, j, lane] = work[0, j, lane] + 0.5 * h * work[1, j, lane]
            _slope(code, consts, slots, stack, (t0, dt, f0, 0.5 * h), fm, work, 5, 2, layout, u,
                   lane_set, k, n_lanes)  # fmt: skip
            for j in range(n_states):
                for lane in range(n_lanes):
                    work[5, j, lane] = work[0, j, lane] + 0.5 * h * work[2, j, lane]
            _slope(code, consts, slots, stack, (t0, dt, f0, 0.5 * h), fm, work, 5, 3, layout, u,
                   lane_set, k, n_lanes)  # fmt: skip
            for j in range(n_states):
                for lane in range(n_lanes):
                    work[5, j, lane] = work[0, j, lane] + h * work[3, j, lane]
            _slope(code, consts, slots, stack, (t0, dt, f0, h), f1, work, 5, 4, layout, u,
                   lane_set, k, n_lanes)  # fmt: skip
            for j in range(n_states):
                for lane in range(n_lanes):
                    work[0, j, lane] += (
                        h / 6.0
                        * (work[1, j, lane] + 2.0 * work[2, j, lane] + 2.0 * work[3, j, lane]
                           + work[4, j, lane])
                    )  # fmt: skip
            _clamp(work, lo, hi, member, n_lanes)


@njit(cache=True)
def _rows(starts, stops):  # pragma: no cover - compiled
    """First output row of each window, windows one after the other; and the total."""
    offsets = np.zeros(starts.shape[0], dtype=np.int64)
    total = 0
    for w in range(starts.shape[0]):
        offsets[w] = total
        total += stops[w] - starts[w]
    return offsets, total


@njit(cache=True)
def simulate_lanes(
    program, bases, layout, u, u_of, out_slots, lo, hi, starts, stops, x0, dt, t0, substeps, depth,
    stepping,
):  # fmt: skip  # pragma: no cover - compiled
    """Integrate a unit over windows for a batch of param vectors; return outputs and states.

    Returns ``(outputs, states)``, shapes ``(n_batch, n_rows, n_outputs)`` and ``(n_batch,
    n_rows, n_states)``: the windows' samples one after the other (window ``w`` at rows
    ``Σ_{v<w} (stops[v] − starts[v])`` on).

    ``program`` is ``(code, consts, bounds, targets)``; ``layout`` is ``(state_slots,
    deriv_slots, in_slots, linear)``; ``bases`` ``(n_batch, n_slots)`` each member's slot vector
    with its params filled; ``u`` ``(n_sets, n_samples, n_inputs)`` input sets at the samples,
    member ``b`` reading set ``u_of[b]``; ``lo``, ``hi`` ``(n_batch, n_states)`` state bounds;
    window ``w`` runs from sample ``starts[w]`` (state ``x0[b, w]``) to ``stops[w] - 1``. Each
    (member, window) is one lane of :func:`_integrate`; the inputs are held over a sample, or
    linear to the next one where ``linear``; ``stepping = (kinds, first, last)`` says how each
    state advances (:func:`_integrate`).
    """
    n_batch, n_windows, n_states = x0.shape
    n_lanes = n_batch * n_windows
    offsets, n_rows = _rows(starts, stops)
    member = np.empty(n_lanes, dtype=np.int64)
    lane_set, start = np.empty_like(member), np.empty_like(member)
    length, row = np.empty_like(member), np.empty_like(member)
    slots = np.empty((bases.shape[1], n_lanes))
    work = np.empty((6, n_states, n_lanes))
    for b in range(n_batch):
        for w in range(n_windows):
            lane = b * n_windows + w
            member[lane], lane_set[lane] = b, u_of[b]
            start[lane], length[lane], row[lane] = starts[w], stops[w] - starts[w], offsets[w]
            for s in range(bases.shape[1]):
                slots[s, lane] = bases[b, s]
            for j in range(n_states):
                work[0, j, lane] = x0[b, w, j]
    y = np.empty((n_batch, n_rows, out_slots.shape[0]))
    states = np.empty((n_batch, n_rows, n_states))
    lanes = (member, lane_set, start, length, row)
    if n_lanes == 1:
        _integrate(program[0], program[1], layout, u, lanes, out_slots, lo, hi,
                   (t0, dt, substeps), depth, slots, work, y, states, True, stepping)  # fmt: skip
    else:
        _integrate(program[0], program[1], layout, u, lanes, out_slots, lo, hi,
                   (t0, dt, substeps), depth, slots, work, y, states, False, stepping)  # fmt: skip
    return y, states


@njit(cache=True)
def chain_windows(
    program, base, layout, u, out_slots, starts, stops, x0, reset, values, dt, t0, substeps, depth,
    stepping,
):  # fmt: skip  # pragma: no cover - compiled
    """Integrate windows one after the other, each from the end of the previous one.

    Returns ``(outputs, states)`` as :func:`simulate_lanes` for one member (without the batch
    axis). The first window starts from ``x0`` ``(n_states,)``; at each window's start the
    states ``reset`` (indices) are set to ``values[w]``; a window whose end is not finite
    passes on its own start instead (per state). ``u`` ``(n_samples, n_inputs)``; no bounds;
    ``stepping`` as :func:`simulate_lanes`.
    """
    n_windows, n_states = starts.shape[0], x0.shape[0]
    offsets, n_rows = _rows(starts, stops)
    y = np.empty((1, n_rows, out_slots.shape[0]))
    states = np.empty((1, n_rows, n_states))
    zero = np.zeros(1, dtype=np.int64)
    lo, hi = np.full((1, n_states), -np.inf), np.full((1, n_states), np.inf)
    slots = np.empty((base.shape[0], 1))
    work = np.empty((6, n_states, 1))
    state = x0.copy()
    sets = u.reshape((1, u.shape[0], u.shape[1]))
    for w in range(n_windows):
        for i in range(reset.shape[0]):
            state[reset[i]] = values[w, i]
        for s in range(base.shape[0]):
            slots[s, 0] = base[s]
        for j in range(n_states):
            work[0, j, 0] = state[j]
        lanes = (zero, zero, starts[w : w + 1], stops[w : w + 1] - starts[w : w + 1],
                 offsets[w : w + 1])  # fmt: skip
        _integrate(program[0], program[1], layout, sets, lanes, out_slots, lo, hi,
                   (t0, dt, substeps), depth, slots, work, y, states, True, stepping)  # fmt: skip
        end = offsets[w] + stops[w] - starts[w] - 1
        for j in range(n_states):
            if math.isfinite(states[0, end, j]):
                state[j] = states[0, end, j]
    return y[0], states[0]


@njit(cache=True)
def slew_limited(u: np.ndarray, max_step: float) -> np.ndarray:  # pragma: no cover - compiled
    """Return ``u`` (shape ``(n,)``) through a follower that moves at most ``max_step`` a sample.

    ``v_k = v_(k−1) + clip(u_k − v_(k−1), −max_step, max_step)``, ``v`` starting at the first
    value and restarting at the first value after each NaN run (NaN kept).
    """
    out = np.empty_like(u)
    follower = math.nan
    for k in range(u.shape[0]):
        if math.isnan(u[k]):
            out[k] = math.nan
            follower = math.nan
            continue
        if math.isnan(follower):
            follower = u[k]
        else:
            follower += min(max(u[k] - follower, -max_step), max_step)
        out[k] = follower
    return out


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
    u = np.ones((1, 4, 1))
    inf = np.full((1, 1), np.inf)
    starts, stops = np.array([0], dtype=np.int64), np.array([4], dtype=np.int64)
    out = np.array([2], dtype=np.int64)
    slew_limited(np.array([0.0, 1.0, math.nan, 2.0]), 0.5)
    one = np.ones(1, dtype=np.int64)
    for kind in (0, 1, 2):  # continuous, euler, zoh: one compiled loop
        stepping = (kind * one, 0 * one, one)
        for n_batch in (1, 2):  # one lane, and several
            simulate_lanes(
                program, np.zeros((n_batch, 4)), layout, u, np.zeros(n_batch, dtype=np.int64),
                out, np.repeat(-inf, n_batch, axis=0), np.repeat(inf, n_batch, axis=0), starts,
                stops, np.zeros((n_batch, 1, 1)), 0.1, 0.0, 2, 3, stepping,
            )  # fmt: skip
    chain_windows(
        program, np.zeros(4), layout, u[0], out, starts, stops, np.zeros(1),
        np.zeros(1, dtype=np.int64), np.zeros((1, 1)), 0.1, 0.0, 2, 3, stepping,
    )  # fmt: skip
