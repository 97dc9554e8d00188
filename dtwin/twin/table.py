"""The twin as a table the user writes: modules of built-in blocks or of their own equations.

Specification: docs/gap.md §Twin file. A twin file with a ``modules:`` key is a table::

    dt: 4.0                        # s, optional (the recording's otherwise)
    discretisation: zoh            # optional: zoh | foh (recorded inputs between samples)
    modules:
      pump:                        # a module's name
        block: lag                 # a built-in block (dtwin.twin.blocks) ...
        inputs: [u]                # recording columns or other modules' outputs
        outputs: [q]
        params: {tau: 8.0, gain: 0.05}
      tanks:                       # ... or the module's own equations
        inputs: [q]
        outputs: [level]
        states: [h1, h2]
        initial: {h1: 28.0}        # optional; states not given are fitted per window
        params: {a1: 0.04, a2: 0.03, offset: 0.0}
        derivatives:
          h1: "q - a1*sqrt(max(h1, 0))"
          h2: "a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))"
        equations:                 # algebraic outputs; an output named like a state is that state
          level: "h2 + offset"
    noise: {level: 0.02}           # optional std devs: by output signal or by module name
    process_noise: {tanks.h1: 0.01}  # optional, per sample: by module.state or by module name

A module may also be an FMU (FMI 2.0, :mod:`dtwin.twin.fmu`)::

      plant:
        fmu: models/plant.fmu        # relative to the twin file (``base_dir``)
        inputs: {u_act: F}           # recording signal -> FMU input variable
        outputs: {x: s}              # recording signal -> FMU output variable
        params: {m: 1.2, d: 0.4}     # FMU parameters the diagnoser may re-fit
        interface: co_simulation     # optional: model_exchange (default when present)

:func:`table_from_mapping` turns the file's content into a :class:`TwinTable`. An expression
(:mod:`dtwin.twin.expressions`) may read the module's params, its states, its input signals and
``t`` (s); nothing else, not even the module's own outputs.

**Validation.** Each bad entry is refused with :class:`TwinTableError`, one line naming the
module, the key and the token::

    twin file: module '<module>': <key>: <rule> (got <value>)
    twin file: module 'tanks': derivatives.h1: unknown name 'q2'
    twin file: noise.levl: 'levl' is neither an output signal nor a module (...)

- *Top level*: a key other than ``dt``, ``discretisation``, ``modules``, ``noise`` and
  ``process_noise`` (a
  section of the paper's ``twin:`` shape — ``actuator``, ``plant``, ``sensor_A``,
  ``sensor_B``, ``fusion``, ``kpi`` — gets its own message: one shape or the other; the whole
  table may sit under ``twin:``); ``modules`` missing, not a mapping or empty; ``dt`` not a
  finite number > 0; ``discretisation`` not ``zoh`` or ``foh``.
- *Names*: a module's name, a signal, a state or a param not matching
  ``[A-Za-z][A-Za-z0-9_]*``; a signal, state or param named ``t`` (time), like a function of
  the expressions (``sqrt``, ``max``…) or a Python keyword.
- *A module*: not a mapping; a key other than ``block``, ``inputs``, ``outputs``, ``states``,
  ``initial``, ``params``, ``derivatives``, ``equations``, ``candidates`` (a list of effect names,
  kept as given), ``discretisation`` (one of ``continuous``, ``euler``, ``zoh``; not on a module
  without states, nor on an FMU module); ``inputs``/``outputs``/``states`` not a list of names or
  with a name twice; a signal that is both an input and an output of the module; an unknown
  ``block``; ``block`` with ``states``, ``derivatives`` or ``equations``; ``initial`` for a name
  that is not a state; a param or an initial state that is not a finite number (a YAML ``true`` is
  not a number); ``candidates`` not a list of names.
- *An FMU module* (keys ``fmu``, ``interface``, ``inputs``, ``outputs``, ``params``,
  ``candidates``): ``fmu`` not a text; ``inputs``/``outputs`` not a mapping of signal names to
  FMU variable names (a list means the same names); no outputs; a file that is missing, not a
  zip, without ``modelDescription.xml``, not FMI 2.0, without the interface or a binary for
  this platform; an input, output or param the FMU does not have as such (a param must have
  causality ``parameter``: a calculated parameter, a constant or a local is not tunable); a
  model that fails to initialise with the declared params (its log's last line quoted).
- *A block module*: the block's number of inputs or outputs; an unknown param, a required one
  missing, a rule broken (``tau > 0``, ``m > 0``, ``c, k >= 0``), ``weights`` not one per
  input, matrix shapes of ``state_space`` inconsistent (``A`` n×n, ``B`` n×m, ``C`` p×n, ``D``
  p×m); an input named like one of the block's states or params.
- *An equations module*: no outputs; a name both a param and a state, a param and an input, or
  a state and an input; a derivative missing for a state or given for a non-state; an
  equation for a name that is not an output, or for an output that is a state (an output named
  like a state *is* that state); an output that is neither a state nor given by an equation.
- *Expressions*: anything the parser refuses (unknown name or function, syntax, too long or
  deep; the parser's message prefixed with module and key); a derivative or an equation that
  is **not finite at the start**: it is evaluated with the declared params, the declared
  initial states and ``t = 0``, every other state and every input set to 0, then to 1, then
  to 10 (the same value for all), and refused when it is NaN or infinite at all three (a
  ``log(h)`` with ``h`` undeclared passes at 1; a ``sqrt(a)`` with ``a = -1`` never does).
- *Wiring*: a signal produced by two modules; a name that is both a module and a signal; an
  **algebraic loop**: a cycle of signals in which every step is algebraic (an equation that
  reads an input directly: an equations module's equation, a ``gain`` or ``weighted_sum``
  block, a ``state_space`` block with a non-zero ``D`` entry). A loop through a state (a
  derivative) is fine: the simulator integrates its modules jointly.
- *Noise*: not a mapping; a key that is neither an output signal nor a module; a value not a
  finite number > 0. A module's entry applies to each of its outputs; a signal's own entry
  wins over its module's.
- *Process noise* (a disturbance of the asset's states, not of its recording: each state
  with level ``σ`` gains ``w_k/dt`` in its derivative, held over sample ``k``, ``w_k ~ N(0,
  σ²)`` white; ``σ`` is the std of the disturbance's integral over a sample, in the state's
  units: its increment per sample were the state's own dynamics frozen, ``√(q·dt)`` for a
  white disturbance of intensity ``q``, state units²/s): not a mapping; a key that is neither
  ``<module>.<state>`` nor a module with states; an FMU module (its equations are inside the
  FMU); a value not a finite number >= 0. A module's entry applies to each of its states; a
  state's own entry wins over its module's (0: no noise on that state).
- *Against a recording* (:func:`check_recorded`): an input that is neither a recording column
  nor produced by a module.

**Discretisation** (a module's ``discretisation:``). ``continuous`` (the default): the
module's derivatives are integrated between samples (:mod:`dtwin.twin.simulate`, Runge-Kutta).
``euler`` and ``zoh`` make it a **discrete** module, advanced once per sample from the previous
sample's states ``s`` and inputs ``u`` (a signal another module produces, at that sample): ``euler``
by one explicit Euler step ``s[k] = s[k−1] + dt·f(s[k−1], u[k−1])``; ``zoh`` by the exact step of
its linear dynamics with the inputs held, ``s[k] = s[k−1] + Γ·f(s[k−1], u[k−1])``, ``Γ =
∫₀^dt exp(J·σ) dσ``, ``J`` the Jacobian of the module's derivatives in its states at ``k−1`` (a
``lag``: ``y[k] = a·y[k−1] + (1 − a)·gain·u[k−1]``, ``a = exp(−dt/tau)``; exact when the
derivatives are affine in the module's states, the exponential Euler step otherwise). A unit
(:func:`dtwin.twin.simulate.units_of`) that joins a discrete module with states to a continuous
one through signals the recording lacks is refused when the recording is read (record the
signals, or give the modules discretisations of one kind).

**Order.** :attr:`TwinTable.modules` lists each module after the producers of its inputs,
in declaration order when that allows it; in a loop through states, the earliest declared
module of the loop comes first.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.twin.blocks import BLOCKS, BlockError, Lowered, lower_block
from dtwin.twin.expressions import FUNCTIONS, Expression, ExpressionError, parse_expression

if TYPE_CHECKING:  # dtwin.twin.fmu is imported when a table has an FMU module (numba, fmpy)
    from dtwin.twin.fmu import FmuInfo

__all__ = [
    "NAME_PATTERN",
    "RESERVED_NAMES",
    "START_PROBES",
    "MODULE_STEPS",
    "DISCRETE_STEPS",
    "ModuleSpec",
    "TwinTable",
    "TwinTableError",
    "check_recorded",
    "table_from_mapping",
]

#: A module's, signal's, state's or param's name.
NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
#: Names no signal, state or param may take: time, the expressions' functions, keywords.
RESERVED_NAMES = frozenset({"t", *FUNCTIONS, *keyword.kwlist})
#: Values of the undeclared states and of the inputs at which the start is evaluated.
START_PROBES = (0.0, 1.0, 10.0)

_TOP_KEYS = ("dt", "discretisation", "modules", "noise", "process_noise")
_LEGACY_KEYS = ("actuator", "plant", "sensor_A", "sensor_B", "fusion", "kpi", "twin")
_MODULE_KEYS = ("block", "inputs", "outputs", "states", "initial", "params", "derivatives",
                "equations", "candidates", "discretisation", "fmu", "interface")  # fmt: skip
_FMU_KEYS = ("fmu", "interface", "inputs", "outputs", "params", "candidates")
_EQUATION_KEYS = ("states", "derivatives", "equations")
_DISCRETISATIONS = ("zoh", "foh")
#: A module's ``discretisation``: how its states advance from one sample to the next.
MODULE_STEPS = ("continuous", "euler", "zoh")
#: The steps of a discrete module (once per sample, from the previous sample).
DISCRETE_STEPS = ("euler", "zoh")


class TwinTableError(DtwinValueError):
    """A twin table entry that breaks a rule: one line naming the module, the key and the token.

    Attributes ``module`` (or None at the top level), ``key`` (``derivatives.h1``), ``token``
    (the offending name or value) and ``rule`` (the message without its place).
    """

    def __init__(self, rule: str, *, module: str | None = None, key: str = "", token: str = ""):
        place = [f"module '{module}'"] if module is not None else []
        place += [key] if key else []
        super().__init__(": ".join(["twin file", *place, rule]))
        self.module = module
        self.key = key
        self.token = token
        self.rule = rule


@dataclass(frozen=True)
class ModuleSpec:
    """One module of a twin table, a block lowered to the same parts as an equations module.

    Attributes
    ----------
    name : str
    block : str or None
        The built-in block's name, None for an equations module.
    inputs, outputs : tuple of str
        Signal names.
    states : tuple of str
        The module's state names (a block's own: ``("x", "v")``).
    params : dict of str to float
        Declared values (a block's defaults filled in, vectors and matrices expanded).
    initial : dict of str to float
        Declared initial states.
    derivatives : dict of str to str
        State → derivative text, one per state, in state order.
    equations : dict of str to str
        Output → text, for the outputs that are not states.
    output_states : dict of str to str
        Output → the state it equals.
    linear : bool
        A built-in (linear) block.
    source : str
        ``"block lag"`` or ``"equations"``, for messages.
    candidates : tuple of str or None
        The effect names the file restricts the diagnosis to, as given; None: not given.
    fmu : FmuInfo or None
        An FMU module's file and variables (:mod:`dtwin.twin.fmu`); its ``states`` are the
        FMU's settable continuous states, ``params`` FMU parameters, no texts.
    defaults : frozenset of str
        A block's params the file does not write (``gain`` = 1 and ``bias`` = 0 of a ``lag``):
        structure, not a declared value with a calibration tolerance.
    discretisation : str
        How its states advance between samples (module docstring, Discretisation):
        ``"continuous"`` (the default), ``"euler"`` or ``"zoh"``.
    """

    name: str
    block: str | None
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    states: tuple[str, ...]
    params: dict[str, float]
    initial: dict[str, float]
    derivatives: dict[str, str]
    equations: dict[str, str]
    output_states: dict[str, str]
    linear: bool
    source: str = ""
    candidates: tuple[str, ...] | None = None
    fmu: FmuInfo | None = None
    defaults: frozenset[str] = frozenset()
    discretisation: str = "continuous"

    @property
    def symbols(self) -> frozenset[str]:
        """The names its expressions may read: params, states, inputs and ``t``."""
        return frozenset({*self.params, *self.states, *self.inputs, "t"})


@dataclass(frozen=True)
class TwinTable:
    """A twin as a table of modules (:func:`table_from_mapping`).

    Attributes
    ----------
    modules : tuple of ModuleSpec
        Each after the producers of its inputs (module docstring, Order).
    dt : float or None
        Sample period, s.
    discretisation : str or None
        ``"zoh"``, ``"foh"`` or None (chosen from data).
    noise : dict of str to float
        Measurement noise standard deviation by output signal (signal units): white noise
        added to the recorded values.
    process_noise : dict of str to float
        Process noise standard deviation by qualified state ``<module>.<state>`` (state units,
        per sample; module docstring, Process noise), only states with a level > 0; empty for
        a table without ``process_noise``.
    """

    modules: tuple[ModuleSpec, ...]
    dt: float | None
    discretisation: str | None
    noise: dict[str, float]
    process_noise: dict[str, float] = field(default_factory=dict)

    def producer(self, signal: str) -> ModuleSpec | None:
        """Return the module producing ``signal``, or None (an exogenous signal)."""
        return next((m for m in self.modules if signal in m.outputs), None)

    def module(self, name: str) -> ModuleSpec:
        """Return the module called ``name``; raise :class:`TwinTableError` if there is none."""
        found = next((m for m in self.modules if m.name == name), None)
        if found is None:
            known = ", ".join(m.name for m in self.modules)
            raise TwinTableError(f"no module '{name}' (modules: {known})", token=name)
        return found

    @property
    def signals(self) -> tuple[str, ...]:
        """Every signal a module produces, in table order."""
        return tuple(s for m in self.modules for s in m.outputs)

    @property
    def exogenous(self) -> tuple[str, ...]:
        """Signals read by some module and produced by none (the recording must hold them)."""
        produced = set(self.signals)
        return tuple(dict.fromkeys(s for m in self.modules for s in m.inputs if s not in produced))


def _token(value: Any) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


def _shown(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    return repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."


def _name(value: Any, *, module: str | None, key: str) -> str:
    """Return ``value`` if it is a valid, unreserved name."""
    if not isinstance(value, str):
        raise TwinTableError(
            f"{_shown(value)} is not a name (got {type(value).__name__})", module=module,
            key=key, token=_token(value),
        )  # fmt: skip
    if not NAME_PATTERN.match(value):
        raise TwinTableError(
            f"'{value}' is not a valid name (letters, digits and _, starting with a letter)",
            module=module, key=key, token=value,
        )  # fmt: skip
    if value in RESERVED_NAMES:
        what = "time" if value == "t" else "a function" if value in FUNCTIONS else "a keyword"
        raise TwinTableError(f"'{value}' is reserved ({what})", module=module, key=key,
                             token=value)  # fmt: skip
    return value


def _names(module: str, key: str, raw: Any) -> tuple[str, ...]:
    """Read a module's list of names (``inputs``, ``outputs``, ``states``); absent: empty."""
    if raw is None:
        return ()
    if not isinstance(raw, (list, tuple)):
        raise TwinTableError(
            f"must be a list of names, e.g. [{raw}] (got {type(raw).__name__} {_shown(raw)})",
            module=module, key=key, token=str(raw),
        )  # fmt: skip
    names = tuple(_name(v, module=module, key=key) for v in raw)
    twice = next((n for i, n in enumerate(names) if n in names[:i]), None)
    if twice is not None:
        raise TwinTableError(f"'{twice}' is listed twice", module=module, key=key, token=twice)
    return names


def _number(value: Any, *, module: str | None, key: str, positive: bool = False) -> float:
    """``value`` as a finite float (> 0 with ``positive``); a boolean is not a number."""
    is_number = isinstance(value, (int, float, np.integer, np.floating))
    if isinstance(value, bool) or not is_number:
        raise TwinTableError(f"must be a number (got {_shown(value)})", module=module, key=key,
                             token=_token(value))  # fmt: skip
    number = float(value)
    if not np.isfinite(number) or (positive and number <= 0):
        rule = "a finite number > 0" if positive else "finite"
        raise TwinTableError(f"must be {rule} (got {_shown(value)})", module=module, key=key,
                             token=_token(value))  # fmt: skip
    return number


def _mapping(raw: Any, *, module: str | None, key: str, of: str) -> Mapping:
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise TwinTableError(
            f"must be a mapping of {of} (got {type(raw).__name__} {_shown(raw)})",
            module=module, key=key, token=str(raw)[:40],
        )  # fmt: skip
    return raw


def _texts(module: str, key: str, raw: Any) -> dict[str, str]:
    """Read ``derivatives`` or ``equations``: name → expression text (a number: its text)."""
    out = {}
    for name, text in _mapping(raw, module=module, key=key, of="names to expressions").items():
        name = _name(name, module=module, key=key)
        is_number = isinstance(text, (int, float)) and not isinstance(text, bool)
        if not isinstance(text, str) and not is_number:
            raise TwinTableError(
                f"must be an expression text (got {_shown(text)})", module=module,
                key=f"{key}.{name}", token=_token(text),
            )  # fmt: skip
        out[name] = repr(float(text)) if is_number else text
    return out


def _params(module: str, raw: Any) -> dict[str, float]:
    params = _mapping(raw, module=module, key="params", of="param names to numbers")
    return {
        _name(name, module=module, key="params"): _number(value, module=module,
                                                          key=f"params.{name}")
        for name, value in params.items()
    }  # fmt: skip


def _check_clashes(module: str, inputs, states, params) -> None:
    for key, names, other, what in (
        ("params", params, states, "a state"),
        ("params", params, inputs, "an input"),
        ("states", states, inputs, "an input"),
    ):
        clash = next((n for n in names if n in other), None)
        if clash is not None:
            key = f"params.{clash}" if key == "params" else key
            raise TwinTableError(f"'{clash}' is also {what}", module=module, key=key, token=clash)


def _check_keys(module: str, key: str, given: Mapping, allowed, what: str) -> None:
    """Refuse a key of ``given`` not in ``allowed``."""
    extra = next((k for k in given if k not in allowed), None)
    if extra is not None:
        listed = ", ".join(allowed) or "none"
        raise TwinTableError(f"'{extra}' is not {what} ({what}s: {listed})", module=module,
                             key=f"{key}.{extra}", token=extra)  # fmt: skip


def _equation_parts(module: str, entry: Mapping, inputs, outputs) -> Lowered:
    """Read an equations module's states, params, texts and output states."""
    states = _names(module, "states", entry.get("states"))
    params = _params(module, entry.get("params"))
    _check_clashes(module, inputs, states, params)
    if not outputs:
        raise TwinTableError("an equations module needs at least one output", module=module,
                             key="outputs")  # fmt: skip
    derivatives = _texts(module, "derivatives", entry.get("derivatives"))
    equations = _texts(module, "equations", entry.get("equations"))
    _check_keys(module, "derivatives", derivatives, states, "a state")
    missing = next((s for s in states if s not in derivatives), None)
    if missing is not None:
        raise TwinTableError(f"state '{missing}' has no derivative", module=module,
                             key="derivatives", token=missing)  # fmt: skip
    as_state = next((o for o in equations if o in states), None)
    if as_state is not None:
        raise TwinTableError(
            f"'{as_state}' is a state: an output named like a state is that state (drop the "
            "equation)", module=module, key=f"equations.{as_state}", token=as_state,
        )  # fmt: skip
    _check_keys(module, "equations", equations, outputs, "an output")
    bare = next((o for o in outputs if o not in states and o not in equations), None)
    if bare is not None:
        raise TwinTableError(f"'{bare}' is neither a state nor given by an equation",
                             module=module, key="outputs", token=bare)  # fmt: skip
    return Lowered(
        states=states,
        params=params,
        derivatives={s: derivatives[s] for s in states},
        equations={o: equations[o] for o in outputs if o in equations},
        output_states={o: o for o in outputs if o in states},
    )


def _block_parts(module: str, entry: Mapping, inputs, outputs) -> Lowered:
    """Lower a block module (:func:`dtwin.twin.blocks.lower_block`), errors with context."""
    block = entry["block"]
    extra = next((k for k in _EQUATION_KEYS if k in entry), None)
    if extra is not None:
        raise TwinTableError(
            f"a block module takes no '{extra}' (block '{block}' has its own; drop 'block' to "
            "write the module's equations)", module=module, key=extra, token=extra,
        )  # fmt: skip
    if not isinstance(block, str):
        raise TwinTableError(f"must be a block name (got {_shown(block)})", module=module,
                             key="block", token=_token(block))  # fmt: skip
    try:
        return lower_block(block, inputs, outputs, entry.get("params"))
    except BlockError as error:
        raise TwinTableError(error.rule, module=module, key=error.key,
                             token=error.token) from None  # fmt: skip


def _module_step(module: str, value: Any, states: tuple[str, ...]) -> str:
    """Return a module's ``discretisation``, validated (module docstring, Discretisation)."""
    if not isinstance(value, str) or value not in MODULE_STEPS:
        raise TwinTableError(
            f"must be one of {', '.join(MODULE_STEPS)} (got {_shown(value)})", module=module,
            key="discretisation", token=_token(value),
        )  # fmt: skip
    if value != "continuous" and not states:
        raise TwinTableError(
            f"the module has no states to step (got {value}; an algebraic module reads its "
            "inputs at each sample)", module=module, key="discretisation", token=value,
        )  # fmt: skip
    return value


def _defaults(entry: Mapping, params: Mapping[str, float]) -> frozenset[str]:
    """Return a block module's scalar params the file leaves at the block's default."""
    written = entry.get("params") or {}
    block = BLOCKS[entry["block"]]
    return frozenset(
        p.name
        for p in block.params
        if p.default is not None and p.name in params and written.get(p.name) is None
    )


def _initial(module: str, raw: Any, states: tuple[str, ...]) -> dict[str, float]:
    given = _mapping(raw, module=module, key="initial", of="state names to numbers")
    _check_keys(module, "initial", given, states, "a state")
    return {s: _number(v, module=module, key=f"initial.{s}") for s, v in given.items()}


#: The effects a module's ``candidates`` may name (docs/gap.md §Your own twin, Which).
TABLE_EFFECTS = (
    "input_saturation", "input_deadzone", "input_delay", "output_saturation",
    "output_bias_drift", "output_scale_error", "output_delay", "output_quantization",
    "state_limit", "state_cubic", "state_abs_square", "state_sign", "coulomb_friction",
    "cubic_stiffness", "quadratic_damping", "parameter_mismatch",
)  # fmt: skip


def _candidates(module: str, raw: Any) -> tuple[str, ...] | None:
    if raw is None:
        return None
    names = _names(module, "candidates", raw)
    unknown = next((n for n in names if n not in TABLE_EFFECTS), None)
    if unknown is not None:
        raise TwinTableError(
            f"unknown effect '{unknown}' (the effects: {', '.join(TABLE_EFFECTS)})",
            module=module, key="candidates", token=unknown,
        )  # fmt: skip
    return names


def _parse(module: ModuleSpec, key: str, text: str) -> Expression:
    """Parse one of the module's texts; the parser's error with the module and key in front."""
    try:
        return parse_expression(text, module.symbols)
    except ExpressionError as error:
        raise TwinTableError(str(error), module=module.name, key=key,
                             token=error.token) from None  # fmt: skip


def _check_start(module: ModuleSpec, key: str, expr: Expression) -> None:
    """Refuse an expression that is not finite at the start (module docstring)."""
    declared = {"t": 0.0, **module.params, **module.initial}
    first = None
    for probe in START_PROBES:
        point = {**dict.fromkeys((*module.states, *module.inputs), probe), **declared}
        value = expr.evaluate({n: point[n] for n in expr.names})
        if np.all(np.isfinite(value)):
            return
        first = value if first is None else first
    raise TwinTableError(
        f"'{expr.text}' is not finite at the start (got {first} with the declared params and "
        "initial states, other states and inputs at 0, 1 and 10)", module=module.name, key=key,
        token=expr.text,
    )  # fmt: skip


def _check_expressions(module: ModuleSpec) -> None:
    texts = [(f"derivatives.{s}", text) for s, text in module.derivatives.items()]
    texts += [(f"equations.{o}", text) for o, text in module.equations.items()]
    for key, text in texts:
        _check_start(module, key, _parse(module, key, text))


def _signal_map(module: str, key: str, raw: Any) -> dict[str, str]:
    """Read an FMU module's ``inputs``/``outputs``: recording signal → FMU variable name."""
    if isinstance(raw, (list, tuple)):
        return {n: n for n in _names(module, key, raw)}
    given = _mapping(raw, module=module, key=key, of="recording signals to FMU variables")
    out = {}
    for signal, variable in given.items():
        signal = _name(signal, module=module, key=key)
        if not isinstance(variable, str) or not variable:
            raise TwinTableError(f"must be an FMU variable name (got {_shown(variable)})",
                                 module=module, key=f"{key}.{signal}",
                                 token=_token(variable))  # fmt: skip
        out[signal] = variable
    return out


def _fmu_module(name: str, entry: Mapping, base_dir: Path | None) -> ModuleSpec:
    """Return an FMU module (``fmu:``), its file read and checked (:func:`read_fmu`)."""
    unknown = next((k for k in entry if k not in _FMU_KEYS), None)
    if unknown is not None:
        raise TwinTableError(f"an FMU module takes no '{unknown}' (allowed: "
                             f"{', '.join(_FMU_KEYS)})", module=name, key=str(unknown),
                             token=str(unknown))  # fmt: skip
    raw = entry["fmu"]
    if not isinstance(raw, str) or not raw:
        raise TwinTableError(f"must be the FMU file's path (got {_shown(raw)})", module=name,
                             key="fmu", token=_token(raw))  # fmt: skip
    inputs = _signal_map(name, "inputs", entry.get("inputs"))
    outputs = _signal_map(name, "outputs", entry.get("outputs"))
    if not outputs:
        raise TwinTableError("an FMU module needs outputs (recording signal: FMU output)",
                             module=name, key="outputs")  # fmt: skip
    both = next((s for s in outputs if s in inputs), None)
    if both is not None:
        raise TwinTableError(f"'{both}' is also an input of the module", module=name,
                             key="outputs", token=both)  # fmt: skip
    params = _mapping(entry.get("params"), module=name, key="params", of="FMU parameters")
    params = {str(p): _number(v, module=name, key=f"params.{p}") for p, v in params.items()}
    from dtwin.twin.fmu import FmuError, read_fmu

    path = Path(raw) if base_dir is None else Path(base_dir) / raw
    try:
        info = read_fmu(path, inputs=inputs, outputs=outputs, params=params,
                        interface=entry.get("interface"), shown=raw)  # fmt: skip
    except FmuError as error:
        raise TwinTableError(error.rule, module=name, key=error.key, token=error.token) from None
    return ModuleSpec(
        name=name, block=None, inputs=tuple(inputs), outputs=tuple(outputs),
        states=info.states, params=dict(info.params), initial={}, derivatives={},
        equations={}, output_states=dict(info.output_states), linear=False,
        source=f"fmu {raw}", candidates=_candidates(name, entry.get("candidates")), fmu=info,
    )  # fmt: skip


def _module_spec(name: Any, entry: Any, base_dir: Path | None = None) -> ModuleSpec:
    """One module of the ``modules`` mapping, validated (module docstring)."""
    name = _name(name, module=None, key="modules")
    if not isinstance(entry, Mapping):
        raise TwinTableError(
            f"must be a mapping with keys among {', '.join(_MODULE_KEYS)} (got "
            f"{type(entry).__name__} {_shown(entry)})", module=name, token=str(entry)[:40],
        )  # fmt: skip
    unknown = next((k for k in entry if k not in _MODULE_KEYS), None)
    if unknown is not None:
        raise TwinTableError(f"unknown key (allowed: {', '.join(_MODULE_KEYS)})", module=name,
                             key=str(unknown), token=str(unknown))  # fmt: skip
    if "fmu" in entry:
        return _fmu_module(name, entry, base_dir)
    if "interface" in entry:
        raise TwinTableError("'interface' is for an FMU module (one with 'fmu')", module=name,
                             key="interface", token="interface")  # fmt: skip
    inputs = _names(name, "inputs", entry.get("inputs"))
    outputs = _names(name, "outputs", entry.get("outputs"))
    both = next((s for s in outputs if s in inputs), None)
    if both is not None:
        raise TwinTableError(f"'{both}' is also an input of the module", module=name,
                             key="outputs", token=both)  # fmt: skip
    is_block = "block" in entry
    parts = (_block_parts if is_block else _equation_parts)(name, entry, inputs, outputs)
    spec = ModuleSpec(
        name=name,
        block=entry["block"] if is_block else None,
        inputs=inputs,
        outputs=outputs,
        states=parts.states,
        params=dict(parts.params),
        initial=_initial(name, entry.get("initial"), parts.states),
        derivatives=dict(parts.derivatives),
        equations=dict(parts.equations),
        output_states=dict(parts.output_states),
        linear=is_block,
        source=f"block {entry['block']}" if is_block else "equations",
        candidates=_candidates(name, entry.get("candidates")),
        defaults=_defaults(entry, parts.params) if is_block else frozenset(),
        discretisation=_module_step(name, entry.get("discretisation", "continuous"),
                                    parts.states),
    )  # fmt: skip
    _check_expressions(spec)
    return spec


def _check_wiring(modules: list[ModuleSpec]) -> None:
    """Refuse a signal produced twice and a name both a module and a signal."""
    producers: dict[str, str] = {}
    for m in modules:
        for s in m.outputs:
            if s in producers:
                raise TwinTableError(f"'{s}' is also produced by module '{producers[s]}'",
                                     module=m.name, key="outputs", token=s)  # fmt: skip
            producers[s] = m.name
    names = {m.name for m in modules}
    for m in modules:
        for key, signals in (("inputs", m.inputs), ("outputs", m.outputs)):
            clash = next((s for s in signals if s in names), None)
            if clash is not None:
                raise TwinTableError(f"'{clash}' is both a module and a signal", module=m.name,
                                     key=key, token=clash)  # fmt: skip


def _algebraic_edges(modules: list[ModuleSpec]) -> dict[str, list[tuple[str, str]]]:
    """Signal → the (signal, module) pairs an equation computes from it directly."""
    edges: dict[str, list[tuple[str, str]]] = {}
    for m in modules:
        for out, text in m.equations.items():
            for name in parse_expression(text, m.symbols).names:
                if name in m.inputs:
                    edges.setdefault(name, []).append((out, m.name))
    return edges


def _find_cycle(edges: Mapping[str, list[tuple[str, str]]]):
    """Find a cycle of the signal graph: (signals, modules of its steps), or None."""
    status: dict[str, int] = {}  # 1: on the current path, 2: done
    for start in edges:
        if start in status:
            continue
        status[start] = 1
        stack, path, via = [iter(edges[start])], [start], []
        while stack:
            step = next(stack[-1], None)
            if step is None:
                status[path.pop()] = 2
                stack.pop()
                if via:
                    via.pop()
                continue
            target, module = step
            if status.get(target) == 1:
                i = path.index(target)
                return [*path[i:], target], [*via[i:], module]
            if target not in status:
                status[target] = 1
                stack.append(iter(edges.get(target, ())))
                path.append(target)
                via.append(module)
    return None


def _check_algebraic_loops(modules: list[ModuleSpec]) -> None:
    cycle = _find_cycle(_algebraic_edges(modules))
    if cycle is None:
        return
    signals, through = cycle
    order = [m.name for m in modules]
    first = min(range(len(through)), key=lambda k: order.index(through[k]))
    signals = [*signals[first:-1], *signals[:first], signals[first]]
    through = [*through[first:], *through[:first]]
    names = ", ".join(f"'{m}'" for m in dict.fromkeys(through))
    raise TwinTableError(
        f"algebraic loop through module(s) {names} (signals {' -> '.join(signals)}): a loop "
        "must pass through a state", module=through[0], key=f"equations.{signals[1]}",
        token=signals[0],
    )  # fmt: skip


def _order(modules: list[ModuleSpec]) -> tuple[ModuleSpec, ...]:
    """Each module after the producers of its inputs, in declaration order where possible."""
    producer = {s: m.name for m in modules for s in m.outputs}
    needs = {m.name: {producer[s] for s in m.inputs if s in producer} - {m.name} for m in modules}
    placed: set[str] = set()
    out: list[ModuleSpec] = []
    while len(out) < len(modules):
        pending = [m for m in modules if m.name not in placed]
        chosen = next((m for m in pending if needs[m.name] <= placed), pending[0])
        out.append(chosen)
        placed.add(chosen.name)
    return tuple(out)


def _noise(raw: Any, modules: tuple[ModuleSpec, ...]) -> dict[str, float]:
    """Noise std devs by output signal (a module's entry expanded to its outputs)."""
    given = _mapping(raw, module=None, key="noise", of="output signals or modules to numbers")
    by_name = {m.name: m for m in modules}
    signals = [s for m in modules for s in m.outputs]
    by_module: dict[str, float] = {}
    by_signal: dict[str, float] = {}
    for key, value in given.items():
        place = f"noise.{key}"
        if key in by_name:
            number = _number(value, module=None, key=place, positive=True)
            by_module.update(dict.fromkeys(by_name[key].outputs, number))
        elif key in signals:
            by_signal[key] = _number(value, module=None, key=place, positive=True)
        else:
            raise TwinTableError(
                f"'{key}' is neither an output signal nor a module (outputs: "
                f"{', '.join(signals)}; modules: {', '.join(by_name)})", key=place, token=str(key),
            )  # fmt: skip
    merged = {**by_module, **by_signal}
    return {s: merged[s] for s in signals if s in merged}


def _process_noise(raw: Any, modules: tuple[ModuleSpec, ...]) -> dict[str, float]:
    """Process noise std devs by qualified state (a module's entry expanded to its states)."""
    given = _mapping(raw, module=None, key="process_noise",
                     of="<module>.<state> or modules to numbers")  # fmt: skip
    by_name = {m.name: m for m in modules}
    states = [f"{m.name}.{s}" for m in modules for s in m.states if m.fmu is None]
    by_module: dict[str, float] = {}
    by_state: dict[str, float] = {}
    for key, value in given.items():
        place = f"process_noise.{key}"
        owner = by_name.get(str(key).split(".", 1)[0])
        if owner is not None and owner.fmu is not None:
            raise TwinTableError(
                f"module '{owner.name}' is an FMU: its states take no process noise (its "
                "equations are inside the FMU)", key=place, token=str(key),
            )  # fmt: skip
        if key not in states and not (key in by_name and by_name[key].states):
            raise TwinTableError(
                f"'{key}' is neither <module>.<state> nor a module with states (states: "
                f"{', '.join(states) or 'none'})", key=place, token=str(key),
            )  # fmt: skip
        number = _number(value, module=None, key=place)
        if number < 0:
            raise TwinTableError(f"must be a finite number >= 0 (got {_shown(value)})",
                                 key=place, token=_token(value))  # fmt: skip
        if key in states:
            by_state[key] = number
        else:
            by_module.update(dict.fromkeys((f"{key}.{s}" for s in by_name[key].states), number))
    merged = {**by_module, **by_state}
    return {s: merged[s] for s in states if merged.get(s, 0.0) > 0}


def _top_level(mapping: Any) -> Mapping:
    """Return the table's mapping (unwrapped from ``twin:``), its top-level keys checked."""
    if isinstance(mapping, Mapping) and "modules" not in mapping:
        inner = mapping.get("twin")
        if isinstance(inner, Mapping) and "modules" in inner and len(mapping) == 1:
            mapping = inner
    if not isinstance(mapping, Mapping):
        raise TwinTableError(f"must be a mapping with 'modules' (got {type(mapping).__name__})")
    for key in mapping:
        if key in _LEGACY_KEYS:
            raise TwinTableError(
                "a section of the paper's twin: shape; a table lists its modules under "
                "'modules:' (write one shape or the other)", key=str(key), token=str(key),
            )  # fmt: skip
        if key not in _TOP_KEYS:
            raise TwinTableError(f"unknown top-level key (allowed: {', '.join(_TOP_KEYS)})",
                                 key=str(key), token=str(key))  # fmt: skip
    modules = mapping.get("modules")
    if not isinstance(modules, Mapping) or not modules:
        shown = "empty" if isinstance(modules, Mapping) else f"got {_shown(modules)}"
        raise TwinTableError(f"must be a non-empty mapping of module names ({shown})",
                             key="modules")  # fmt: skip
    return mapping


def _discretisation(value: Any) -> str | None:
    if value is None or value in _DISCRETISATIONS:
        return value
    raise TwinTableError(
        f"must be zoh or foh (got {_shown(value)}; euler and bandlimited are the paper "
        "plant's, for the twin: shape)", key="discretisation", token=_token(value),
    )  # fmt: skip


def table_from_mapping(
    mapping: Mapping, *, dt: float | None = None, base_dir: str | Path | None = None
) -> TwinTable:
    """Return the :class:`TwinTable` of a twin file's content (module docstring).

    Parameters
    ----------
    mapping : mapping
        The file's content: ``dt``, ``discretisation``, ``modules``, ``noise`` and
        ``process_noise`` at the top level or all under ``twin:``.
    dt : float, optional
        Sample period, s, when the file gives none (the recording's).
    base_dir : str or Path, optional
        The twin file's folder: an FMU module's path is relative to it (default: the
        working directory).

    Returns
    -------
    TwinTable

    Raises
    ------
    TwinTableError
        On every rule of the module docstring, one line naming module, key and token.

    Examples
    --------
    >>> table = table_from_mapping({"modules": {
    ...     "pump": {"block": "lag", "inputs": ["u"], "outputs": ["q"], "params": {"tau": 8.0}},
    ...     "tank": {"inputs": ["q"], "outputs": ["h"], "states": ["h"], "params": {"a": 0.1},
    ...              "derivatives": {"h": "q - a*sqrt(max(h, 0))"}}}})
    >>> [m.name for m in table.modules], table.exogenous, table.module("pump").equations
    (['pump', 'tank'], ('u',), {'q': 'y + bias'})
    >>> table_from_mapping({"modules": {"tank": {"outputs": ["h"], "states": ["h"],
    ...                     "derivatives": {"h": "q2 - h"}}}})
    Traceback (most recent call last):
    ...
    dtwin.twin.table.TwinTableError: twin file: module 'tank': derivatives.h: unknown name 'q2'
    """
    raw = _top_level(mapping)
    period = raw.get("dt") if raw.get("dt") is not None else dt
    if period is not None:
        period = _number(period, module=None, key="dt", positive=True)
    discretisation = _discretisation(raw.get("discretisation"))
    folder = None if base_dir is None else Path(base_dir)
    modules = [_module_spec(name, entry, folder) for name, entry in raw["modules"].items()]
    _check_wiring(modules)
    _check_algebraic_loops(modules)
    ordered = _order(modules)
    return TwinTable(
        ordered, period, discretisation, _noise(raw.get("noise"), ordered),
        _process_noise(raw.get("process_noise"), ordered),
    )  # fmt: skip


def check_recorded(table: TwinTable, columns: Collection[str]) -> None:
    """Refuse a table whose exogenous inputs the recording lacks.

    Parameters
    ----------
    table : TwinTable
    columns : collection of str
        The recording's signal columns.

    Raises
    ------
    TwinTableError
        ``twin file: module 'pump': inputs: 'u' is neither a recording column nor produced by
        a module`` for the first such input in table order.
    """
    recorded = set(columns)
    produced = set(table.signals)
    for m in table.modules:
        for s in m.inputs:
            if s not in produced and s not in recorded:
                raise TwinTableError(
                    f"'{s}' is neither a recording column nor produced by a module",
                    module=m.name, key="inputs", token=s,
                )  # fmt: skip
