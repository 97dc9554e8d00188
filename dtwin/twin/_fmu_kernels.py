"""Compiled loops that drive an FMU's C functions: Model Exchange RK4 windows, Co-Simulation steps.

The FMI 2.0 functions are called through ctypes function pointers (``fns``, built by
:mod:`dtwin.twin.fmu`), which numba calls as plain C functions: a call costs nanoseconds,
where the same call through fmpy's Python wrappers costs microseconds. Pointer arguments are
passed as addresses (``array.ctypes.data``). Without numba the same loops run in Python.

``fns`` for Model Exchange: ``(setTime, setReal, setContinuousStates, getDerivatives, getReal,
completedIntegratorStep, getEventIndicators, enterEventMode, newDiscreteStates,
enterContinuousTimeMode, getContinuousStates)``; for Co-Simulation: ``(setReal, getReal,
doStep, setRealInputDerivatives)``. A status above ``fmi2Warning`` (1) stops the run; the
samples not reached stay NaN and the worst status is returned. Arrays are time-first.
"""

from __future__ import annotations

import numpy as np

from dtwin._jit import njit

__all__ = ["me_windows", "cs_window", "warm_up"]

#: Most event iterations (``fmi2NewDiscreteStates`` calls) at one event.
MAX_EVENT_ITERATIONS = 100


@njit(cache=True)
def _inputs_at(u, k, frac, linear, values):  # pragma: no cover - compiled
    """Write the inputs at sample ``k`` + ``frac`` (linear or held per input) into ``values``."""
    last = u.shape[0] - 1
    for i in range(u.shape[1]):
        value = u[k, i]
        if linear[i] and frac > 0.0 and k < last:
            value = value + frac * (u[k + 1, i] - value)
        values[i] = value


@njit(cache=True)
def _slope(fns, comp, t, state, u, k, frac, linear, in_vr, values, out):  # pragma: no cover
    """``out`` = the FMU's derivatives at time ``t``, ``state`` and the inputs; the status."""
    _inputs_at(u, k, frac, linear, values)
    status = fns[0](comp, t)
    if u.shape[1]:
        status = max(status, fns[1](comp, in_vr.ctypes.data, u.shape[1], values.ctypes.data))
    status = max(status, fns[2](comp, state.ctypes.data, state.shape[0]))
    return max(status, fns[3](comp, out.ctypes.data, out.shape[0]))


@njit(cache=True)
def _record(fns, comp, t, state, u, k, linear, in_vr, out_vr, values, y):  # pragma: no cover
    """Write the outputs at sample ``k`` into ``y[k]`` (time, inputs, states set); the status."""
    _inputs_at(u, k, 0.0, linear, values)
    status = fns[0](comp, t)
    if u.shape[1]:
        status = max(status, fns[1](comp, in_vr.ctypes.data, u.shape[1], values.ctypes.data))
    status = max(status, fns[2](comp, state.ctypes.data, state.shape[0]))
    row = np.empty(out_vr.shape[0])
    status = max(status, fns[4](comp, out_vr.ctypes.data, out_vr.shape[0], row.ctypes.data))
    y[k] = row
    return status


@njit(cache=True)
def _clamp(state, lo, hi):  # pragma: no cover - compiled
    for j in range(state.shape[0]):
        state[j] = min(max(state[j], lo[j]), hi[j])


@njit(cache=True)
def _rk4(fns, comp, state, u, k, dt, t0, substeps, linear, in_vr, values, work, lo, hi):
    """Advance ``state`` from sample ``k`` to ``k + 1`` in ``substeps`` RK4 steps; the status."""
    k1, k2, k3, k4, trial = work[0], work[1], work[2], work[3], work[4]
    h = dt / substeps
    status = 0
    for j in range(substeps):
        f0, fm, f1 = j / substeps, (j + 0.5) / substeps, (j + 1.0) / substeps
        t = t0 + (k + f0) * dt
        status = max(status, _slope(fns, comp, t, state, u, k, f0, linear, in_vr, values, k1))
        trial[:] = state + 0.5 * h * k1
        status = max(status, _slope(fns, comp, t + 0.5 * h, trial, u, k, fm, linear, in_vr,
                                    values, k2))  # fmt: skip
        trial[:] = state + 0.5 * h * k2
        status = max(status, _slope(fns, comp, t + 0.5 * h, trial, u, k, fm, linear, in_vr,
                                    values, k3))  # fmt: skip
        trial[:] = state + h * k3
        status = max(status, _slope(fns, comp, t + h, trial, u, k, f1, linear, in_vr, values,
                                    k4))  # fmt: skip
        state += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        _clamp(state, lo, hi)
    return status


@njit(cache=True)
def _events(fns, comp, state, indicators, previous, flags, info):  # pragma: no cover
    """After a sample: an event the FMU asks for or an indicator that changed sign is handled.

    Event iteration (``fmi2EnterEventMode``, ``fmi2NewDiscreteStates`` until no new discrete
    states are needed, ``fmi2EnterContinuousTimeMode``); the states are read back when the
    event changed them. Returns the status (4, fatal, when the FMU asks to terminate).
    """
    status = fns[5](comp, 1, flags.ctypes.data, flags[1:].ctypes.data)
    enter = flags[0] != 0
    if indicators.shape[0]:
        status = max(status, fns[6](comp, indicators.ctypes.data, indicators.shape[0]))
        for i in range(indicators.shape[0]):
            if (indicators[i] > 0.0) != (previous[i] > 0.0):
                enter = True
    if enter and status <= 1:
        status = max(status, fns[7](comp))
        info[0] = 1
        count = 0
        while info[0] != 0 and count < MAX_EVENT_ITERATIONS and status <= 1:
            status = max(status, fns[8](comp, info.ctypes.data))
            count += 1
        if info[1] != 0:
            return 4
        status = max(status, fns[9](comp))
        if info[3] != 0:
            status = max(status, fns[10](comp, state.ctypes.data, state.shape[0]))
        if indicators.shape[0]:
            status = max(status, fns[6](comp, indicators.ctypes.data, indicators.shape[0]))
    previous[:] = indicators
    return status


@njit(cache=True)
def me_windows(fns, comp, u, linear, in_vr, out_vr, lo, hi, starts, stops, x0, dt, t0,
               substeps, events, n_indicators):  # fmt: skip  # pragma: no cover - compiled
    """Integrate a Model Exchange FMU over windows; return ``(outputs, states, status)``.

    Window ``w`` starts at sample ``starts[w]`` from the continuous states ``x0[w]``
    (``fmi2SetContinuousStates``) and runs to ``stops[w] - 1``; samples outside every window
    are NaN. ``events``: call ``fmi2CompletedIntegratorStep`` and watch the ``n_indicators``
    event indicators after every sample.
    """
    n = u.shape[0]
    n_states = x0.shape[1]
    y = np.full((n, out_vr.shape[0]), np.nan)
    states = np.full((n, n_states), np.nan)
    state = np.empty(n_states)
    work = np.empty((5, n_states))
    values = np.empty(max(u.shape[1], 1))
    indicators, previous = np.zeros(n_indicators), np.zeros(n_indicators)
    flags = np.zeros(2, dtype=np.int32)
    info = np.zeros(8, dtype=np.int32)  # fmi2EventInfo: five fmi2Boolean, padding, a double
    worst = 0
    for w in range(starts.shape[0]):
        a = starts[w]
        state[:] = x0[w]
        _clamp(state, lo, hi)
        status = _record(fns, comp, t0 + a * dt, state, u, a, linear, in_vr, out_vr, values, y)
        if events and n_indicators:
            status = max(status, fns[6](comp, previous.ctypes.data, n_indicators))
        states[a] = state
        for k in range(a, stops[w] - 1):
            if status > 1:
                break
            status = _rk4(fns, comp, state, u, k, dt, t0, substeps, linear, in_vr, values, work,
                          lo, hi)  # fmt: skip
            if events and status <= 1:
                status = max(status, _events(fns, comp, state, indicators, previous, flags, info))
            status = max(status, _record(fns, comp, t0 + (k + 1) * dt, state, u, k + 1, linear,
                                         in_vr, out_vr, values, y))  # fmt: skip
            states[k + 1] = state
        if status > 1:
            y[a : stops[w]] = np.nan
            states[a : stops[w]] = np.nan
        worst = max(worst, status)
    return y, states, worst


@njit(cache=True)
def cs_window(fns, comp, u, linear, interpolate, in_vr, out_vr, state_vr, first, a, b, dt, t0,
              y, states):  # fmt: skip  # pragma: no cover - compiled
    """Step a Co-Simulation FMU from sample ``first`` to ``b - 1``, recording from ``a``.

    The FMU is initialised at sample ``first``. At each sample the inputs are set
    (``fmi2SetReal``; with ``interpolate``, a linear input's slope to the next sample by
    ``fmi2SetRealInputDerivatives``), the outputs and ``state_vr`` read into ``y`` and
    ``states`` (from sample ``a`` on), then ``fmi2DoStep`` over ``dt``. Returns the status.
    """
    n_in = u.shape[1]
    values = np.empty(max(n_in, 1))
    slopes = np.zeros(max(n_in, 1))
    orders = np.ones(max(n_in, 1), dtype=np.int32)
    row = np.empty(max(out_vr.shape[0], 1))
    state_row = np.empty(max(state_vr.shape[0], 1))
    last = u.shape[0] - 1
    status = 0
    for k in range(first, b):
        for i in range(n_in):
            values[i] = u[k, i]
            slopes[i] = (u[k + 1, i] - u[k, i]) / dt if linear[i] and k < last else 0.0
        if n_in:
            status = max(status, fns[0](comp, in_vr.ctypes.data, n_in, values.ctypes.data))
            if interpolate:
                status = max(status, fns[3](comp, in_vr.ctypes.data, n_in, orders.ctypes.data,
                                            slopes.ctypes.data))  # fmt: skip
        if k >= a:
            status = max(status, fns[1](comp, out_vr.ctypes.data, out_vr.shape[0],
                                        row.ctypes.data))  # fmt: skip
            y[k] = row[: out_vr.shape[0]]
            if state_vr.shape[0]:
                status = max(status, fns[1](comp, state_vr.ctypes.data, state_vr.shape[0],
                                            state_row.ctypes.data))  # fmt: skip
                states[k] = state_row[: state_vr.shape[0]]
        if status > 1:
            y[a:b] = np.nan
            return status
        if k < b - 1:
            status = max(status, fns[2](comp, t0 + k * dt, dt, 1))
    return status


def _stand_ins() -> tuple[tuple, tuple]:
    """Model Exchange and Co-Simulation function tuples of Python stand-ins returning fmi2OK.

    They have the C signatures of :mod:`dtwin.twin.fmu`'s pointers, hence numba's types: what
    is compiled for them serves every FMU.
    """
    import ctypes

    p, d, n, i = ctypes.c_void_p, ctypes.c_double, ctypes.c_size_t, ctypes.c_int

    def ok(*_args) -> int:
        return 0

    def function(*argtypes):
        return ctypes.CFUNCTYPE(ctypes.c_int, *argtypes)(ok)

    me = (function(p, d), function(p, p, n, p), function(p, p, n), function(p, p, n),
          function(p, p, n, p), function(p, i, p, p), function(p, p, n), function(p),
          function(p, p), function(p), function(p, p, n))  # fmt: skip
    cs = (function(p, p, n, p), function(p, p, n, p), function(p, d, d, i),
          function(p, p, n, p, p))  # fmt: skip
    return me, cs


def warm_up() -> None:
    """Compile the loops into numba's on-disk cache (``make venv`` calls this once)."""
    me, cs = _stand_ins()
    u, linear, refs = np.zeros((3, 1)), np.ones(1, dtype=np.bool_), np.zeros(1, dtype=np.uint32)
    bounds = (np.full(2, -np.inf), np.full(2, np.inf))
    first, last = np.zeros(1, dtype=np.int64), np.full(1, 3, dtype=np.int64)
    me_windows(me, 0, u, linear, refs, refs, *bounds, first, last, np.zeros((1, 2)), 0.1, 0.0,
               1, True, 1)  # fmt: skip
    cs_window(cs, 0, u, linear, True, refs, refs, refs, 0, 0, 3, 0.1, 0.0, np.zeros((3, 1)),
              np.zeros((3, 1)))  # fmt: skip
