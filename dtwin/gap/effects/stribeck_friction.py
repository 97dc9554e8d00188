"""``stribeck_friction`` (M1): Coulomb friction with a breakaway force ``Fs`` at rest.

Specification: docs/gap.md §Candidate effects.

:data:`EFFECT` is the form the diagnoser fits; it nests ``coulomb_friction`` (``Fs = Fc``).
The default cases draw none of it (:data:`CASE` is None): ``coulomb_friction``'s real form has
the bump, and the ``unseen`` arm draws a generalised Stribeck friction under this name
(:mod:`dtwin.gapbench.arms`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from dtwin.gap.effects._base import CompiledLaw, Effect, ForceOps, Scales, smoothing_velocity

__all__ = ["EFFECT", "CASE"]


def _stribeck_law(theta, velocity_std: float, ops: ForceOps):
    """``F = (Fc + max(Fs − Fc, 0)·exp(−(v/vs)²))·tanh(v/v_s)``: the breakaway force at rest.

    A breakaway force below the sliding one is no Stribeck bump (it would mimic a viscous
    term: a Coulomb and viscous friction read as Stribeck friction with ``Fs < Fc``).
    """
    fc, fs, vs = (float(value) for value in theta)
    bump, vs, smooth = max(fs - fc, 0.0), max(abs(vs), 1e-300), smoothing_velocity(velocity_std)

    def stribeck(x, v):
        ratio = v / vs
        return (fc + bump * ops.exp(-ratio * ratio)) * ops.tanh(v / smooth)

    return stribeck


def _stribeck_from_coulomb(theta: Sequence[float], s: Scales) -> list[list[float]]:
    """Stribeck starts from a fitted Coulomb level ``Fc``: the Coulomb fit itself, then a bump.

    A Coulomb friction fitted to a friction with a breakaway force reads a level between the
    sliding and the breakaway force, so the bumped starts put the sliding force below it and
    the breakaway force above it, at a low and a middling Stribeck velocity.
    """
    fc = float(theta[0])
    low, mid = 0.1 * s.velocity_std, 0.3 * s.velocity_std
    return [[fc, fc, low], [0.8 * fc, 2.0 * fc, low], [0.8 * fc, 2.0 * fc, mid]]


def _breakaway_excess(theta: Sequence[float]) -> float:
    """``(Fs − Fc)/Fc`` (0 without a bump, inf for a bump on no sliding force)."""
    fc, fs = float(theta[0]), float(theta[1])
    bump = max(fs - fc, 0.0)
    return bump / fc if fc > 0 else (math.inf if bump > 0 else 0.0)


def _coulomb_part(theta: Sequence[float]) -> list[float]:
    """``[Fc]``: the Coulomb friction this one is when ``Fs ≤ Fc`` (no bump)."""
    return [float(theta[0])]


def _stribeck_compiled(values: list[float], smooth: float) -> CompiledLaw:
    fc, fs, vs = values
    return "stribeck_friction", (fc, max(fs - fc, 0.0), max(abs(vs), 1e-300), smooth)


EFFECT = Effect(
    "stribeck_friction",
    ("M1",),
    ("Fc", "Fs", "vs"),
    ("input units (force)", "input units (force)", "output units / s"),
    "force",
    "F = (Fc + max(Fs − Fc, 0)·exp(−(v/vs)²))·tanh(v / v_s),  v_s = 0.01·std(v)",
    lambda s: [
        (0.0, 3.0 * s.input_max),
        (0.0, 3.0 * s.input_max),
        (0.05 * s.velocity_std, 0.5 * s.velocity_std),
    ],
    lambda s: [[0.05 * s.input_std, 0.1 * s.input_std, f * s.velocity_std] for f in (0.1, 0.3)],
    lambda s: [0.1 * s.input_std, 0.1 * s.input_std, 0.1 * s.velocity_std],
    nests=("coulomb_friction",),
    nested_starts=_stribeck_from_coulomb,
    departure=_breakaway_excess,
    plain_part=_coulomb_part,
    force_law=_stribeck_law,
    compiled_law=_stribeck_compiled,
)


#: The benchmark draws no case of this effect of its own.
CASE = None
