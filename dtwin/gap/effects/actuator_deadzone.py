"""``actuator_deadzone`` (M0): no actuator output for commands inside ±D.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits (a hard symmetric dead zone); :data:`CASE` is how
the benchmark draws it and its real form (symmetric, asymmetric or smooth).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from dtwin.gap.effects import actuator_saturation
from dtwin.gap.effects._base import Effect
from dtwin.gap.effects._case import CaseEffect, log_between

__all__ = ["EFFECT", "CASE", "SOFT_DEADZONE", "deadzone"]


def deadzone(u: np.ndarray, width: float) -> np.ndarray:
    """Return ``sign(u)·max(|u| − D, 0)``: no output inside ``|u| < D``."""
    return np.sign(u) * np.maximum(np.abs(u) - width, 0.0)


def _deadzone_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return deadzone(u, theta[0])


_HARD = Effect(
    "actuator_deadzone",
    ("M0",),
    ("D",),
    ("input units",),
    "input",
    "u -> sign(u)·max(|u| − D, 0)",
    lambda s: [(0.0, 0.9 * s.input_max)],
    lambda s: [[f * s.input_max] for f in (0.05, 0.2, 0.45)],
    lambda s: [0.1 * s.input_max],
    input_map=_deadzone_input,
)


def _soft_deadzone_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    """Return ``u − u/(1 + |u/D|^p)^(1/p)``: the input less the catalogue's saturation at ±D."""
    return u - actuator_saturation.soft_saturation(u, theta[0], theta[1])


_SATURATION = actuator_saturation.EFFECT

#: The dead zone with a sharpness ``p``, the hard one as ``p → ∞``: the wider form its
#: interval is contrasted with (``Effect.smoothed``).
SOFT_DEADZONE = replace(
    _HARD,
    name="soft_deadzone",
    params=("D", "p"),
    units=("input units", "1"),
    formula="u -> u − u/(1 + |u/D|^p)^(1/p)  (dead zone ±D, sharpness p)",
    bounds=lambda s: [(1e-6 * s.input_max, 0.9 * s.input_max), _SATURATION.bounds(s)[1]],
    typical=lambda s: [_HARD.typical(s)[0], _SATURATION.typical(s)[1]],
    input_map=_soft_deadzone_input,
)

EFFECT = replace(_HARD, smoothed=SOFT_DEADZONE)


def _draw_deadzone(module, level, rng, scale) -> dict[str, Any]:
    """Return an ``actuator_deadzone``: half-widths ``D_high``, ``D_low`` (u units)."""
    form = str(rng.choice(["symmetric", "asymmetric", "smooth"]))
    width = log_between(0.05, 0.3, level) * scale["u_std"]
    ratio = rng.uniform(0.6, 1.0) if form == "asymmetric" else 1.0
    return {"form": form, "D_high": width, "D_low": width * ratio}


def _deadzone(u, spec, dt):
    """``actuator_deadzone``: half-widths ``D_high``, ``D_low``, or a smooth one (u units)."""
    high, low = spec["D_high"], spec["D_low"]
    if spec["form"] == "smooth":
        return u - high * np.tanh(u / high)
    return np.where(u > high, u - high, np.where(u < -low, u + low, 0.0))


def _deadzone_truth(spec, key, dt):
    """Return a symmetric dead zone's half-width ``D``; None for an asymmetric one."""
    if spec.get("form") in ("symmetric", "smooth"):
        return "D", spec["D_high"], 0.0
    return None


CASE = CaseEffect("actuator_deadzone", _draw_deadzone, actuator=_deadzone, truth=_deadzone_truth)
