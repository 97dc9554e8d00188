"""``coulomb_friction`` (M1): a sliding friction force of constant size ``Fc``.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` is the form the diagnoser fits (``Fc·tanh(v/v_s)``); :data:`CASE` is how the
benchmark draws it and its real form (a Stribeck bump, or Coulomb plus viscous friction).
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._base import CompiledLaw, Effect, ForceOps, smoothing_velocity
from dtwin.gap.effects._case import CaseEffect, log_between, spec_value

__all__ = ["EFFECT", "CASE"]


def _coulomb_law(theta, velocity_std: float, ops: ForceOps):
    """``F = Fc·tanh(v/v_s)``."""
    fc, smooth = float(theta[0]), smoothing_velocity(velocity_std)
    return lambda x, v: fc * ops.tanh(v / smooth)


def _coulomb_compiled(values: list[float], smooth: float) -> CompiledLaw:
    return "tanh_friction", (values[0], smooth)


EFFECT = Effect(
    "coulomb_friction",
    ("M1",),
    ("Fc",),
    ("input units (force)",),
    "force",
    "F = Fc·tanh(v / v_s),  v_s = 0.01·std(v)",
    lambda s: [(0.0, 3.0 * s.input_max)],
    lambda s: [[0.05 * s.input_std]],
    lambda s: [0.1 * s.input_std],
    force_law=_coulomb_law,
    compiled_law=_coulomb_compiled,
)


def _draw_friction(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``coulomb_friction``: Stribeck or Coulomb + viscous (``Fc``, ``Fs`` in N)."""
    fc = log_between(0.012, 0.2, level) * scale["u_max"]
    form = str(rng.choice(["stribeck", "coulomb_viscous"]))
    return {
        "form": form,
        "Fc": fc,
        "Fs": fc * rng.uniform(1.2, 2.0) if form == "stribeck" else fc,
        "vs": rng.uniform(0.05, 0.3) * scale["v_std"],
        "extra_c": rng.uniform(0.0, 0.05) if form == "coulomb_viscous" else 0.0,
    }


def _friction(spec, c, k, min_smoothing=0.0):
    """Stribeck or Coulomb + viscous friction; its sign smoothed over ``10⁻³·vs`` or more."""
    fc, fs, vs = spec["Fc"], spec["Fs"], spec["vs"]
    smooth = max(1e-3 * vs, min_smoothing)
    return "generalised_stribeck", (fc, fs - fc, vs, 2.0, smooth, spec["extra_c"])


CASE = CaseEffect("coulomb_friction", _draw_friction, force=_friction, truth=spec_value("Fc"))
