"""Light linear filters: scipy.signal's ``lfilter`` and ``lfiltic`` without importing it.

``import scipy.signal`` costs ~0.7 CPU-s (it loads scipy.stats, scipy.optimize, …), more than
a short job's own work: simulate, fit_surrogates, residuals, targeted_intervention and every
sweep chunk filter ~1,000-sample signals with first- and second-order filters. For such inputs
:func:`lfilter` runs scipy's own direct-form II transposed recursion (``scipy/signal/_lfilter.cc``,
``filt``: the coefficients divided by ``a[0]``, then per sample ``y = z₀ + b₀·x``,
``zᵢ = (zᵢ₊₁ + x·bᵢ₊₁) − y·aᵢ₊₁``, ``z_last = x·b_last − y·a_last``) in Python floats, the same
IEEE operations in the same order, so the result is bit-identical to scipy's (checked in
tests/concepts/test_lfilter.py). Long signals, other dtypes, a one-coefficient denominator
(scipy's convolution path) or a process that has scipy.signal loaded anyway go to scipy itself.
Arrays are time-first where the caller says so (``axis``).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["lfilter", "lfiltic"]

#: Longest signal (samples along the axis, all columns together) filtered in Python: ~0.3 s at
#: second order, still below scipy.signal's import.
MAX_PYTHON_SAMPLES = 200_000


def _scipy_signal() -> Any:
    import scipy.signal  # the heavy path, imported only when taken

    return scipy.signal


def _real_float64(value: Any, exact: bool) -> np.ndarray | None:
    """``value`` as float64 (``exact``: only if it is float64 already), None if not real."""
    array = np.asarray(value)
    if array.dtype == np.float64:
        return array
    if exact or array.dtype.kind not in "biuf" or array.dtype.itemsize > 8:
        return None
    return array.astype(np.float64)


def _use_python(b: Any, a: Any, x: Any, axis: int, zi: Any) -> tuple | None:
    """Float64 ``(b, a, x, zi)`` when the Python recursion applies, else None.

    It applies when scipy would compute in float64 (a float64 signal and delays, real
    coefficients), ``a`` has at least two coefficients and the signal is short.
    """
    if "scipy.signal" in sys.modules:
        return None
    b, a = _real_float64(b, exact=False), _real_float64(a, exact=False)
    x = _real_float64(x, exact=True)
    zi = None if zi is None else _real_float64(zi, exact=True)
    if b is None or a is None or x is None or (zi is not None and zi.ndim != x.ndim):
        return None
    if b.ndim != 1 or a.ndim != 1 or len(a) < 2 or len(b) == 0 or a[0] == 0.0:
        return None
    if x.ndim == 0 or not -x.ndim <= axis < x.ndim or x.size > MAX_PYTHON_SAMPLES:
        return None
    return b, a, x, zi


def _filter_column(b: list, a: list, x: list, z: list) -> list:
    """Return one column filtered as scipy's ``filt`` does; ``z`` (the delays) updated in place."""
    n = len(b)
    out = [0.0] * len(x)
    for k, xk in enumerate(x):
        yk = z[0] + b[0] * xk
        for i in range(n - 2):
            z[i] = z[i + 1] + xk * b[i + 1] - yk * a[i + 1]
        z[n - 2] = xk * b[n - 1] - yk * a[n - 1]
        out[k] = yk
    return out


def _python_lfilter(b, a, x, axis, zi):
    """Return ``(y, zf)`` filtered along ``axis``, or None if ``zi`` does not fit (scipy raises)."""
    n = max(len(a), len(b))
    a0 = float(a[0])
    bz = [float(v) / a0 for v in b] + [0.0] * (n - len(b))
    az = [float(v) / a0 for v in a] + [0.0] * (n - len(a))
    moved = np.moveaxis(x, axis, -1)
    columns = moved.reshape(-1, moved.shape[-1])
    if zi is None:
        states = np.zeros((len(columns), n - 1))
    else:
        zi_moved = np.moveaxis(zi, axis, -1)
        shapes = zip(zi_moved.shape[:-1], moved.shape[:-1], strict=True)
        if zi_moved.shape[-1] != n - 1 or any(z not in (1, m) for z, m in shapes):
            return None  # scipy raises its own error
        states = np.broadcast_to(zi_moved, (*moved.shape[:-1], n - 1)).reshape(-1, n - 1)
    outputs, finals = [], []
    for column, state in zip(columns.tolist(), states.tolist(), strict=True):
        outputs.append(_filter_column(bz, az, column, state))
        finals.append(state)
    y = np.moveaxis(np.array(outputs).reshape(moved.shape), -1, axis)
    zf = np.moveaxis(np.array(finals).reshape((*moved.shape[:-1], n - 1)), -1, axis)
    return y, zf


def lfilter(
    b: Sequence[float] | np.ndarray,
    a: Sequence[float] | np.ndarray,
    x: np.ndarray,
    axis: int = -1,
    zi: np.ndarray | None = None,
) -> Any:
    """Return :func:`scipy.signal.lfilter` ``(b, a, x, axis, zi)``, bit for bit.

    Parameters
    ----------
    b, a : sequence of float
        Numerator and denominator coefficients (``a[0] != 0``).
    x : array, shape (n_steps,) or (n_steps, n_channels) (any axis order)
        Input signal.
    axis : int, default -1
        Axis along which to filter.
    zi : array, optional
        Initial delays, shaped as scipy takes them (``max(len(a), len(b)) − 1`` along ``axis``).

    Returns
    -------
    ndarray, or (ndarray, ndarray) when ``zi`` is given
        The filtered signal (shape of ``x``), and the final delays.

    Examples
    --------
    >>> lfilter([1.0], [1.0, -0.5], np.ones(4)).tolist()
    [1.0, 1.5, 1.75, 1.875]
    """
    prepared = _use_python(b, a, x, axis, zi)
    done = None if prepared is None else _python_lfilter(*prepared[:3], axis, prepared[3])
    if done is None:
        return _scipy_signal().lfilter(b, a, x, axis=axis, zi=zi)
    return done if zi is not None else done[0]


def lfiltic(
    b: Sequence[float] | np.ndarray,
    a: Sequence[float] | np.ndarray,
    y: np.ndarray,
    x: np.ndarray | None = None,
) -> np.ndarray:
    """Return :func:`scipy.signal.lfiltic` ``(b, a, y, x)``: delays that reproduce past samples.

    ``y`` and ``x`` are the past outputs and inputs, newest first (``y[-1]``, ``y[-2]``, …).
    Float64 inputs take scipy's own sums (``zi[m] = Σ b[m+1:]·x[:M−m] − Σ a[m+1:]·y[:N−m]``,
    divided by ``a[0]`` unless it is 1) without importing scipy.signal; others go to scipy.

    Examples
    --------
    >>> lfiltic([0.0, 0.5], [1.0, -0.5], [2.0], [1.0]).tolist()
    [1.5]
    """
    arrays = [_real_float64(v, exact=False) for v in (b, a)]
    arrays += [_real_float64(v, exact=True) for v in (y, np.zeros(0) if x is None else x)]
    if "scipy.signal" in sys.modules or any(v is None or v.ndim != 1 for v in arrays):
        return _scipy_signal().lfiltic(b, a, y, x)
    b, a, y, x = [*arrays[:3], None if x is None else arrays[3]]
    n_a, n_b = len(a) - 1, len(b) - 1
    if n_a < 0 or a[0] == 0.0:
        return _scipy_signal().lfiltic(b, a, y, x)
    x = np.zeros(n_b) if x is None else np.concatenate((x, np.zeros(max(n_b - len(x), 0))))
    y = np.concatenate((y, np.zeros(max(n_a - len(y), 0))))
    zi = np.zeros(max(n_a, n_b))
    for m in range(n_b):
        zi[m] = np.sum(b[m + 1 :] * x[: n_b - m], axis=0)
    for m in range(n_a):
        zi[m] -= np.sum(a[m + 1 :] * y[: n_a - m], axis=0)
    if a[0] != 1.0:
        zi /= a[0]
    return zi
