"""``quadratic_damping`` (M1): a damping force ``c2·v·|v|`` beyond the linear one.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits; :data:`CASE` is how the benchmark draws it and
its real form (a power 1.7–2.3).
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._base import Effect, ForceOps
from dtwin.gap.effects._case import CaseEffect, log_between

__all__ = ["EFFECT", "CASE"]


def _quadratic_damping_law(theta, velocity_std: float, ops: ForceOps):
    """``F = c2·v·|v|``."""
    c2 = float(theta[0])
    return lambda x, v: c2 * v * ops.abs(v)


def _quadratic_damping_compiled(
    values: list[float], smooth: float
) -> tuple[str, tuple[float, ...]]:
    return "quadratic_damping", (values[0],)


EFFECT = Effect(
    "quadratic_damping",
    ("M1",),
    ("c2",),
    ("input units·s²/output units²",),
    "force",
    "F = c2·v·|v|",
    lambda s: [(0.0, 50.0 * s.input_std / s.velocity_std**2)],
    lambda s: [[0.05 * s.input_std / s.velocity_std**2]],
    lambda s: [0.1 * s.input_std / s.velocity_std**2],
    force_law=_quadratic_damping_law,
    compiled_law=_quadratic_damping_compiled,
)


def _draw_damping(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``quadratic_damping``: ``ratio·c·v_ref·|v/v_ref|^power``, power 1.7–2.3."""
    power = float(rng.uniform(1.7, 2.3))
    ratio = log_between(0.15, 3.0, level)
    return {"form": f"|v|^{power:.2f}", "power": power, "ratio": ratio, "v_ref": scale["v_max"]}


def _damping(spec, c, k, min_smoothing=0.0):
    ratio, ref, power = spec["ratio"], spec["v_ref"], spec["power"]
    return "power_damping", (ratio * c * ref, ref, power)


CASE = CaseEffect("quadratic_damping", _draw_damping, force=_damping)
