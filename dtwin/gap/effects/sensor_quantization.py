"""``sensor_quantization`` (M2a, M2b): the sensor's reading sits on a lattice of step ``q``.

Specification: docs/gap.md §Candidate effects, §Which, §Generator.

:data:`EFFECT` is the form the diagnoser fits, with the lattice tools it is fitted and chosen
by (:func:`find_lattice`, :func:`refine_lattice`, :func:`quantizer_log_density`,
:func:`quantization_variance`); :data:`CASE` is how the benchmark draws it (a quantizer after
the noise).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dtwin.gap.effects._base import Effect
from dtwin.gap.effects._case import CaseEffect, log_between, spec_value

__all__ = [
    "EFFECT",
    "CASE",
    "smooth_quantize",
    "quantization_variance",
    "quantizer_log_density",
    "find_lattice",
    "refine_lattice",
]


def smooth_quantize(s: np.ndarray, step: float, noise_std: float) -> np.ndarray:
    """Return ``E[q·round((s + ε)/q)]`` for ``ε ~ N(0, σ²)``, the MSE-best quantized prediction.

    Notes
    -----
    ``q·round(s/q) − s`` is a sawtooth with Fourier series
    ``Σ_m (q/(π m))·(−1)^m·sin(2π m s/q)``; averaging over Gaussian noise before the quantizer
    damps term m by ``exp(−2π² m² σ²/q²)``. With ``σ → 0`` this is the hard staircase; with
    ``σ ≳ q/2`` it is ``s``: a quantizer finer than the noise is invisible in the mean.
    """
    step = abs(step)
    if step <= 0:
        return s
    sigma = max(noise_std, step / 60.0)
    out = s.copy()
    phase = 2.0 * np.pi * s / step
    for m in range(1, 61):
        damp = math.exp(-2.0 * math.pi**2 * m * m * sigma * sigma / (step * step))
        if damp < 1e-5:
            break
        out += (step / (math.pi * m)) * (-1.0) ** m * damp * np.sin(m * phase)
    return out


#: Above this noise-to-step ratio the quantizer's conditional variance is ``σ² + q²/12``
#: up to terms of order ``exp(−2π²·ratio²)`` (< 1e-34 at 2): Sheppard's correction.
_SHEPPARD_RATIO = 2.0


#: Rows per block in :func:`quantization_variance`: bounds its temporaries at a few MB.
_QUANTIZATION_BLOCK = 1 << 15


def quantization_variance(s: np.ndarray, step: float, noise_std: float) -> float:
    """Return the mean over ``s`` of ``Var(q·round((s + ε)/q) | s)``, ``ε ~ N(0, σ²)``.

    The part of a quantizer's output that no prediction can remove: with noise before the
    quantizer the quantization error is itself random.

    Parameters
    ----------
    s : ndarray, shape (T,)
        Noise-free signal before the quantizer (signal units).
    step : float
        Quantizer step ``q`` (signal units).
    noise_std : float
        Standard deviation ``σ`` of the Gaussian noise before the quantizer (signal units).

    Returns
    -------
    float
        The mean conditional variance (signal units squared); 0 when ``σ`` or ``q`` is not
        positive.

    Notes
    -----
    For ``σ ≥ 2q`` the closed form ``σ² + q²/12`` holds to within ``exp(−2π²σ²/q²)`` of the
    variance; below that the exact sum runs over the ``≤ 35`` levels within ``8σ`` of each
    sample, in blocks of rows. Memory is O(1) beyond ``s`` whatever the values' magnitudes.

    Examples
    --------
    >>> s = np.linspace(0.0, 1.0, 1001)
    >>> round(quantization_variance(s, 0.1, 1.0) / (1.0 + 0.1**2 / 12), 12)
    1.0
    >>> quantization_variance(s, 0.1, 0.0)
    0.0
    """
    if not (noise_std > 0 and step > 0) or len(s) == 0:
        return 0.0
    if noise_std >= _SHEPPARD_RATIO * step:
        return float(noise_std**2 + step**2 / 12.0)
    total = 0.0
    for start in range(0, len(s), _QUANTIZATION_BLOCK):
        total += _quantization_variance_sum(s[start : start + _QUANTIZATION_BLOCK], step, noise_std)
    return total / len(s)


def _quantization_variance_sum(s: np.ndarray, step: float, noise_std: float) -> float:
    """Return the sum over ``s`` of the exact conditional variance (``σ < 2q``, ≤ 35 levels).

    Levels within ``8σ`` of each sample, measured from the sample (variance is shift-free, so
    the truncated mass, < 1.3e-15, does not scale with ``s²``), probabilities renormalised.
    """
    from scipy.special import ndtr

    reach = int(math.ceil(8 * noise_std / step)) + 1
    levels = np.round(s / step)[:, None] + np.arange(-reach, reach + 1)[None, :]
    offsets = levels * step - s[:, None]
    prob = ndtr((offsets + 0.5 * step) / noise_std) - ndtr((offsets - 0.5 * step) / noise_std)
    prob /= np.sum(prob, axis=1, keepdims=True)
    mean = np.sum(prob * offsets, axis=1)
    return float(np.sum(np.sum(prob * offsets**2, axis=1) - mean**2))


def quantizer_log_density(
    y: np.ndarray,
    s: np.ndarray,
    step: float,
    offset: float,
    noise_before: float,
    noise_after: float,
) -> np.ndarray:
    """Return ``log p(y[k] | s[k])`` of a quantizer between two noises, shape ``(T,)``.

    ``y = offset + q·round((s − offset + ε_b)/q) + ε_a`` with ``ε_b ~ N(0, σ_b²)``,
    ``ε_a ~ N(0, σ_a²)``: a Gaussian mixture over the levels within ``8σ_b`` of each sample,
    level ``l`` weighted by ``P(l | s) = Φ((l·q + q/2 − s')/σ_b) − Φ((l·q − q/2 − s')/σ_b)``.
    Values that sit on a lattice (small ``σ_a``) are far likelier under it than under any
    Gaussian as wide as the quantization error: this is how a quantizer is told apart when the
    noise before it makes its staircase unpredictable. Rows are processed in blocks (memory
    O(block·levels)).

    Parameters
    ----------
    y, s : ndarray, shape (T,)
        Recorded output and the noise-free prediction before the quantizer (signal units).
    step, offset : float
        Quantizer step ``q > 0`` and lattice offset (signal units).
    noise_before, noise_after : float
        ``σ_b ≥ 0`` and ``σ_a > 0`` (signal units).

    Examples
    --------
    >>> y = np.array([0.0, 0.1, 0.2])
    >>> bool(np.all(quantizer_log_density(y, y, 0.1, 0.0, 0.0, 0.001) > 5.0))
    True
    """
    from scipy.special import logsumexp, ndtr

    sigma_b = max(float(noise_before), 1e-6 * step)
    reach = int(math.ceil(8 * sigma_b / step)) + 1
    out = np.empty(len(y))
    for start in range(0, len(y), _QUANTIZATION_BLOCK):
        rows = slice(start, start + _QUANTIZATION_BLOCK)
        shifted = s[rows] - offset
        levels = np.round(shifted / step)[:, None] + np.arange(-reach, reach + 1)[None, :]
        centre = levels * step - shifted[:, None]
        prob = ndtr((centre + 0.5 * step) / sigma_b) - ndtr((centre - 0.5 * step) / sigma_b)
        residual = (y[rows] - offset)[:, None] - levels * step
        log_normal = -0.5 * (residual / noise_after) ** 2 - math.log(
            noise_after * math.sqrt(2 * math.pi)
        )
        out[rows] = logsumexp(log_normal, b=np.maximum(prob, 1e-300), axis=1)
    return out


def refine_lattice(y: np.ndarray, step: float, offset: float, rounds: int = 3):
    """Return ``(q, offset, blur)``: a lattice refined by least squares on its level numbers.

    Each value is given its level ``l = round((y − offset)/q)``; regressing ``y`` on ``l``
    gives the step and offset exactly when the values sit on a lattice (a grid search leaves
    an error of a per cent or so, which the far levels multiply); ``blur`` is the residual's
    standard deviation (noise after the quantizer). Stops when the levels no longer change.

    Examples
    --------
    >>> y = 0.37 * np.arange(-6, 7) + 0.05
    >>> [round(v, 9) for v in refine_lattice(y, 0.35, 0.0)]
    [0.37, 0.05, 0.0]
    """
    levels = None
    for _ in range(rounds):
        new_levels = np.round((y - offset) / step)
        if levels is not None and np.array_equal(new_levels, levels):
            break
        levels = new_levels
        if np.ptp(levels) == 0:
            break
        slope, intercept = np.polyfit(levels, y, 1)
        if not slope > 0:
            break
        step, offset = float(slope), float(intercept)
    blur = float(np.std(y - offset - step * np.round((y - offset) / step)))
    return step, offset, blur


def find_lattice(y: np.ndarray, low: float, high: float, n_grid: int = 400):
    """Return ``(q, offset, concentration)`` of the coarsest lattice the values ``y`` sit on.

    For each step ``q`` on a log grid in ``[low, high]`` the concentration
    ``R(q) = |mean(exp(2πi·y/q))|`` is 1 when every value is a multiple of ``q`` (plus an
    offset), ``exp(−2π²σ²/q²)`` when noise of std σ is added after the quantizer, and about
    ``1/√n`` for values on no lattice. The coarsest step whose concentration is at least half
    the best is returned (a lattice of step q also lies on q/2, q/3, …), refined locally.
    """
    grid = np.geomspace(low, high, n_grid)
    sample = y[:: max(1, len(y) // 5000)]
    conc = np.array([abs(np.mean(np.exp(2j * np.pi * sample / q))) for q in grid])
    best = conc.max()
    index = int(np.flatnonzero(conc >= 0.5 * best)[-1])
    index = max(range(max(0, index - 3), min(n_grid, index + 4)), key=lambda i: conc[i])
    while index > 0 and conc[index - 1] > conc[index]:  # up to the peak: a coarse lattice's
        index -= 1  # shoulder (few levels) can stay above half the best far from its peak
    fine = np.linspace(grid[max(0, index - 1)], grid[min(n_grid - 1, index + 1)], 41)
    fine_conc = [abs(np.mean(np.exp(2j * np.pi * sample / q))) for q in fine]
    q = float(fine[int(np.argmax(fine_conc))])
    phase = np.angle(np.mean(np.exp(2j * np.pi * y / q)))
    return q, float(phase * q / (2 * np.pi)), float(max(fine_conc))


def _quantizer_output(lag, bias, t, theta) -> np.ndarray:
    step, offset, before = theta
    return offset + smooth_quantize(lag + bias - offset, step, before)


EFFECT = Effect(
    "sensor_quantization",
    ("M2a", "M2b"),
    ("q", "offset", "noise_before"),
    ("output units", "output units", "output units"),
    "output",
    "y = offset + q·round((lag + bias − offset + e)/q) + e',  e ~ N(0, noise_before²)",
    lambda s: [(1e-12, 4.0 * s.output_std), (-np.inf, np.inf), (0.0, np.inf)],
    lambda s: [[]],
    lambda s: [max(s.noise_std, 0.01 * s.output_std), s.output_std, s.noise_std or 1.0],
    output_map=_quantizer_output,
    lattice=True,
)


def _draw_quantization(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``sensor_quantization`` with step ``q`` of 3–10 noise standard deviations."""
    return {"form": "round after noise", "q": log_between(3.0, 10.0, level) * scale["sigma"]}


def _quantization(y, spec, t, x):
    return spec["q"] * np.round(y / spec["q"])


CASE = CaseEffect(
    "sensor_quantization", _draw_quantization, reading=_quantization, truth=spec_value("q")
)
