"""An FMU (FMI 2.0, Model Exchange or Co-Simulation) as one module of a twin table.

Specification: docs/gap.md §An FMU as a module. A module of a twin table may be a Functional
Mock-up Unit exported from Modelica, Simulink, Dymola, OpenModelica or AMESim::

    modules:
      plant:
        fmu: models/plant.fmu          # relative to the twin file
        inputs: {u_act: F}             # recording signal -> FMU input variable
        outputs: {x: s}                # recording signal -> FMU output variable
        params: {m: 1.2, d: 0.4}       # FMU parameters the diagnoser may re-fit (start values)
        interface: co_simulation       # optional; Model Exchange when the FMU has it

:func:`read_fmu` reads and checks the FMU (:class:`FmuError`, one line, on a file that is not
a zip, has no ``modelDescription.xml``, is not FMI 2.0, lacks the interface or the binary for
this platform, names an input, output or param the FMU does not have as such, or fails to
initialise: its log's last line quoted) and returns an :class:`FmuInfo`.
:func:`model_for` builds a unit's model: a :class:`FmuModelExchange` or a :class:`FmuModel`
(Co-Simulation) with the interface of :class:`dtwin.twin.simulate.UnitModel` (``spec``,
``param_names``, ``simulate``; ``derivatives`` for Model Exchange).

**Params.** A listed param must have causality ``parameter`` (variability ``fixed`` or
``tunable``: a start value the importer sets before initialisation, which is when dtwin sets
it); a ``calculatedParameter``, a constant, an input, an output or a local is refused.

**Simulation.** The FMU is instantiated once per process and file (:func:`_instance`: the zip
extracted to a temporary folder, the binary loaded, removed at exit) and re-initialised at each
run with the run's params. *Model Exchange*: dtwin integrates the FMU's derivatives with the
classical Runge-Kutta method, ``substeps`` steps per sample (as an expression module, chosen
from the Jacobian of the FMU's derivatives), inputs held or linear between samples as the
twin's discretisation says; every window restarts from its fitted continuous states
(``fmi2SetContinuousStates``); events (``fmi2CompletedIntegratorStep``, a sign change of an
event indicator) are handled at the sample where they are seen. *Co-Simulation*: the FMU's own
solver steps over each sample (``fmi2DoStep``, communication step = the recording's ``dt``),
a linear input by its slope when the FMU can interpolate inputs (``fmi2SetRealInputDerivatives``)
and held otherwise; windows restart from fitted states when every continuous state has a start
value the importer may set (the FMU is reset and initialised per window), otherwise the FMU
runs once from its own start values up to each window's end and :attr:`FmuModel.restart` says
so (``fmi2SetFMUstate`` restores only the FMU's own snapshots, never a state fitted to a
recording, so it cannot restart a window).
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import shutil
import tempfile
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.twin._fmu_kernels import cs_window, me_windows
from dtwin.twin.simulate import UnitModel, UnitSpec

__all__ = [
    "FMU_INTERFACES",
    "FmuError",
    "FmuInfo",
    "FmuModel",
    "FmuModelExchange",
    "model_for",
    "read_fmu",
]

#: The ``interface`` values of an FMU module and the modelDescription element of each.
FMU_INTERFACES = {"model_exchange": "modelExchange", "co_simulation": "coSimulation"}
#: How a window restarts, by mode (the report's words).
RESTARTS = {
    "states": "each window restarts from fitted continuous states (fmi2SetContinuousStates)",
    "start values": "each window restarts from fitted states set as start values (the FMU "
    "reset and initialised per window)",
    "none": "the states cannot be set: one run from the FMU's own start values up to each "
    "part's end, one window per part",
}


class FmuError(DtwinValueError):
    """An FMU module that cannot be used: ``rule`` for ``key`` (``fmu``, ``inputs.x``, ...)."""

    def __init__(self, rule: str, *, key: str = "fmu", token: str = ""):
        super().__init__(f"{key}: {rule}")
        self.rule, self.key, self.token = rule, key, token


@dataclass(frozen=True)
class FmuInfo:
    """What dtwin needs of an FMU module (:func:`read_fmu`).

    Attributes
    ----------
    path : str
        Absolute path of the ``.fmu``.
    interface : str
        ``"model_exchange"`` or ``"co_simulation"``.
    model_identifier, guid : str
    inputs, outputs : dict of str to str
        Recording signal → FMU variable.
    refs : dict of str to int
        FMU variable → value reference (inputs, outputs, params, states).
    params : dict of str to float
        Listed FMU parameters and their declared values.
    states : tuple of str
        The FMU's continuous states (variables whose derivatives it declares) that windows
        restart from; empty when they cannot be set (``restart == "none"``).
    output_states : dict of str to str
        Recording signal → the state its output variable is (the same value reference).
    restart : str
        ``"states"``, ``"start values"`` or ``"none"`` (:data:`RESTARTS`).
    interpolates_inputs : bool
        Co-Simulation: the FMU takes input slopes over a step.
    n_event_indicators : int
    needs_step_calls : bool
        Model Exchange: ``fmi2CompletedIntegratorStep`` must be called after each step.
    """

    path: str
    interface: str
    model_identifier: str
    guid: str
    inputs: dict[str, str]
    outputs: dict[str, str]
    refs: dict[str, int]
    params: dict[str, float]
    states: tuple[str, ...]
    output_states: dict[str, str]
    restart: str
    interpolates_inputs: bool = True
    n_event_indicators: int = 0
    needs_step_calls: bool = False

    @property
    def name(self) -> str:
        """The file's name (for messages)."""
        return Path(self.path).name


def _description(path: Path, shown: str):
    """Return fmpy's model description of ``path``, every failure as one :class:`FmuError`."""
    if not path.is_file():
        raise FmuError(f"no such file '{shown}'", token=shown)
    if not zipfile.is_zipfile(path):
        raise FmuError(f"'{shown}' is not an FMU (not a zip archive)", token=shown)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    if "modelDescription.xml" not in names:
        raise FmuError(f"'{shown}' has no modelDescription.xml", token=shown)
    from fmpy import read_model_description

    try:
        description = read_model_description(str(path))
    except Exception as error:  # fmpy raises plain exceptions for a bad XML or schema
        first = (str(error).strip().splitlines() or ["invalid"])[0]
        raise FmuError(f"'{shown}': modelDescription.xml: {first}", token=shown) from None
    if description.fmiVersion != "2.0":
        raise FmuError(
            f"'{shown}' is FMI {description.fmiVersion}; an FMU module must be FMI 2.0",
            token=description.fmiVersion,
        )
    return description, names


def _interface(description, requested: str | None, shown: str) -> tuple[str, object]:
    """Return the interface used and its modelDescription element."""
    present = [i for i, attr in FMU_INTERFACES.items() if getattr(description, attr)]
    if requested is None:
        requested = present[0] if present else "model_exchange"
    if requested not in FMU_INTERFACES:
        raise FmuError(f"must be {' or '.join(FMU_INTERFACES)} (got {requested!r})",
                       key="interface", token=str(requested))  # fmt: skip
    if requested not in present:
        raise FmuError(f"'{shown}' has no {requested} interface (it has: "
                       f"{', '.join(present) or 'none'})", key="interface",
                       token=requested)  # fmt: skip
    return requested, getattr(description, FMU_INTERFACES[requested])


def _check_binary(names: Sequence[str], identifier: str, shown: str) -> None:
    from fmpy import platform, sharedLibraryExtension

    wanted = f"binaries/{platform}/{identifier}{sharedLibraryExtension}"
    if wanted not in names:
        found = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and
                        n.count("/") >= 2 and n.split("/")[1]})  # fmt: skip
        raise FmuError(
            f"'{shown}' has no binary for this platform ({wanted}; it has: "
            f"{', '.join(found) or 'no binaries'})", token=platform,
        )  # fmt: skip


def _variable(by_name, name, key, causalities, what, *, kinds=("Real",)):
    """Return the FMU variable ``name`` if its causality is one of ``causalities``."""
    variable = by_name.get(name)
    if variable is None or variable.causality not in causalities or variable.type not in kinds:
        listed = [v.name for v in by_name.values() if v.causality in causalities]
        shown = ", ".join(listed[:12]) + (", ..." if len(listed) > 12 else "")
        actual = (f" (it is {variable.causality}, variability {variable.variability})"
                  if variable is not None else "")  # fmt: skip
        raise FmuError(f"'{name}' is not {what} of the FMU{actual}; {what.split()[-1]}s: "
                       f"{shown or 'none'}", key=key, token=str(name))  # fmt: skip
    return variable


def _states(description, interface: str) -> tuple[tuple[str, ...], str, dict[str, int]]:
    """Return the settable continuous states, the restart mode and their value references."""
    states = [d.variable.derivative for d in description.derivatives]
    if any(s is None for s in states):
        return (), "none", {}
    refs = {s.name: s.valueReference for s in states}
    if interface == "model_exchange":
        return tuple(refs), "states", refs
    settable = all(s.initial in ("exact", "approx") and s.causality in ("local", "output")
                   for s in states)  # fmt: skip
    return (tuple(refs), "start values", refs) if settable and states else ((), "none", {})


def read_fmu(
    path: str | Path,
    *,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    params: Mapping[str, float],
    interface: str | None = None,
    shown: str | None = None,
) -> FmuInfo:
    """Read and check an FMU module's file; return its :class:`FmuInfo`.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.
    inputs, outputs : mapping of str to str
        Recording signal → FMU input (causality ``input``) or output (``output``) variable.
    params : mapping of str to float
        FMU parameters (causality ``parameter``) and their declared values.
    interface : {"model_exchange", "co_simulation"}, optional
        Default: Model Exchange when the FMU has it.
    shown : str, optional
        The path as the twin file wrote it (for messages).

    Raises
    ------
    FmuError
        One line (module docstring); the FMU is also initialised once with the declared params
        and a failure quotes the last line of its log.
    """
    path = Path(path).resolve()
    shown = shown or str(path)
    description, names = _description(path, shown)
    interface, element = _interface(description, interface, shown)
    _check_binary(names, element.modelIdentifier, shown)
    by_name = {v.name: v for v in description.modelVariables}
    refs = {}
    for key, mapping, causalities, what in (
        ("inputs", inputs, ("input",), "an input"),
        ("outputs", outputs, ("output",), "an output"),
    ):
        for signal, name in mapping.items():
            refs[name] = _variable(by_name, name, f"{key}.{signal}", causalities,
                                   what).valueReference  # fmt: skip
    for name in params:
        refs[name] = _variable(by_name, name, f"params.{name}", ("parameter",),
                               "a tunable parameter").valueReference  # fmt: skip
    states, restart, state_refs = _states(description, interface)
    refs.update(state_refs)
    by_ref = {ref: name for name, ref in state_refs.items()}
    info = FmuInfo(
        path=str(path), interface=interface, model_identifier=element.modelIdentifier,
        guid=description.guid, inputs=dict(inputs), outputs=dict(outputs), refs=refs,
        params={k: float(v) for k, v in params.items()}, states=states,
        output_states={s: by_ref[refs[v]] for s, v in outputs.items() if refs[v] in by_ref},
        restart=restart,
        interpolates_inputs=bool(getattr(element, "canInterpolateInputs", True)),
        n_event_indicators=int(description.numberOfEventIndicators or 0),
        needs_step_calls=not bool(getattr(element, "completedIntegratorStepNotNeeded", False)),
    )  # fmt: skip
    _instance(info).start(info, np.array(list(info.params.values())), 0.0)
    return info


_ME_FUNCTIONS = (
    ("fmi2SetTime", (ctypes.c_void_p, ctypes.c_double)),
    ("fmi2SetReal", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)),
    ("fmi2SetContinuousStates", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)),
    ("fmi2GetDerivatives", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)),
    ("fmi2GetReal", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)),
    ("fmi2CompletedIntegratorStep",
     (ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)),
    ("fmi2GetEventIndicators", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)),
    ("fmi2EnterEventMode", (ctypes.c_void_p,)),
    ("fmi2NewDiscreteStates", (ctypes.c_void_p, ctypes.c_void_p)),
    ("fmi2EnterContinuousTimeMode", (ctypes.c_void_p,)),
    ("fmi2GetContinuousStates", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)),
)  # fmt: skip
_CS_FUNCTIONS = (
    ("fmi2SetReal", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)),
    ("fmi2GetReal", (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)),
    ("fmi2DoStep", (ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)),
    ("fmi2SetRealInputDerivatives",
     (ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p)),
)  # fmt: skip


def _owned(array, width: int | None = None) -> np.ndarray:
    """Return ``array`` as a writable C-ordered float64 array, shape ``(len(array), width)``.

    The numba loops are compiled (and cached by ``make venv``) for writable arrays; a read-only
    one (a pandas frame's ``to_numpy()`` under copy-on-write) would compile them again, for
    about a minute. Copies only when needed.
    """
    out = np.require(array, dtype=np.float64, requirements=("C", "W"))
    return out.reshape(len(out), -1 if width is None else width)


def _pointers(dll, table) -> tuple:
    """Return the FMI functions as ctypes function pointers with plain C argument types."""
    out = []
    for name, argtypes in table:
        address = ctypes.cast(getattr(dll, name), ctypes.c_void_p).value
        out.append(ctypes.CFUNCTYPE(ctypes.c_int, *argtypes)(address))
    return tuple(out)


@dataclass
class _Instance:
    """One instantiated FMU of this process (:func:`_instance`)."""

    info: FmuInfo
    fmu: object
    folder: str
    callbacks: object
    fns: tuple
    log: list[str] = field(default_factory=list)
    initialised: bool = False
    current: tuple | None = None

    @property
    def component(self) -> int:
        """The ``fmi2Component`` address."""
        return int(self.fmu.component)

    def start(self, info: FmuInfo, params, t0: float, states: Sequence[float] | None = None):
        """Reset, set ``params`` (and state start values), initialise at ``t0``.

        ``info`` is the module's (two modules may share one file with different params).
        Raises :class:`FmuError` quoting the log's last line when the FMU refuses.
        """
        fmu = self.fmu
        try:
            if self.initialised:
                fmu.reset()
            self.initialised, self.current = True, None
            fmu.setupExperiment(startTime=float(t0))
            names = list(info.params)
            if names:
                fmu.setReal([info.refs[n] for n in names], [float(v) for v in params])
            if states is not None and info.states:
                fmu.setReal([info.refs[s] for s in info.states], [float(v) for v in states])
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            if info.interface == "model_exchange":
                while fmu.newDiscreteStates()[0]:
                    pass
                fmu.enterContinuousTimeMode()
        except Exception as error:
            last = self.log[-1] if self.log else str(error)
            raise FmuError(f"'{info.name}' failed to initialise: {last}", token=info.name) from None
        self.current = (tuple(info.params), tuple(float(v) for v in params), float(t0))


_INSTANCES: dict[tuple, _Instance] = {}


def _logger(log: list[str]):
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    def record(_env, _name, status, _category, message) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        log.append(text.strip().splitlines()[-1] if text.strip() else f"status {status}")
        del log[:-50]

    return fmi2CallbackLoggerTYPE(record)


def _instance(info: FmuInfo) -> _Instance:
    """Return the process's instance of ``info``'s FMU (instantiated on first use)."""
    stat = Path(info.path).stat()
    key = (info.path, stat.st_mtime_ns, stat.st_size, info.interface)
    if key in _INSTANCES:
        return _INSTANCES[key]
    from fmpy import extract
    from fmpy.fmi2 import FMU2Model, FMU2Slave, calloc, fmi2CallbackFunctions, free
    from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE as Allocate
    from fmpy.fmi2 import fmi2CallbackFreeMemoryTYPE as Free
    from fmpy.logging import addLoggerProxy

    folder = tempfile.mkdtemp(prefix="dtwin-fmu-")
    log: list[str] = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _logger(log)
    callbacks.allocateMemory = Allocate(calloc)
    callbacks.freeMemory = Free(free)
    addLoggerProxy(ctypes.byref(callbacks))
    kind = FMU2Model if info.interface == "model_exchange" else FMU2Slave
    try:
        extract(info.path, unzipdir=folder)
        fmu = kind(guid=info.guid, modelIdentifier=info.model_identifier, unzipDirectory=folder,
                   instanceName="dtwin")  # fmt: skip
        fmu.instantiate(callbacks=callbacks, loggingOn=True)
    except Exception as error:
        shutil.rmtree(folder, ignore_errors=True)
        last = log[-1] if log else (str(error).strip().splitlines() or ["unknown error"])[0]
        raise FmuError(f"'{info.name}' could not be loaded: {last}", token=info.name) from None
    table = _ME_FUNCTIONS if info.interface == "model_exchange" else _CS_FUNCTIONS
    instance = _Instance(info, fmu, folder, callbacks, _pointers(fmu.dll, table), log)
    _INSTANCES[key] = instance
    return instance


@atexit.register
def _release() -> None:
    """Free every instance and remove its extracted folder."""
    while _INSTANCES:
        _key, instance = _INSTANCES.popitem()
        with contextlib.suppress(Exception):  # leaving the process anyway
            instance.fmu.freeInstance()
        shutil.rmtree(instance.folder, ignore_errors=True)


@dataclass(frozen=True)
class FmuModel:
    """A unit whose only module is a Co-Simulation FMU.

    :class:`~dtwin.twin.simulate.UnitModel`'s interface without ``derivatives`` (the FMU's
    internals are closed).

    ``param_names`` are the unit's qualified params (``plant.k``): the FMU's listed params.
    """

    spec: UnitSpec
    info: FmuInfo
    module: str
    param_names: tuple[str, ...] = ()
    assignments: tuple = ()
    #: The FMU's internals are closed: no state effects are offered.
    closed: bool = True

    @classmethod
    def from_spec(cls, spec: UnitSpec, info: FmuInfo, module: str) -> FmuModel:
        """Return the model of ``spec``, a unit of one FMU module called ``module``."""
        return cls(spec, info, module, tuple(spec.params))

    @property
    def restart(self) -> str:
        """How windows restart: ``states``, ``start values`` or ``none`` (:data:`RESTARTS`)."""
        return self.info.restart

    @property
    def restarts(self) -> bool:
        """Whether a window can start from fitted states."""
        return self.info.restart != "none"

    @property
    def notes(self) -> tuple[str, ...]:
        """What the report says about this unit's FMU."""
        kind = "Model Exchange" if self.info.interface == "model_exchange" else "Co-Simulation"
        held = ""
        if self.info.interface == "co_simulation" and not self.info.interpolates_inputs:
            held = "; its inputs are held over each step (it cannot interpolate inputs)"
        return (
            f"module '{self.module}' is an FMU ({self.info.name}, {kind}): "
            f"{RESTARTS[self.info.restart]}{held}",
            f"module '{self.module}': FMU internals are closed: no state effects",
        )

    def _refs(self, names: Sequence[str]) -> np.ndarray:
        return np.array([self.info.refs[n] for n in names], dtype=np.uint32)

    def simulate(self, inputs, theta, starts, stops, x0, dt, *, substeps=1, linear=None,
                 limits=None, t0=0.0):  # fmt: skip
        """Simulate over windows; return ``(outputs, states)`` as :meth:`UnitModel.simulate`.

        Shapes ``(n_samples, n_outputs)`` and ``(n_samples, n_states)``, NaN outside the
        windows and where the FMU failed. ``substeps`` and ``limits`` are unused (the FMU
        steps itself, its states are closed).
        """
        u = _owned(inputs)
        linear = np.ones(u.shape[1], dtype=np.bool_) if linear is None else np.asarray(linear)
        params = np.asarray(theta[: len(self.param_names)], dtype=float)
        x0 = np.asarray(x0, dtype=float).reshape(len(starts), -1)
        n, n_out = len(u), len(self.spec.outputs)
        y = np.full((n, n_out), np.nan)
        states = np.full((n, len(self.spec.states)), np.nan)
        instance = _instance(self.info)
        in_vr = self._refs(self.info.inputs[s] for s in self.spec.inputs)
        out_vr = self._refs(self.info.outputs[s] for s in self.spec.outputs)
        state_vr = self._refs(self.info.states)
        for w, (a, b) in enumerate(zip(starts, stops, strict=True)):
            first = int(a) if self.restarts else 0
            try:
                instance.start(self.info, params, t0 + first * dt,
                               x0[w] if self.restarts else None)  # fmt: skip
            except FmuError:
                continue
            cs_window(
                instance.fns, instance.component, u, linear, self.info.interpolates_inputs,
                in_vr, out_vr, state_vr, first, int(a), int(b), float(dt), float(t0), y, states,
            )  # fmt: skip
        return y, states


@dataclass(frozen=True)
class FmuModelExchange(FmuModel):
    """A unit whose only module is a Model Exchange FMU, integrated by dtwin.

    RK4 over the FMU's derivatives, windows restarted by ``fmi2SetContinuousStates``;
    :meth:`derivatives` for Jacobians.
    """

    def simulate(self, inputs, theta, starts, stops, x0, dt, *, substeps=1, linear=None,
                 limits=None, t0=0.0):  # fmt: skip
        """Integrate over windows; return ``(outputs, states)`` as :meth:`UnitModel.simulate`.

        ``limits`` (lo, hi) clamp the states after each step, as for an expression module.
        """
        u = _owned(inputs)
        linear = np.ones(u.shape[1], dtype=np.bool_) if linear is None else np.asarray(linear)
        n_states = len(self.spec.states)
        x0 = _owned(np.reshape(x0, (len(starts), n_states)), n_states)
        if limits is None:
            limits = (np.full(n_states, -np.inf), np.full(n_states, np.inf))
        instance = _instance(self.info)
        params = np.asarray(theta[: len(self.param_names)], dtype=float)
        starts = np.asarray(starts, dtype=np.int64)
        try:
            instance.start(self.info, params, t0 + (int(starts[0]) if len(starts) else 0) * dt)
        except FmuError:
            nan = np.full((len(u), len(self.spec.outputs)), np.nan)
            return nan, np.full((len(u), n_states), np.nan)
        y, states, _status = me_windows(
            instance.fns, instance.component, u, linear.astype(np.bool_),
            self._refs(self.info.inputs[s] for s in self.spec.inputs),
            self._refs(self.info.outputs[s] for s in self.spec.outputs),
            np.asarray(limits[0], dtype=float), np.asarray(limits[1], dtype=float), starts,
            np.asarray(stops, dtype=np.int64), x0, float(dt), float(t0), int(substeps),
            self.info.needs_step_calls or self.info.n_event_indicators > 0,
            self.info.n_event_indicators,
        )  # fmt: skip
        return y, states

    def derivatives(self, state: np.ndarray, inputs: np.ndarray, theta, t: float = 0.0):
        """Return the FMU's state derivatives at one point, shape ``(n_states,)``."""
        instance = _instance(self.info)
        params = np.asarray(theta[: len(self.param_names)], dtype=float)
        if instance.current is None or instance.current[:2] != (tuple(self.info.params),
                                                                tuple(params)):  # fmt: skip
            instance.start(self.info, params, t)
        set_time, set_real, set_states, get_derivatives = instance.fns[:4]
        comp = instance.component
        u = np.ascontiguousarray(inputs, dtype=float).ravel()
        x = np.ascontiguousarray(state, dtype=float).ravel()
        out = np.empty(len(x))
        in_vr = self._refs(self.info.inputs[s] for s in self.spec.inputs)
        set_time(comp, float(t))
        if len(u):
            set_real(comp, in_vr.ctypes.data, len(u), u.ctypes.data)
        set_states(comp, x.ctypes.data, len(x))
        status = get_derivatives(comp, out.ctypes.data, len(x))
        return out if status <= 1 else np.full(len(x), np.nan)


def model_for(spec: UnitSpec, table) -> UnitModel | FmuModel:
    """Return the model of a unit: an FMU's when its module is an FMU, else a compiled program.

    Parameters
    ----------
    spec : UnitSpec
    table : dtwin.twin.table.TwinTable

    Raises
    ------
    DtwinValueError
        An FMU module joined to other modules by unrecorded signals (an FMU is diagnosed on its
        own: record the signals between it and its neighbours).
    """
    modules = [m for m in table.modules if m.name in spec.modules]
    fmus = [m for m in modules if getattr(m, "fmu", None) is not None]
    if not fmus:
        return UnitModel.from_spec(spec)
    if len(modules) > 1:
        raise DtwinValueError(
            f"twin file: module '{fmus[0].name}': an FMU module is diagnosed on its own, but "
            f"the unrecorded signal(s) {', '.join(spec.internal) or '-'} join it to module(s) "
            f"{', '.join(m.name for m in modules if m is not fmus[0])}: record them"
        )
    info = fmus[0].fmu
    kind = FmuModelExchange if info.interface == "model_exchange" else FmuModel
    return kind.from_spec(spec, info, fmus[0].name)
