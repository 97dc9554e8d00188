"""The catalogue of candidate unmodelled effects of the gap diagnoser, one module per effect.

Specification: docs/gap.md §Candidate effects (the catalogue table).

Each effect's module holds its :class:`Effect` (``EFFECT``: modules, parameters with units and
bounds, the textbook form the diagnoser fits) and its benchmark case (``CASE``: how the
benchmark draws it and the real form it acts in, or None; :class:`CaseEffect`). What every
effect is made of is :mod:`~dtwin.gap.effects._base`. Adding an effect is one module here, listed
in :data:`EFFECT_MODULES`, plus its test (tests/gap/test_gap_effects.py walks the catalogue);
no code branches on an effect's name.
"""

from __future__ import annotations

from types import ModuleType

from dtwin.gap.effects import (
    actuator_deadzone,
    actuator_delay,
    actuator_saturation,
    coulomb_friction,
    cubic_stiffness,
    parameter_mismatch,
    quadratic_damping,
    sensor_bias_drift,
    sensor_delay,
    sensor_quantization,
    sensor_scale_error,
    stribeck_friction,
)
from dtwin.gap.effects._base import (
    ARRAY_OPS,
    FRICTION_SMOOTHING,
    NONE,
    PARAMETER_MISMATCH,
    SCALAR_OPS,
    UNEXPLAINED,
    Effect,
    ForceOps,
    Scales,
)
from dtwin.gap.effects._case import CaseEffect
from dtwin.gap.effects._delay import MAX_DELAY_SAMPLES, fractional_delay
from dtwin.gap.effects.actuator_deadzone import deadzone
from dtwin.gap.effects.actuator_saturation import soft_saturation
from dtwin.gap.effects.sensor_bias_drift import DRIFT_CURVATURE_MAX, bias_drift
from dtwin.gap.effects.sensor_quantization import (
    find_lattice,
    quantization_variance,
    quantizer_log_density,
    refine_lattice,
    smooth_quantize,
)

__all__ = [
    "Scales",
    "Effect",
    "ForceOps",
    "CaseEffect",
    "ARRAY_OPS",
    "SCALAR_OPS",
    "FRICTION_SMOOTHING",
    "EFFECT_MODULES",
    "EFFECTS",
    "EFFECT_NAMES",
    "CATALOGUE_CASES",
    "MAX_DELAY_SAMPLES",
    "NONE",
    "UNEXPLAINED",
    "PARAMETER_MISMATCH",
    "effects_for_module",
    "effect_by_name",
    "soft_saturation",
    "deadzone",
    "fractional_delay",
    "bias_drift",
    "DRIFT_CURVATURE_MAX",
    "smooth_quantize",
    "quantization_variance",
    "quantizer_log_density",
    "find_lattice",
    "refine_lattice",
]

#: Every effect's module, in the catalogue's order (the order candidates are tried and listed).
EFFECT_MODULES: tuple[ModuleType, ...] = (
    actuator_saturation,
    actuator_deadzone,
    actuator_delay,
    coulomb_friction,
    stribeck_friction,
    cubic_stiffness,
    quadratic_damping,
    sensor_quantization,
    sensor_scale_error,
    sensor_bias_drift,
    sensor_delay,
    parameter_mismatch,
)

EFFECTS: tuple[Effect, ...] = tuple(module.EFFECT for module in EFFECT_MODULES)

#: The benchmark's case of each catalogue effect that has one (its draw and real form), by name.
CATALOGUE_CASES: dict[str, CaseEffect] = {
    module.CASE.name: module.CASE for module in EFFECT_MODULES if module.CASE is not None
}

#: Every name a diagnosis can report as ``effect``.
EFFECT_NAMES: tuple[str, ...] = (*(effect.name for effect in EFFECTS), NONE, UNEXPLAINED)


def effects_for_module(module: str, *, include_mismatch: bool = True) -> list[Effect]:
    """Return the candidate effects of ``module`` (``parameter_mismatch`` first if included)."""
    found = [e for e in EFFECTS if module in e.modules and not e.refits_linear]
    if include_mismatch:
        found.insert(0, effect_by_name(PARAMETER_MISMATCH))
    return found


def effect_by_name(name: str) -> Effect:
    """Return the :class:`Effect` called ``name``."""
    for effect in EFFECTS:
        if effect.name == name:
            return effect
    raise KeyError(f"unknown effect {name!r}; known: {', '.join(e.name for e in EFFECTS)}")
