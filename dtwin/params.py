"""Typed, validated parameters of the twin and of the command generator (paper §3.1).

The ``twin:`` mapping of ``config/config.yaml`` (and of a stand-alone twin file for the gap
diagnoser) has exactly this shape::

    dt: 0.02
    actuator: {tau: 0.15}
    plant: {m: 1.0, c: 0.4, k: 4.0}
    sensor_A: {tau: 0.08, bias: 0.0}
    sensor_B: {tau: 0.25, bias: 0.01}
    fusion: {alpha: 0.6}
    kpi: {w1: 1.0, w2: 0.2}
    noise: {actuator: 0.005, plant: 0.04, sensor_A: 0.03, sensor_B: 0.02}   # standard deviations
    discretisation: euler   # how the plant's m, c, k map to samples (optional)

Units: seconds for ``dt`` and every ``tau``; kg, N·s/m, N/m for the plant; signal units for
biases and noise standard deviations (the plant noise is an acceleration, m/s²).
``discretisation`` is one of :data:`dtwin.twin.paper_modules.DISCRETISATIONS`: ``euler`` (the
paper's explicit Euler, the only one :func:`dtwin.physics.simulate_physics` runs) or an exact hold
(``zoh``, ``foh``, ``bandlimited``: the gap diagnoser's plant, docs/gap.md §Modules); absent
(None), the gap diagnoser chooses on the training part.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, get_args, get_type_hints

from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_in_range,
    require_mapping,
    require_nonnegative,
    require_number,
    require_positive,
)
from dtwin.twin.paper_modules import CONTRACTS, DISCRETISATIONS
from dtwin.twin.wiring import MODULES

__all__ = [
    "ActuatorParams",
    "PlantParams",
    "SensorParams",
    "FusionParams",
    "KpiParams",
    "NoiseParams",
    "TwinParams",
    "CommandParams",
    "ALGEBRAIC_SECTIONS",
    "twin_params_from_mapping",
    "command_params_from_mapping",
    "discretisation_from_mapping",
]


@dataclass(frozen=True)
class ActuatorParams:
    """M0 first-order low-pass: time constant ``tau`` (s)."""

    tau: float


@dataclass(frozen=True)
class PlantParams:
    """M1 mass-spring-damper: mass ``m`` (kg), damping ``c`` (N·s/m), stiffness ``k`` (N/m)."""

    m: float
    c: float
    k: float


@dataclass(frozen=True)
class SensorParams:
    """M2a/M2b first-order sensor: lag ``tau`` (s) and additive ``bias`` (signal units)."""

    tau: float
    bias: float


@dataclass(frozen=True)
class FusionParams:
    """M3 static fusion: weight ``alpha`` on sensor A, in [0, 1]."""

    alpha: float


@dataclass(frozen=True)
class KpiParams:
    """M4 KPI ``z = w1·x + w2·v``."""

    w1: float
    w2: float


@dataclass(frozen=True)
class NoiseParams:
    """Noise standard deviations: actuator process, plant acceleration, sensor A/B measurement."""

    actuator: float
    plant: float
    sensor_A: float
    sensor_B: float


@dataclass(frozen=True)
class TwinParams:
    """Physical parameters of the six-module twin (the ``twin:`` config section).

    Sections other than ``dt`` may be ``None`` when built with ``require_all=False``
    (the gap diagnoser then calibrates that module from data). ``discretisation`` is the
    plant's (module docstring); None when the mapping does not declare one.
    """

    dt: float
    actuator: ActuatorParams | None
    plant: PlantParams | None
    sensor_A: SensorParams | None
    sensor_B: SensorParams | None
    fusion: FusionParams | None
    kpi: KpiParams | None
    noise: NoiseParams | None
    discretisation: str | None = None


@dataclass(frozen=True)
class CommandParams:
    """Command generator of paper §3.1 (see :func:`dtwin.command.make_command`).

    ``u = amp·(sine_amp·sin(2π·sine_freq_hz·t) + square_amp·sign(sin(2π·square_freq_hz·t))
    + Σ steps)``, with a N(0, step_std²) step added every ``step_every_s`` seconds from t = 0.
    """

    amp: float
    sine_amp: float
    sine_freq_hz: float
    square_amp: float
    square_freq_hz: float
    step_every_s: float
    step_std: float


def _section_fields() -> dict[str, tuple[type, tuple[str, ...]]]:
    """Each section of :class:`TwinParams`: its dataclass and its keys, in module order.

    Derived from the module contract (:data:`dtwin.twin.paper_modules.CONTRACTS`: a module's section
    and linear parameters, the noise channels) and the field types of :class:`TwinParams`, so the
    modules are listed once (``tests/concepts/test_params.py`` checks each dataclass has those
    fields).
    """
    hints = get_type_hints(TwinParams)
    keys = {contract.section: contract.params for contract in CONTRACTS.values()}
    keys["noise"] = tuple(contract.noise for contract in CONTRACTS.values() if contract.noise)
    return {
        section: (next(t for t in get_args(hints[section]) if t is not type(None)), fields)
        for section, fields in keys.items()
    }


_SECTION_FIELDS = _section_fields()

#: The sections of the modules the twin recomputes from upstream signals (M3, M4: ``fusion``,
#: ``kpi``): what fault injection and the bias correction read of ``twin`` besides ``dt``.
ALGEBRAIC_SECTIONS: tuple[str, ...] = tuple(
    module.section for module in MODULES if module.surrogate == "algebraic"
)

_POSITIVE = {"tau", "m"}
_NONNEGATIVE = {"c", "k"}


def _field_value(section: str, field: str, raw: Any, prefix: str) -> float:
    name = f"{prefix}.{section}.{field}"
    if section == "noise":
        return require_nonnegative(name, raw)
    if section == "fusion":
        return require_in_range(name, raw, 0.0, 1.0)
    if field in _POSITIVE:
        return require_positive(name, raw)
    if field in _NONNEGATIVE:
        return require_nonnegative(name, raw)
    return require_number(name, raw)


def _build_section(section: str, raw: Any, prefix: str) -> Any:
    cls, fields = _SECTION_FIELDS[section]
    mapping = require_mapping(f"{prefix}.{section}", raw)
    missing = [field for field in fields if field not in mapping]
    if missing:
        raise DtwinValueError(f"{prefix}.{section} is missing key(s): {', '.join(missing)}")
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise DtwinValueError(f"{prefix}.{section} has unknown key(s): {', '.join(unknown)}")
    return cls(**{field: _field_value(section, field, mapping[field], prefix) for field in fields})


def twin_params_from_mapping(
    mapping: Mapping[str, Any] | TwinParams,
    *,
    require_all: bool = True,
    prefix: str = "twin",
    required: Sequence[str] = (),
) -> TwinParams:
    """Return validated :class:`TwinParams` from a ``twin:``-shaped mapping.

    Parameters
    ----------
    mapping : Mapping or TwinParams
        The ``twin`` section (``dt`` plus the module sections of the module docstring); a
        :class:`TwinParams` is returned as it is (once ``required`` is checked), so a stage
        parses its section once and passes the object on.
    require_all : bool, default True
        If False, missing module sections become ``None`` instead of an error.
    prefix : str, default "twin"
        Name used in error messages (``twin.fusion.alpha must be in [0, 1] (got 1.3)``).
    required : sequence of str, default ()
        Sections that must be present even when ``require_all`` is False (a stage's own,
        e.g. ``("fusion", "kpi")``).

    Raises
    ------
    DtwinValueError, DtwinTypeError
        On a missing or unknown key, a wrong type or a value out of range.

    Examples
    --------
    >>> p = twin_params_from_mapping({"dt": 0.02, "fusion": {"alpha": 0.6}}, require_all=False)
    >>> p.fusion.alpha, p.plant
    (0.6, None)
    """
    if isinstance(mapping, TwinParams):
        _require_sections(mapping, required, prefix)
        return mapping
    mapping = require_mapping(prefix, mapping)
    if "dt" not in mapping:
        raise DtwinValueError(f"{prefix} is missing key: dt")
    unknown = sorted(set(mapping) - set(_SECTION_FIELDS) - {"dt", "discretisation"})
    if unknown:
        raise DtwinValueError(f"{prefix} has unknown key(s): {', '.join(unknown)}")
    sections: dict[str, Any] = {}
    for section in _SECTION_FIELDS:
        if section in mapping and mapping[section] is not None:
            sections[section] = _build_section(section, mapping[section], prefix)
        elif require_all or section in required:
            raise DtwinValueError(f"{prefix} is missing key: {section}")
        else:
            sections[section] = None
    return TwinParams(
        dt=require_positive(f"{prefix}.dt", mapping["dt"]),
        **sections,
        discretisation=discretisation_from_mapping(mapping, prefix=prefix),
    )


def _require_sections(twin: TwinParams, sections: Sequence[str], prefix: str) -> None:
    for section in sections:
        if getattr(twin, section) is None:
            raise DtwinValueError(f"{prefix} is missing key: {section}")


def discretisation_from_mapping(mapping: Mapping[str, Any], *, prefix: str = "twin") -> str | None:
    """Return the ``discretisation`` of a ``twin:``-shaped mapping, or None when absent.

    Raises
    ------
    DtwinValueError, DtwinTypeError
        If it is not one of :data:`dtwin.twin.paper_modules.DISCRETISATIONS`.

    Examples
    --------
    >>> discretisation_from_mapping({"dt": 0.02, "discretisation": "euler"})
    'euler'
    """
    value = mapping.get("discretisation")
    if value is None:
        return None
    if not isinstance(value, str):
        raise DtwinTypeError(
            f"{prefix}.discretisation must be a string (got {type(value).__name__})"
        )
    if value not in DISCRETISATIONS:
        raise DtwinValueError(
            f"{prefix}.discretisation must be one of {', '.join(DISCRETISATIONS)} (got {value!r})"
        )
    return value


def command_params_from_mapping(
    mapping: Mapping[str, Any], *, prefix: str = "command"
) -> CommandParams:
    """Return validated :class:`CommandParams` from the ``command:`` config section."""
    mapping = require_mapping(prefix, mapping)
    fields = CommandParams.__dataclass_fields__
    missing = [field for field in fields if field not in mapping]
    if missing:
        raise DtwinValueError(f"{prefix} is missing key(s): {', '.join(missing)}")
    values = {field: require_number(f"{prefix}.{field}", mapping[field]) for field in fields}
    require_positive(f"{prefix}.step_every_s", values["step_every_s"])
    require_nonnegative(f"{prefix}.step_std", values["step_std"])
    return CommandParams(**values)
