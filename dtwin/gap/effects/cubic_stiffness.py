"""``cubic_stiffness`` (M1): a spring force ``k3·(x − x0)³`` beyond the linear one.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits; :data:`CASE` is how the benchmark draws it and
its real form (a power near 2, hardening or softening).
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._base import CompiledLaw, Effect, ForceOps, Scales
from dtwin.gap.effects._case import CaseEffect, log_between

__all__ = ["EFFECT", "CASE"]


def _cubic_law(theta, velocity_std: float, ops: ForceOps):
    """``F = k3·(x − x0)³``."""
    k3, centre = float(theta[0]), float(theta[1])

    def cubic(x, v):
        offset = x - centre
        return k3 * offset * offset * offset

    return cubic


def _cubic_compiled(values: list[float], smooth: float) -> CompiledLaw:
    return "cubic_spring", (values[0], values[1])


def _centre_bounds(s: Scales) -> tuple[float, float]:
    """Return the bounds of a spring's centre: 3 standard deviations about the mean, and 0."""
    reach = 3.0 * s.output_std
    return (min(s.output_mean - reach, -reach), max(s.output_mean + reach, reach))


EFFECT = Effect(
    "cubic_stiffness",
    ("M1",),
    ("k3", "x0"),
    ("input units / output units^3", "output units"),
    "force",
    "F = k3·(x − x0)^3  (x0: the spring's centre in recording units)",
    lambda s: [
        (-50.0 * s.stiffness / s.output_std**2, 50.0 * s.stiffness / s.output_std**2),
        _centre_bounds(s),
    ],
    lambda s: [[0.0, 0.0], [0.0, s.output_mean]],
    lambda s: [0.1 * s.stiffness / s.output_std**2, s.output_std],
    force_law=_cubic_law,
    compiled_law=_cubic_compiled,
)


def _draw_stiffness(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``cubic_stiffness``: ``ratio·k·x_ref·|x/x_ref|^(power+1)``, power near 2."""
    power = float(rng.choice([2.0, rng.uniform(1.6, 2.4)]))
    # softening is capped so that the spring stays stiff over the whole run
    ratio = (
        log_between(0.06, 0.8, level) if rng.uniform() < 0.75 else -log_between(0.04, 0.2, level)
    )
    return {
        "form": f"|x|^{power:.2f} hardening" if ratio > 0 else f"|x|^{power:.2f} softening",
        "power": power,
        "ratio": ratio,
        "x_ref": scale["x_max"],
    }


def _stiffness(spec, c, k, min_smoothing=0.0):
    ratio, ref, power = spec["ratio"], spec["x_ref"], spec["power"]
    return "power_spring", (ratio * k * ref, ref, power + 1)


def _stiffness_truth(spec, key, dt):
    """Return a stiffness of power exactly 2 as the catalogue's ``k3``; None otherwise."""
    if spec.get("power") == 2.0:
        k = key["asset"]["plant"]["k"]
        return "k3", spec["ratio"] * k / spec["x_ref"] ** 2, 0.0
    return None


CASE = CaseEffect("cubic_stiffness", _draw_stiffness, force=_stiffness, truth=_stiffness_truth)
