"""The plant (module M1) discretised exactly, for any sample rate: the gap diagnoser's plant.

Specification: docs/gap.md §Modules (the plant's discretisation).

The paper's simulator steps the plant ``m·ẍ = u − c·ẋ − k·x − F(x, ẋ)`` by explicit Euler
(:func:`dtwin.twin.paper_modules.plant_response`), right at its ~150 samples per period and wrong at
10. Here the linear part is discretised exactly, through matrix exponentials, for what the input
does between samples (the **hold**):

- :data:`~dtwin.twin.paper_modules.ZOH`: held (a digital controller's output);
- :data:`~dtwin.twin.paper_modules.FOH`: linear between samples (it lets ``u[k]`` act on ``x[k]``);
- :data:`~dtwin.twin.paper_modules.BANDLIMITED`: the band-limited interpolation of the samples (a
  windowed sinc, :data:`SINC_TAPS` samples each side), what a multisine through a DAC and an
  anti-aliasing filter is; exact for any input below the Nyquist frequency up to the window.

One step is ``s[k] = a·s[k−1] + d[k−1]`` with ``s = (x, v)`` and the drive
``d[k−1] = Σ_j taps[j]·w[k−1+first+j]`` (:class:`HoldMatrices`, :func:`hold_matrices`), ``w``
the input per unit mass. A state-dependent force ``F`` (a candidate effect) always enters with
the first-order hold, by one predictor-corrector pass per step (:func:`exact_plant_response`),
over sub-steps of the sample when the force is stiff on its scale (:func:`force_substeps`).
Arrays are time-first, shape ``(n_samples,)``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from scipy.linalg import expm
from scipy.signal import lfilter

from dtwin.twin.paper_modules import BANDLIMITED, FOH, ZOH, Force, require_discretisation

__all__ = [
    "EXACT_HOLDS",
    "SINC_TAPS",
    "HoldMatrices",
    "hold_matrices",
    "exact_plant_response",
    "free_response_basis",
    "MAX_FORCE_SUBSTEPS",
    "force_substeps",
]

#: The exact discretisations of :func:`exact_plant_response`.
EXACT_HOLDS: tuple[str, ...] = (ZOH, FOH, BANDLIMITED)
#: Samples on each side of an interval the band-limited hold interpolates from (Lanczos window).
SINC_TAPS = 8
_QUADRATURE_NODES = 24


class HoldMatrices(NamedTuple):
    """One exact step ``s[k] = a·s[k−1] + Σ_j taps[j]·w[k−1+first+j]``, ``s = (x, v)``.

    ``w`` is the acceleration input (force per unit mass, ``(u − F)/m``); ``a`` has shape
    (2, 2), ``taps`` shape (n_taps, 2). The zero-order hold has one tap (``first = 0``), the
    first-order hold two (``w[k−1]``, ``w[k]``), the band-limited hold ``2·SINC_TAPS``.
    """

    a: np.ndarray
    taps: np.ndarray
    first: int

    def drive(self, w: np.ndarray, rows: Sequence[tuple[int, int]] | None = None) -> np.ndarray:
        """Return ``d`` of shape ``(n, 2)``: ``d[k−1]`` drives step ``k`` (ends repeat ``w``).

        ``rows``: ``(start, stop)`` ranges; when they cover under half of ``w`` in at most
        :data:`_DRIVE_RANGES` ranges, only their rows are computed (the others are 0), each
        value as the whole computation gives it (a simulation over a few windows of a long
        recording reads nothing else).
        """
        w = np.asarray(w, dtype=float)
        before, after = max(-self.first, 0), max(self.first + len(self.taps) - 1, 0)
        padded = np.concatenate([np.full(before, w[0]), w, np.full(after, w[-1])])
        start = before + self.first  # d[i] = Σ_j taps[j]·padded[start + i + j]
        n = len(w)
        if rows is None or len(rows) > _DRIVE_RANGES or 2 * sum(b - a for a, b in rows) >= n:
            drive = np.empty((n, 2))
            self._fill(padded, start, 0, n, drive)
            return drive
        drive = np.zeros((n, 2))
        for a, b in rows:
            self._fill(padded, start, a, b, drive)
        return drive

    def _fill(self, padded, start: int, a: int, b: int, drive: np.ndarray) -> None:
        """Write rows ``a … b−1`` of the drive into ``drive`` from the padded input."""
        taps = self.taps
        if len(taps) <= 2:  # the hold's one or two products per sample, by slices
            # (np.correlate's per-sample dot costs 5x more; these sums are its own roundings)
            for i in (0, 1):
                np.multiply(padded[start + a : start + b], taps[0, i], out=drive[a:b, i])
                if len(taps) == 2:
                    drive[a:b, i] += padded[start + a + 1 : start + b + 1] * taps[1, i]
            return
        for i in (0, 1):
            drive[a:b, i] = np.correlate(padded[start + a : start + b + len(taps) - 1], taps[:, i])


#: Most ``(start, stop)`` ranges :meth:`HoldMatrices.drive` computes one by one.
_DRIVE_RANGES = 64


@lru_cache(maxsize=512)
def hold_matrices(c_per_m: float, k_per_m: float, dt: float, hold: str) -> HoldMatrices:
    """Return the exact discretisation of ``ẍ = w − (c/m)·ẋ − (k/m)·x`` over one sample.

    Parameters
    ----------
    c_per_m, k_per_m : float
        Damping and stiffness per unit mass, 1/s and 1/s² (``k = 0``: an integrating plant).
    dt : float
        Sample period, s.
    hold : {"zoh", "foh", "bandlimited"}
        The input between samples (see the module docstring).

    Returns
    -------
    HoldMatrices
        Cached per argument tuple (a fit asks for the same step several times per simulation):
        treat its arrays as read-only.

    Notes
    -----
    With ``F = [[0, 1], [−k/m, −c/m]]``, ``g = (0, 1)ᵀ`` and the augmented state
    ``(s, w, Δ)``, ``ṡ = F·s + g·w``, ``ẇ = Δ/dt``: one matrix exponential of the
    augmented matrix gives ``s[k] = e₁₁·s[k−1] + e₁₂·w[k−1] + e₁₃·(w[k] − w[k−1])``, exact for
    a piecewise-linear input (``Δ = 0``: the zero-order hold). The band-limited hold's taps are
    ``dt·∫₀¹ exp(F·dt·(1−τ))·g·h(τ − j) dτ`` for the normalised Lanczos kernel ``h``, by
    Gauss–Legendre quadrature (:data:`_QUADRATURE_NODES` nodes).

    Examples
    --------
    >>> step = hold_matrices(0.0, 0.0, 0.1, "foh")  # a free mass: x gains w·dt²/2 per step
    >>> [round(float(b), 6) for b in step.taps.ravel()]
    [0.003333, 0.05, 0.001667, 0.05]
    >>> bool(np.allclose(hold_matrices(0.3, 40.0, 0.05, "bandlimited").taps.sum(axis=0),
    ...                  hold_matrices(0.3, 40.0, 0.05, "zoh").taps[0]))
    True
    """
    require_discretisation(hold, EXACT_HOLDS)
    augmented = np.zeros((4, 4))
    augmented[:2, :2] = [[0.0, 1.0], [-k_per_m, -c_per_m]]
    augmented[1, 2] = 1.0
    augmented[2, 3] = 1.0 / dt
    exact = expm(augmented * dt)
    a = exact[:2, :2]
    if hold == ZOH:
        return HoldMatrices(a, exact[None, :2, 2], 0)
    if hold == FOH:
        slope = exact[:2, 3]
        return HoldMatrices(a, np.stack([exact[:2, 2] - slope, slope]), 0)
    return HoldMatrices(a, _bandlimited_taps(augmented[:2, :2], dt), 1 - SINC_TAPS)


def _lanczos(x: np.ndarray) -> np.ndarray:
    inside = np.abs(x) < SINC_TAPS
    return np.where(inside, np.sinc(x) * np.sinc(x / SINC_TAPS), 0.0)


@lru_cache(maxsize=1)
def _quadrature() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return Gauss–Legendre nodes on [0, 1], their weights and the kernel (nodes, taps)."""
    nodes, weights = np.polynomial.legendre.leggauss(_QUADRATURE_NODES)
    tau = 0.5 * (nodes + 1.0)
    offsets = np.arange(1 - SINC_TAPS, SINC_TAPS + 1)
    kernel = _lanczos(tau[:, None] - offsets[None, :])
    kernel /= kernel.sum(axis=1, keepdims=True)  # a constant input is reproduced exactly
    return tau, weights, kernel


def _bandlimited_taps(system: np.ndarray, dt: float) -> np.ndarray:
    """Return the taps ``(2·SINC_TAPS, 2)`` of ``w[k−1+j]``, ``j = 1−SINC_TAPS … SINC_TAPS``."""
    tau, weights, kernel = _quadrature()
    transitions = expm(system[None] * (dt * (1.0 - tau))[:, None, None])  # (nodes, 2, 2)
    columns = transitions[:, :, 1]  # exp(F·dt·(1−τ))·g
    return 0.5 * dt * np.einsum("n,ni,nj->ji", weights, columns, kernel)


def _linear_windows(drive: np.ndarray, x0: np.ndarray, v0: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Positions of windows of the linear plant, each row from its own initial state.

    ``drive`` has shape (n_windows, length, 2): ``d[k−1]`` of each window (:class:`HoldMatrices`);
    ``x0``, ``v0`` shape (n_windows,). The response is one linear filter per row: the position's
    transfer from ``d`` is ``C·adj(zI − A)/det(zI − A)``, ``C·adj·e₁ = z − a₂₂``,
    ``C·adj·e₂ = a₁₂`` (:func:`scipy.signal.lfilter` along axis 1).
    """
    den = np.array([1.0, -(a[0, 0] + a[1, 1]), a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]])
    d_x, d_v = drive[..., 0], drive[..., 1]
    forcing = np.zeros(d_x.shape)  # the FIR part, by slices (lfilter loops over rows for FIR)
    forcing[:, 1:] += d_x[:, :-1]
    forcing[:, 2:] += a[0, 1] * d_v[:, :-2] - a[1, 1] * d_x[:, :-2]
    x1_free = a[0, 0] * x0 + a[0, 1] * v0
    forcing[:, 0] += x0
    if forcing.shape[1] > 1:
        forcing[:, 1] += x1_free - (a[0, 0] + a[1, 1]) * x0
    return lfilter([1.0], den, forcing, axis=1)


#: Up to this many windows of one length are stepped one after another on Python floats
#: (~1.5 µs per step and window with a cubic force); more go in lockstep as numpy arrays
#: (~20 µs per step whatever their number, the cost of a dozen ufunc calls on tiny arrays).
SCALAR_WINDOWS = 8


def _force_windows(drive, x0, v0, a, force_step: HoldMatrices, force: Force, inv_m):
    """Exact steps with a state-dependent force, all windows of one length in lockstep.

    ``drive`` has shape (n_windows, length, 2), ``x0``, ``v0`` shape (n_windows,); returns the
    positions, shape (n_windows, length), ``inf`` from a window's first non-finite sample. The
    input enters through ``drive`` (its own hold); the force, a continuous function of the
    state whatever holds the input, always enters with the first-order hold (trapezoidal), by
    one predictor-corrector pass: a force held over the sample (explicit) feeds energy into a
    lightly damped plant and can diverge. A force with a ``scalar`` attribute (the same law
    on Python floats) uses it when the windows are stepped one by one (:data:`SCALAR_WINDOWS`);
    one with a ``law`` attribute (:class:`dtwin.twin._force_kernels.ForceLaw`) is stepped by the
    compiled loop of :mod:`dtwin.twin._force_kernels`, the same arithmetic ~50× faster.
    """
    (a11, a12), (a21, a22) = a.tolist()
    (q1, q2), (r1, r2) = force_step.taps.tolist()
    law = getattr(force, "law", None)
    if law is not None:  # a known law: the compiled loop (dtwin.twin._force_kernels)
        from dtwin.twin._force_kernels import force_windows

        steps = (a11, a12, a21, a22, q1, q2, r1, r2)
        return force_windows(drive, x0, v0, steps, law, inv_m)
    if drive.shape[0] <= SCALAR_WINDOWS:  # few windows: one after another on plain floats
        steps = (a11, a12, a21, a22, q1, q2, r1, r2)
        scalar = getattr(force, "scalar", force)
        return np.stack(
            [
                _force_single(window, float(x), float(v), steps, scalar, inv_m)
                for window, x, v in zip(drive, x0, v0, strict=True)
            ]
        )
    drive_x = np.ascontiguousarray(drive[..., 0].T)  # time-major: row j is step j of every
    drive_v = np.ascontiguousarray(drive[..., 1].T)  # window, contiguous (not a strided column)
    x, v = np.asarray(x0, dtype=float).copy(), np.asarray(v0, dtype=float).copy()
    out = np.empty(drive_x.shape)
    out[0] = x
    with np.errstate(all="ignore"):
        for j in range(1, out.shape[0]):
            f_prev = force(x, v) * inv_m
            x_free = a11 * x + a12 * v + drive_x[j - 1] - q1 * f_prev
            v_free = a21 * x + a22 * v + drive_v[j - 1] - q2 * f_prev
            f_next = force(x_free - r1 * f_prev, v_free - r2 * f_prev) * inv_m
            x, v = x_free - r1 * f_next, v_free - r2 * f_next
            out[j] = x
    out = out.T
    broken = ~(np.abs(out) < 1e300)
    out[np.cumsum(broken, axis=1) > 0] = np.inf
    return out


def _force_single(drive, x, v, steps, force: Force, inv_m) -> np.ndarray:
    """Run the step loop of :func:`_force_windows` for one window, on Python floats.

    The same arithmetic in the same order, with the drive iterated as Python floats and the
    positions collected in a list (no per-step indexing or numpy item assignment).
    """
    a11, a12, a21, a22, q1, q2, r1, r2 = steps
    positions = [x]
    append = positions.append
    with np.errstate(all="ignore"):
        for dx, dv in zip(drive[:-1, 0].tolist(), drive[:-1, 1].tolist(), strict=True):
            f_prev = float(force(x, v)) * inv_m
            x_free = a11 * x + a12 * v + dx - q1 * f_prev
            v_free = a21 * x + a22 * v + dv - q2 * f_prev
            f_next = float(force(x_free - r1 * f_prev, v_free - r2 * f_prev)) * inv_m
            x, v = x_free - r1 * f_next, v_free - r2 * f_next
            if not -1e300 < x < 1e300:
                break
            append(x)
    out = np.full(len(drive), np.inf)
    out[: len(positions)] = positions
    return out


def free_response_basis(step: HoldMatrices, length: int) -> np.ndarray:
    """Return the position's free response to unit initial states, shape ``(length, 2)``.

    Column 0 starts from ``(x, v) = (1, 0)``, column 1 from ``(0, 1)``: row ``j`` is the first
    row of ``A^j`` (:class:`HoldMatrices`).
    """
    a = step.a
    den = [1.0, -(a[0, 0] + a[1, 1]), a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]]
    seeds = np.zeros((2, max(length, 2)))
    seeds[0, 0], seeds[0, 1] = 1.0, a[0, 0] - (a[0, 0] + a[1, 1])  # x₀ = 1, x₁ = a₁₁
    seeds[1, 1] = a[0, 1]  # x₀ = 0, x₁ = a₁₂
    return lfilter([1.0], den, seeds, axis=1)[:, :length].T


def exact_plant_response(
    u: np.ndarray,
    m: float,
    c: float,
    k: float,
    dt: float,
    *,
    windows: Sequence[tuple[int, int]],
    x_start: np.ndarray,
    v_start: np.ndarray,
    hold: str = FOH,
    force: Force | None = None,
    drive: np.ndarray | None = None,
    substeps: int = 1,
) -> np.ndarray:
    """Return the plant's position, exactly discretised, over windows restarted from states.

    Parameters
    ----------
    u : array, shape (n_samples,)
        Force input (input units), already corrected for offset and delay.
    m, c, k : float
        Mass, viscous damping, stiffness (input units per position unit and its derivatives);
        ``k = 0`` is an integrating plant.
    dt : float
        Sample period, s.
    windows : sequence of (start, stop)
        Each window ``[start, stop)`` is simulated from the state ``(x_start[start],
        v_start[start])`` (free run: one window over everything). Samples outside every window
        are 0.
    x_start, v_start : array, shape (n_samples,)
        The states windows may start from (the recorded position, the velocity estimated from
        it), position units and position units/s.
    hold : {"zoh", "foh", "bandlimited"}, default "foh"
        The input between samples (:func:`hold_matrices`). The band-limited hold reads the
        input on both sides of a window's samples (the whole ``u``, not the window only).
    force : callable, optional
        The ``force`` hook ``F(x, v)``, input units, opposing the motion; called with arrays of
        shape (n_windows,).
    drive : array, shape (n_samples, 2), optional
        ``hold_matrices(c/m, k/m, dt, hold).drive(u/m, windows)`` (its rows inside the windows)
        when the caller has it already (a simulation that runs the same input twice);
        computed here when None.
    substeps : int, default 1
        Steps per sample of the force (:func:`force_substeps`); with more than one (and a
        force) see :func:`_substepped_response`.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)
        Position; ``inf`` from the sample where a window diverges.

    Notes
    -----
    Paper §3.1 M1, ``m·ẍ = u − c·ẋ − k·x − F(x, ẋ)``, discretised exactly for the linear part
    (:func:`hold_matrices`); the force, a continuous function of the state, always enters with
    the first-order hold, evaluated at the previous state and at a predicted next state (one
    predictor-corrector pass, second order in ``dt``), windows of one length in lockstep; the
    force must accept arrays. Without a force the whole response is a linear filter, windows
    side by side.
    """
    step = hold_matrices(c / m, k / m, dt, hold)
    if drive is None:
        drive = step.drive(np.asarray(u, dtype=float) / m, windows)
    if force is not None and substeps > 1:
        return _substepped_response(
            u, m, c, k, dt, windows, x_start, v_start, hold, force, drive, substeps
        )
    out = np.zeros(len(drive))
    force_step = step if hold == FOH else hold_matrices(c / m, k / m, dt, FOH)
    by_length: dict[int, list[int]] = {}
    for start, stop in windows:
        by_length.setdefault(stop - start, []).append(start)
    for length, starts in by_length.items():
        first = np.asarray(starts)
        x0, v0 = x_start[first], v_start[first]
        tiled = _tiling(first, length)
        rows = tiled or first[:, None] + np.arange(length)
        windows_drive = drive[rows].reshape(len(first), length, 2)
        if force is None:
            positions = _linear_windows(windows_drive, x0, v0, step.a)
        else:
            positions = _force_windows(windows_drive, x0, v0, step.a, force_step, force, 1 / m)
        out[rows] = positions.reshape(-1) if tiled else positions
    return out


#: Most sub-steps per sample :func:`force_substeps` asks for (the cost of a simulation with a
#: force grows with them; beyond 16 the friction rigs' simulation error no longer fell).
MAX_FORCE_SUBSTEPS = 16


def force_substeps(slope: float, m: float, dt: float) -> int:
    """Return the force's steps per sample: a power of 2 with ``h·slope/|m| ≤ 1``, at most 16.

    ``slope`` is the force's largest ``|∂F/∂v|`` (input units per velocity unit): over a
    step ``h`` the force acts like a damper of that size, and the predictor-corrector pass is
    accurate only while ``h·slope/m`` stays well inside its stability bound of 2. A friction's
    sign, smoothed over a velocity far below the velocity change of one sample, is such a
    damper near rest: per sample the velocity reversal falls inside a step and the force
    changes sign there (on rigs at 3–100 samples per period with friction, the true friction's
    simulation error was 1–6 times the noise floor with one step per sample, below a third of
    it with 16). Powers of 2 keep the count constant while a fit moves the parameters a little.

    Examples
    --------
    >>> [force_substeps(slope, 1.0, 0.01) for slope in (0.0, 150.0, 1e9)]
    [1, 2, 16]
    """
    ratio = dt * float(slope) / abs(float(m)) if m else math.inf
    if not ratio > 1.0:
        return 1
    if not math.isfinite(ratio):
        return MAX_FORCE_SUBSTEPS
    return int(min(MAX_FORCE_SUBSTEPS, 2 ** math.ceil(math.log2(ratio))))


def _substepped_response(u, m, c, k, dt, windows, x_start, v_start, hold, force, drive, substeps):
    """Return :func:`exact_plant_response` with the force stepped ``substeps`` times per sample.

    The input between samples is the hold's (zero-order: held; otherwise linear between the
    samples) on the fine grid, stepped exactly there; so that the linear part at the samples
    stays the sample-level hold's exactly (a band-limited input is not linear between
    samples), each sample's last sub-step also carries the difference between the sample's
    drive ``drive[k]`` and the fine steps' drive propagated over the sample (zero for the
    zero-order hold up to rounding). Only the force's path within the sample is then
    approximated, and it is fed back at every sub-step. Positions at the samples, shape
    ``(n_samples,)``.
    """
    n = len(drive)
    fine_dt = dt / substeps
    fine_hold = ZOH if hold == ZOH else FOH
    u = np.asarray(u, dtype=float)
    if fine_hold == ZOH:
        fine_u = np.repeat(u, substeps)
    else:
        fine_u = np.interp(np.arange(n * substeps) / substeps, np.arange(n), u)
    fine = hold_matrices(c / m, k / m, fine_dt, fine_hold)
    fine_drive = fine.drive(fine_u / m)
    # the fine drive of each sample propagated to its end: Σ_i a_h^(S−1−i)·fine_drive[k·S + i],
    # one matrix product (rows (i, component) of a sample against the stacked powers)
    powers = [np.eye(2)]
    for _ in range(substeps - 1):
        powers.append(fine.a @ powers[-1])
    stacked = np.concatenate([power.T for power in powers[::-1]])  # (2·S, 2)
    per_sample = fine_drive.reshape(n, 2 * substeps) @ stacked
    fine_drive[substeps - 1 :: substeps] += drive - per_sample
    law = getattr(force, "law", None)
    if law is not None and _disjoint(windows):  # a known law: the compiled loop, in place
        from dtwin.twin._force_kernels import substepped_windows

        force_step = fine if fine_hold == FOH else hold_matrices(c / m, k / m, fine_dt, FOH)
        (a11, a12), (a21, a22) = fine.a.tolist()
        (q1, q2), (r1, r2) = force_step.taps.tolist()
        steps = (a11, a12, a21, a22, q1, q2, r1, r2)
        return substepped_windows(
            fine_drive, windows, substeps, x_start, v_start, steps, law, 1 / m
        )
    fine_windows = [(a * substeps, (b - 1) * substeps + 1) for a, b in windows]
    fine_x, fine_v = np.zeros(n * substeps), np.zeros(n * substeps)
    starts = np.array([a for a, _ in windows], dtype=int)
    fine_x[starts * substeps], fine_v[starts * substeps] = x_start[starts], v_start[starts]
    fine_out = exact_plant_response(
        fine_u,
        m,
        c,
        k,
        fine_dt,
        windows=fine_windows,
        x_start=fine_x,
        v_start=fine_v,
        hold=fine_hold,
        force=force,
        drive=fine_drive,
    )
    out = np.zeros(n)
    for a, b in windows:
        out[a:b] = fine_out[a * substeps : (b - 1) * substeps + 1 : substeps]
    return out


def _disjoint(windows: Sequence[tuple[int, int]]) -> bool:
    """Return whether the windows are in order and do not overlap."""
    return all(b <= a_next for (_, b), (a_next, _) in itertools.pairwise(windows))


def _tiling(starts: np.ndarray, length: int) -> slice | None:
    """Return the slice the windows cover if they tile it back to back, else None.

    Back-to-back windows (a fixed horizon) are a reshaped slice of the series, not a gathered
    copy: the same values, without the fancy indexing.
    """
    if len(starts) and np.array_equal(np.diff(starts), np.full(len(starts) - 1, length)):
        return slice(int(starts[0]), int(starts[0]) + len(starts) * length)
    return None
