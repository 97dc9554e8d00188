"""``actuator_delay`` (M0): an extra delay of the command, in seconds, fractional.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits; :data:`CASE` is how the benchmark draws it (0.8–6
samples) and acts on the command. The delay forms are shared with ``sensor_delay``
(:mod:`dtwin.gap.effects._delay`).
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._case import CaseEffect, log_between
from dtwin.gap.effects._delay import delay_effect, delay_truth, delayed

__all__ = ["EFFECT", "CASE"]


EFFECT = delay_effect(
    "actuator_delay", ("M0",), "u_cmd[k] -> u_cmd[k − delay/dt]  (fractional, linear interpolation)"
)


def _draw_actuator_delay(module, level, rng, scale) -> dict[str, Any]:
    """Return an ``actuator_delay`` of 0.8–6 samples (fractional)."""
    return {"form": "fractional", "delay_samples": log_between(0.8, 6.0, level)}


CASE = CaseEffect("actuator_delay", _draw_actuator_delay, actuator=delayed, truth=delay_truth)
