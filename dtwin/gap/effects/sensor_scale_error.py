"""``sensor_scale_error`` (M2a, M2b): the sensor reads its position times a gain.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits; :data:`CASE` is how the benchmark draws it (a
gain 6–35 % away from 1).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dtwin.gap.effects._base import Effect
from dtwin.gap.effects._case import CaseEffect, log_between, spec_value

__all__ = ["EFFECT", "CASE"]


def _scale_output(lag, bias, t, theta) -> np.ndarray:
    return theta[0] * lag + bias


EFFECT = Effect(
    "sensor_scale_error",
    ("M2a", "M2b"),
    ("gain",),
    ("1",),
    "output",
    "y = gain·lag + bias",
    lambda s: [(0.1, 10.0)],
    lambda s: [[1.0]],
    lambda s: [0.1],
    linear_form=True,
    output_map=_scale_output,
)


def _draw_scale_error(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``sensor_scale_error``: a gain 6–35 % away from 1."""
    sign = 1 if rng.uniform() < 0.5 else -1
    return {"form": "gain", "gain": 1 + sign * log_between(0.06, 0.35, level)}


def _scale_error(lag, spec):
    return spec["gain"] * lag


CASE = CaseEffect(
    "sensor_scale_error",
    _draw_scale_error,
    sensor_gain=_scale_error,
    truth=spec_value("gain", without=1.0),
)
