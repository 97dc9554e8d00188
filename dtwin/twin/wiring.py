"""The wiring table of the six-module twin (paper §3, Fig. 1).

One table says which signals each module reads and writes, and names its parameter section; it
is the one table of the modules, which the module contract
(:data:`dtwin.twin.paper_modules.CONTRACTS`) and the twin's parameters
(:class:`dtwin.params.TwinParams`) extend. The simulator, the surrogate chain, the residual
definitions and ``fig01_pipeline`` all read it, so the picture and the loops cannot drift from
each other.

Signals keep the paper's names: ``u_cmd`` (command), ``u_act`` (realised actuation),
``x`` (position), ``v`` (velocity), ``y_A``/``y_B`` (sensor readings), ``y_fused``
(fused measurement) and ``z`` (KPI). Residual ``e<id>`` belongs to module ``M<id>``.

Each module has a **role** (:data:`ROLES`: actuator, plant, sensor, fusion, KPI). Code that
treats modules differently asks for the role (:func:`role_of`, :func:`only_module`), never for a
module's name, so the table is the one place that says which module is the plant.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ACTUATOR",
    "PLANT",
    "SENSOR",
    "FUSION",
    "KPI",
    "ROLES",
    "Module",
    "MODULES",
    "SIGNALS",
    "RESIDUALS",
    "module_by_name",
    "role_of",
    "modules_with_role",
    "only_module",
]

#: Role of the first-order lag that turns the command into the realised actuation.
ACTUATOR = "actuator"
#: Role of the mass-spring-damper (position and velocity from the actuation force).
PLANT = "plant"
#: Role of a position sensor (a first-order lag with a bias).
SENSOR = "sensor"
#: Role of the fusion of the two sensor readings.
FUSION = "fusion"
#: Role of the key performance indicator computed from position and velocity.
KPI = "kpi"
#: Every role, in data-flow order.
ROLES: tuple[str, ...] = (ACTUATOR, PLANT, SENSOR, FUSION, KPI)


@dataclass(frozen=True)
class Module:
    """One module of the pipeline.

    Attributes
    ----------
    name : str
        Paper label, ``"M0"`` … ``"M4"``.
    title : str
        Human-readable role (``"Actuator LPF"``).
    inputs : tuple of str
        Signals the module reads.
    outputs : tuple of str
        Signals the module writes; the first is the module's output proper (the one its
        residual compares), the plant also writes the velocity ``v``.
    residual : str
        Name of its residual channel, surrogate − physics (paper Eq. (1)).
    section : str
        Name of its parameter section in :class:`dtwin.params.TwinParams` (``"plant"``); its
        parameters and law are the module's contract (:data:`dtwin.twin.paper_modules.CONTRACTS`).
    surrogate : str
        ``"arx"`` when the twin replaces it with an ARX model, ``"algebraic"`` when the
        twin recomputes it from upstream surrogate signals.
    role : str
        What the module does, one of :data:`ROLES` (both sensors are ``"sensor"``).
    """

    name: str
    title: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    residual: str
    section: str
    surrogate: str
    role: str

    @property
    def output(self) -> str:
        """The module's output proper (first of :attr:`outputs`)."""
        return self.outputs[0]


MODULES: tuple[Module, ...] = (
    Module("M0", "Actuator LPF", ("u_cmd",), ("u_act",), "e0", "actuator", "arx", ACTUATOR),
    Module("M1", "Plant (mass-spring-damper)", ("u_act",), ("x", "v"), "e1", "plant", "arx", PLANT),
    Module("M2a", "Sensor A", ("x",), ("y_A",), "e2a", "sensor_A", "arx", SENSOR),
    Module("M2b", "Sensor B", ("x",), ("y_B",), "e2b", "sensor_B", "arx", SENSOR),
    Module("M3", "Fusion", ("y_A", "y_B"), ("y_fused",), "e3", "fusion", "algebraic", FUSION),
    Module("M4", "KPI", ("x", "v"), ("z",), "e4", "kpi", "algebraic", KPI),
)

#: Every signal of the pipeline, in data-flow order (the columns of the physics table).
SIGNALS: tuple[str, ...] = ("u_cmd", "u_act", "x", "v", "y_A", "y_B", "y_fused", "z")

#: Residual channel names in module order.
RESIDUALS: tuple[str, ...] = tuple(module.residual for module in MODULES)


def module_by_name(name: str) -> Module:
    """Return the :class:`Module` called ``name`` (``"M0"`` … ``"M4"``)."""
    for module in MODULES:
        if module.name == name:
            return module
    known = ", ".join(module.name for module in MODULES)
    raise KeyError(f"unknown module {name!r}; known modules: {known}")


_ROLE_OF: dict[str, str] = {module.name: module.role for module in MODULES}


def role_of(name: str) -> str:
    """Return the role (one of :data:`ROLES`) of the module called ``name``.

    Examples
    --------
    >>> role_of("M2b")
    'sensor'
    """
    role = _ROLE_OF.get(name)
    if role is None:
        return module_by_name(name).role  # raises the KeyError naming the known modules
    return role


def modules_with_role(role: str) -> tuple[str, ...]:
    """Return the names of the modules with role ``role``, in the wiring's order.

    Examples
    --------
    >>> modules_with_role(SENSOR)
    ('M2a', 'M2b')
    """
    if role not in ROLES:
        raise KeyError(f"unknown role {role!r}; known roles: {', '.join(ROLES)}")
    return tuple(module.name for module in MODULES if module.role == role)


def only_module(role: str) -> str:
    """Return the name of the one module with role ``role`` (every role but ``sensor``).

    Raises
    ------
    KeyError
        If ``role`` is unknown or several modules have it.

    Examples
    --------
    >>> only_module(PLANT)
    'M1'
    """
    names = modules_with_role(role)
    if len(names) != 1:
        raise KeyError(f"{len(names)} modules have role {role!r}: {', '.join(names)}")
    return names[0]
