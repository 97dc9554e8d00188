"""``actuator_saturation`` (M0): the actuator cannot deliver more than a limit ±U.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits (a soft saturation, sharpness ``p``);
:data:`CASE` is how the benchmark draws it and the real form it acts in (tanh, clip or an
asymmetric clip), which differ from the fitted one on purpose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from dtwin.gap.effects._base import Effect
from dtwin.gap.effects._case import CaseEffect, log_between

__all__ = ["EFFECT", "CASE", "soft_saturation"]


def soft_saturation(u: np.ndarray, limit: float, sharpness: float) -> np.ndarray:
    """Return ``u / (1 + |u/U|^p)^(1/p)``: a saturation at ±U, hard as ``p → ∞``."""
    ratio = np.abs(u / limit)
    with np.errstate(over="ignore"):
        return u / np.power(1.0 + np.power(ratio, sharpness), 1.0 / sharpness)


def _saturation_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return soft_saturation(u, theta[0], theta[1])


EFFECT = Effect(
    "actuator_saturation",
    ("M0",),
    ("U", "p"),
    ("input units", "1"),
    "input",
    "u -> u / (1 + |u/U|^p)^(1/p)  (saturation at ±U, sharpness p)",
    lambda s: [(0.02 * s.input_max, 3.0 * s.input_max), (1.0, 40.0)],
    lambda s: [[f * s.input_max, p] for f in (0.4, 0.7, 1.0) for p in (3.0, 12.0)],
    lambda s: [s.input_max, 5.0],
    input_map=_saturation_input,
    # A tanh saturation read through the algebraic form overshoots its level by 10–30 % when
    # the input stays below about twice the level: the data bound U from below only.
    input_limit=("U", "u_cmd"),
)


def _draw_saturation(module, level, rng, scale) -> dict[str, Any]:
    """Return an ``actuator_saturation``: tanh (``U``) or clip (``U_high``, ``U_low``), u units."""
    form = str(rng.choice(["tanh", "clip", "asymmetric_clip"]))
    umax = scale["u_max"]
    if form == "tanh":
        return {"form": form, "U": log_between(2.0, 0.55, level) * umax}
    high = log_between(0.9, 0.4, level) * umax
    low = high if form == "clip" else high * rng.uniform(1.1, 1.6)
    return {"form": form, "U_high": high, "U_low": low}


def _saturation(u, spec, dt):
    """``actuator_saturation``: tanh (``U``) or clip (``U_high``, ``U_low``), u units."""
    if spec["form"] == "tanh":
        return spec["U"] * np.tanh(u / spec["U"])
    return np.clip(u, -spec["U_low"], spec["U_high"])


def _saturation_truth(spec, key, dt):
    """Return a symmetric saturation's level ``U`` (tanh or clip); None if asymmetric."""
    if spec.get("form") == "tanh":
        return "U", spec["U"], math.inf
    if spec.get("form") == "clip":
        return "U", spec["U_high"], math.inf
    return None


CASE = CaseEffect(
    "actuator_saturation", _draw_saturation, actuator=_saturation, truth=_saturation_truth
)
