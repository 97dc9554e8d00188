"""``sensor_delay`` (M2a, M2b): an extra delay of the position a sensor reads, fractional.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits; :data:`CASE` is how the benchmark draws it (4–15
samples) and acts on the sensor's input. The delay forms are shared with ``actuator_delay``
(:mod:`dtwin.gap.effects._delay`).
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._case import CaseEffect, log_between
from dtwin.gap.effects._delay import delay_effect, delay_truth, delayed

__all__ = ["EFFECT", "CASE"]


EFFECT = delay_effect(
    "sensor_delay", ("M2a", "M2b"), "x[k] -> x[k − delay/dt]  (fractional, linear interpolation)"
)


def _draw_sensor_delay(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``sensor_delay`` of 4–15 samples (fractional)."""
    return {"form": "fractional", "delay_samples": log_between(4.0, 15.0, level)}


CASE = CaseEffect(
    "sensor_delay",
    _draw_sensor_delay,
    sensor_input=delayed,
    continuous_delay=True,
    truth=delay_truth,
)
