"""The forms the two delay effects share (``actuator_delay``, ``sensor_delay``).

Specification: docs/gap.md §Candidate effects, §Generator.

The fitted form (:func:`fractional_delay` of the module input, bounds up to
:data:`MAX_DELAY_SAMPLES` samples) and the benchmark's real form and truth (a delay drawn in
samples, scored in seconds).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dtwin.gap.effects._base import Bounds, Effect, Scales

__all__ = [
    "MAX_DELAY_SAMPLES",
    "fractional_delay",
    "delay_input",
    "delay_bounds",
    "delay_starts",
    "delayed",
    "delay_truth",
    "delay_effect",
]


#: Longest extra delay a delay candidate may take, in samples.
MAX_DELAY_SAMPLES = 25


def fractional_delay(u: np.ndarray, delay_samples: float) -> np.ndarray:
    """Return ``u`` delayed by a non-negative, possibly fractional number of samples.

    ``u_d[k] = (1 − f)·u[k − n] + f·u[k − n − 1]`` with ``n + f = delay_samples``; samples
    before the start repeat ``u[0]``.
    """
    delay_samples = max(float(delay_samples), 0.0)
    whole = int(math.floor(delay_samples))
    frac = delay_samples - whole
    n = len(u)
    if whole >= n:
        return np.full(n, u[0])
    padded = np.concatenate([np.full(whole + 1, u[0]), u])
    shifted = padded[1 : n + 1]  # u[k - whole]
    shifted_more = padded[:n]  # u[k - whole - 1]
    return (1.0 - frac) * shifted + frac * shifted_more


def delay_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return fractional_delay(u, theta[0] / dt)


def delay_bounds(s: Scales) -> Bounds:
    return [(0.0, MAX_DELAY_SAMPLES * s.dt)]


def delay_starts(s: Scales) -> list[list[float]]:
    return [[(d + 0.5) * s.dt] for d in range(MAX_DELAY_SAMPLES)]


def delay_typical(s: Scales) -> list[float]:
    """Return a delay's typical size: one sample, s."""
    return [s.dt]


def delay_effect(name: str, modules: tuple[str, ...], formula: str) -> Effect:
    """Return the :class:`Effect` of an extra fractional delay of a module's input (``delay``, s).

    Bounds 0 to :data:`MAX_DELAY_SAMPLES` samples, a start in every whole sample; the two delay
    effects differ only in their name, modules and formula.
    """
    return Effect(
        name,
        modules,
        ("delay",),
        ("s",),
        "delay",
        formula,
        delay_bounds,
        delay_starts,
        delay_typical,
        input_map=delay_input,
    )


def delayed(u, spec, dt=None):
    """Return the signal delayed by ``delay_samples`` (fractional; actuator or sensor)."""
    return fractional_delay(u, spec["delay_samples"])


def delay_truth(spec, key, dt):
    """Return a delay's truth in s (it is drawn in samples)."""
    return "delay", spec["delay_samples"] * dt, 0.0
