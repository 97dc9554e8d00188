"""``sensor_bias_drift`` (M2a, M2b): the sensor's offset drifts over the recording.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits (:func:`bias_drift`); :data:`CASE` is how the
benchmark draws it and its real form (a power, an exponential or a line with a wander).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dtwin.gap.effects._base import Effect
from dtwin.gap.effects._case import CaseEffect, log_between

__all__ = ["EFFECT", "CASE", "DRIFT_CURVATURE_MAX", "bias_drift"]


#: Largest |curvature·duration| of ``sensor_bias_drift``: the drift's rate changes at most
#: e^10-fold over the recording.
DRIFT_CURVATURE_MAX = 10.0


def bias_drift(t: np.ndarray, rate: float, curvature: float) -> np.ndarray:
    """Return a sensor's drift ``rate·(1 − exp(−ρ·t))/ρ`` at times ``t`` (s), shape of ``t``.

    A drift whose rate changes exponentially, ``rate·exp(−ρ·t)``: ``ρ > 0`` settles (a sensor
    warming up, the first-order thermal drift), ``ρ < 0`` accelerates, ``ρ = 0`` is the
    straight line ``rate·t``. A straight line fitted on the training part overshot a settling
    drift on the choosing part: strong drifts (signal-to-noise 4–8) read ``unexplained``.
    """
    t = np.asarray(t, dtype=float)
    if abs(curvature) * float(np.max(np.abs(t), initial=0.0)) < 1e-9:
        return rate * t
    return rate * -np.expm1(-curvature * t) / curvature


def _drift_output(lag, bias, t, theta) -> np.ndarray:
    return lag + bias + bias_drift(t, theta[0], theta[1])


EFFECT = Effect(
    "sensor_bias_drift",
    ("M2a", "M2b"),
    ("rate", "curvature"),
    ("output units / s", "1 / s"),
    "output",
    "y = lag + bias + rate·(1 − exp(−ρ·t))/ρ,  ρ = curvature (ρ = 0: rate·t)",
    lambda s: [
        (-100.0 * s.output_std / s.duration, 100.0 * s.output_std / s.duration),
        (-DRIFT_CURVATURE_MAX / s.duration, DRIFT_CURVATURE_MAX / s.duration),
    ],
    lambda s: [[0.0, 0.0], [0.0, 3.0 / s.duration], [0.0, -1.0 / s.duration]],
    lambda s: [0.1 * s.output_std / s.duration, 1.0 / s.duration],
    output_map=_drift_output,
)


def _draw_bias_drift(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``sensor_bias_drift`` of ``total`` (2.5–15 σ) with a non-linear shape."""
    form = str(rng.choice(["power", "exponential", "linear_plus_wander"]))
    total = log_between(2.5, 15.0, level) * scale["sigma"] * (1 if rng.uniform() < 0.5 else -1)
    return {
        "form": form,
        "total": total,
        "power": rng.uniform(0.6, 1.6),
        "tau_frac": rng.uniform(0.4, 1.5),
    }


def _bias_drift(y, spec, t, x):
    """Return the reading plus a drift of ``total`` over the run, shaped by ``form``."""
    s = t / t[-1]
    if spec["form"] == "power":
        shape = s ** spec["power"]
    elif spec["form"] == "exponential":
        shape = (1 - np.exp(-s / spec["tau_frac"])) / (1 - math.exp(-1 / spec["tau_frac"]))
    else:
        shape = 0.8 * s + 0.2 * np.sin(2 * np.pi * 0.7 * s) ** 2
    return y + spec["total"] * shape


CASE = CaseEffect("sensor_bias_drift", _draw_bias_drift, reading=_bias_drift)
