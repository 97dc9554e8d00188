"""Units of a twin table and their simulation over windows restarted from the recording.

Specification: docs/gap.md §Twin file (Units, Simulation).

A **unit** is what the diagnoser can compare with a recording on its own: one module whose
inputs and outputs are recorded, or several modules joined by signals that are not recorded
(:func:`units_of`). Its recorded inputs drive it; its recorded outputs are scored; its states
are integrated jointly, so a loop between its modules through states (a motor's electrical and
mechanical parts coupled through the back-EMF) is one system of equations.

:class:`UnitModel` lays a unit out as one slot vector (``t``, inputs, states, params, algebraic
signals, derivatives) and one postfix program of assignments (algebraic equations in dependency
order, then each state's derivative), integrated by :func:`dtwin.twin._kernels.simulate_lanes`
with the classical Runge-Kutta method over ``substeps`` steps per sample. Recorded inputs are
held over a sample (``zoh``) or linear between samples (``foh``, and always for a signal another
module produces). A unit of **discrete** modules (a module's ``discretisation`` ``euler`` or
``zoh``, :mod:`dtwin.twin.table`) is stepped once per sample from the previous sample's states and
inputs instead (:attr:`UnitModel.stepping`; ``substeps`` and holds unused). A unit's variants (a
candidate effect: an extra term in a derivative, a wrapped signal, a state limit, extra params)
are :meth:`UnitModel.variant`; they keep the unit's stepping.

Accuracy: the step ``h = dt/substeps`` is chosen so that ``h·ρ ≤`` :data:`STEP_RHO`, with ``ρ``
the largest magnitude of an eigenvalue of the unit's Jacobian over its recorded operating points
(:func:`choose_substeps`); RK4's local error on a linear mode ``λ`` is ``(hλ)^5/120`` of the
state, at most 2.6e-4 for ``hρ = 0.5`` (the bound below).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.twin._kernels import chain_windows, simulate_lanes
from dtwin.twin.expressions import OP_STORE, parse_expression
from dtwin.twin.table import DISCRETE_STEPS, TwinTableError

__all__ = [
    "STEP_RHO",
    "MAX_SUBSTEPS",
    "Assignment",
    "UnitSpec",
    "UnitModel",
    "units_of",
    "choose_substeps",
    "window_rows",
]

#: Largest ``h·ρ`` of a Runge-Kutta step (``ρ`` the Jacobian's spectral radius).
STEP_RHO = 0.5
#: Most Runge-Kutta steps per sample.
MAX_SUBSTEPS = 64


@dataclass(frozen=True)
class Assignment:
    """One assignment of a unit's program: ``target = text`` with local names bound to slots.

    ``target`` is a slot name (a signal, or ``d/<module>.<state>`` for a derivative);
    ``symbols`` maps each local name the text may read to its slot name.
    """

    target: str
    text: str
    symbols: Mapping[str, str]
    module: str


@dataclass(frozen=True)
class UnitSpec:
    """A unit of a twin table (:func:`units_of`).

    Attributes
    ----------
    modules : tuple of str
        Its modules, in table order.
    inputs : tuple of str
        Recorded signals it reads that none of its modules produce.
    outputs : tuple of str
        Recorded signals its modules produce (scored).
    states : tuple of str
        Qualified states ``<module>.<state>``.
    params : dict of str to float
        Qualified params ``<module>.<param>`` and their declared values.
    assignments : tuple of Assignment
        Algebraic equations in dependency order, then one derivative per state.
    output_states : dict of str to str
        Recorded output → the qualified state it equals (set from the recording at a restart).
    initial : dict of str to float
        Declared initial states (qualified).
    internal : tuple of str
        Signals its modules produce that are not recorded.
    linear : bool
        Every module is a linear built-in block.
    defaults : frozenset of str
        Qualified params left at a block's default (:attr:`ModuleSpec.defaults`).
    stepping : dict of str to str
        Qualified state → ``"euler"`` or ``"zoh"`` for the states of discrete modules
        (:attr:`ModuleSpec.discretisation`); empty for a unit of continuous modules. A unit's
        states are all discrete or all continuous (:func:`units_of`).
    """

    modules: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    states: tuple[str, ...]
    params: dict[str, float]
    assignments: tuple[Assignment, ...]
    output_states: dict[str, str]
    initial: dict[str, float]
    internal: tuple[str, ...] = ()
    linear: bool = False
    defaults: frozenset[str] = frozenset()
    stepping: dict[str, str] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The unit's name: its module, or its modules joined by ``+``."""
        return "+".join(self.modules)

    def module_of(self, qualified: str) -> str:
        """Return the module of a qualified state or param name."""
        return qualified.split(".", 1)[0]


def _derivative_slot(state: str) -> str:
    return f"d/{state}"


def _module_assignments(module, produced_in_unit: set[str]) -> list[Assignment]:
    """Return the algebraic and derivative assignments of one module (qualified names).

    An FMU module has none: its model is the FMU (:func:`dtwin.twin.fmu.model_for`).
    """
    if getattr(module, "fmu", None) is not None:
        return []
    local = {p: f"{module.name}.{p}" for p in module.params}
    local.update({s: f"{module.name}.{s}" for s in module.states})
    local.update({s: s for s in module.inputs})
    local["t"] = "t"
    algebraic = [
        Assignment(signal, text, local, module.name) for signal, text in module.equations.items()
    ]
    for signal, state in module.output_states.items():
        if signal in produced_in_unit:
            algebraic.append(Assignment(signal, state, local, module.name))
    derivatives = [
        Assignment(
            _derivative_slot(f"{module.name}.{s}"), module.derivatives[s], local, module.name
        )
        for s in module.states
    ]
    return algebraic + derivatives


def _order_algebraic(assignments: list[Assignment]) -> list[Assignment]:
    """Order algebraic assignments so each comes after those producing what it reads."""
    targets = {a.target for a in assignments}
    ordered, placed = [], set()
    pending = list(assignments)
    while pending:
        ready = [
            a
            for a in pending
            if all(a.symbols.get(n, n) not in targets - placed for n in _reads(a))
        ]
        if not ready:
            loop = ", ".join(sorted({a.module for a in pending}))
            raise DtwinValueError(f"twin table: algebraic loop among module(s) {loop}")
        for a in ready:
            ordered.append(a)
            placed.add(a.target)
            pending.remove(a)
    return ordered


def _reads(assignment: Assignment) -> tuple[str, ...]:
    return parse_expression(assignment.text, assignment.symbols).names


def units_of(table, recorded: Sequence[str]) -> list[UnitSpec]:
    """Return the units of ``table`` for a recording with columns ``recorded``.

    Modules joined by a signal that one produces, another reads and the recording lacks form one
    unit (union over such signals). A unit without a recorded output is left out (nothing to
    score).

    Parameters
    ----------
    table : dtwin.twin.table.TwinTable
    recorded : sequence of str
        The recording's signal columns.

    Returns
    -------
    list of UnitSpec
        In table order of their first module.
    """
    recorded_set = set(recorded)
    group = {m.name: m.name for m in table.modules}

    def root(name: str) -> str:
        while group[name] != name:
            name = group[name]
        return name

    for consumer in table.modules:
        for signal in consumer.inputs:
            producer = table.producer(signal)
            if producer is not None and signal not in recorded_set:
                group[root(consumer.name)] = root(producer.name)
    members: dict[str, list] = {}
    for module in table.modules:
        members.setdefault(root(module.name), []).append(module)
    units = [_unit_spec(mods, recorded_set) for mods in members.values()]
    return [u for u in units if u.outputs]


def _check_stepping(modules: list, internal: tuple[str, ...]) -> None:
    """Refuse a unit whose modules with states are not all discrete or all continuous."""
    stepped = [m for m in modules if m.states and m.fmu is None]
    discrete = [m for m in stepped if m.discretisation in DISCRETE_STEPS]
    if not discrete or len(discrete) == len(stepped):
        return
    first = discrete[0]
    others = ", ".join(m.name for m in stepped if m not in discrete)
    raise TwinTableError(
        f"{first.discretisation} is a discrete module's step, and module(s) {others} of its "
        f"unit (joined by the signal(s) {', '.join(internal)} the recording lacks) are "
        "continuous: record those signals, or give the unit's modules discretisations of one "
        "kind (euler/zoh, or continuous)", module=first.name, key="discretisation",
        token=first.discretisation,
    )  # fmt: skip


def _unit_spec(modules: list, recorded: set[str]) -> UnitSpec:
    """One unit from its modules (table order)."""
    produced = {s for m in modules for s in m.outputs}
    inputs = tuple(dict.fromkeys(s for m in modules for s in m.inputs if s not in produced))
    outputs = tuple(s for m in modules for s in m.outputs if s in recorded)
    internal = tuple(s for m in modules for s in m.outputs if s not in recorded)
    _check_stepping(modules, internal)
    assignments = [a for m in modules for a in _module_assignments(m, produced)]
    algebraic = _order_algebraic([a for a in assignments if not a.target.startswith("d/")])
    derivatives = [a for a in assignments if a.target.startswith("d/")]
    output_states = {
        s: f"{m.name}.{state}"
        for m in modules
        for s, state in m.output_states.items()
        if s in recorded
    }
    return UnitSpec(
        modules=tuple(m.name for m in modules),
        inputs=inputs,
        outputs=outputs,
        states=tuple(f"{m.name}.{s}" for m in modules for s in m.states),
        params={f"{m.name}.{p}": float(v) for m in modules for p, v in m.params.items()},
        assignments=tuple(algebraic + derivatives),
        output_states=output_states,
        initial={f"{m.name}.{s}": float(v) for m in modules for s, v in m.initial.items()},
        internal=internal,
        linear=all(m.linear for m in modules),
        defaults=frozenset(f"{m.name}.{p}" for m in modules for p in m.defaults),
        stepping={
            f"{m.name}.{s}": m.discretisation
            for m in modules
            if m.discretisation in DISCRETE_STEPS
            for s in m.states
        },
    )


@dataclass(frozen=True)
class UnitModel:
    """A unit compiled for simulation: its slot layout and postfix program.

    Build with :meth:`from_spec`; :meth:`simulate` runs it. ``param_names`` are the unit's
    qualified params followed by any extra params of a variant (in that order: the ``theta``
    vector of :meth:`simulate`).
    """

    spec: UnitSpec
    param_names: tuple[str, ...]
    slots: Mapping[str, int] = field(repr=False)
    program: tuple = field(repr=False)
    layout: tuple = field(repr=False)
    out_slots: np.ndarray = field(repr=False)
    depth: int = 1
    assignments: tuple[Assignment, ...] = ()

    @property
    def stepping(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(kinds, first, last)`` per state, shape ``(n_states,)`` each (int64).

        ``kinds``: 0 continuous (Runge-Kutta), 1 ``euler``, 2 ``zoh``; ``first``/``last`` the
        span of the state's module among the unit's states (states ``first … last − 1``).
        """
        return _stepping(self.spec)

    @classmethod
    def from_spec(
        cls,
        spec: UnitSpec,
        assignments: Sequence[Assignment] | None = None,
        extra_params: Sequence[str] = (),
    ) -> UnitModel:
        """Compile ``spec`` (or ``spec`` with ``assignments`` in place of its own)."""
        assignments = tuple(spec.assignments if assignments is None else assignments)
        param_names = (*spec.params, *extra_params)
        names = ["t", *spec.inputs, *spec.states, *param_names]
        names += [a.target for a in assignments if a.target not in names]
        slots = {name: i for i, name in enumerate(names)}
        codes, consts, bounds, depth = [], [], [0], 1
        for a in assignments:
            expr = parse_expression(a.text, a.symbols)
            code = expr.bound({n: slots[a.symbols[n]] for n in expr.names})
            code[code[:, 0] == 0, 1] += sum(len(c) for c in consts)
            code = np.vstack([code, [[OP_STORE, slots[a.target]]]])
            codes.append(code)
            consts.append(expr.consts)
            bounds.append(bounds[-1] + len(code))
            depth = max(depth, expr.depth)
        targets = np.array([slots[a.target] for a in assignments], dtype=np.int64)
        program = (
            np.concatenate(codes).ravel() if codes else np.zeros(0, dtype=np.int64),
            np.concatenate(consts) if consts else np.zeros(0),
            np.array(bounds, dtype=np.int64),
            targets,
        )
        layout = (
            np.array([slots[s] for s in spec.states], dtype=np.int64),
            np.array([slots[_derivative_slot(s)] for s in spec.states], dtype=np.int64),
            np.array([slots[s] for s in spec.inputs], dtype=np.int64),
            np.ones(len(spec.inputs), dtype=np.bool_),
        )
        out_slots = np.array([slots[s] for s in spec.outputs], dtype=np.int64)
        return cls(spec, param_names, slots, program, layout, out_slots, depth, assignments)

    def variant(
        self, replaced: Mapping[str, str] = {}, added: Sequence[Assignment] = (), extra=()
    ) -> UnitModel:
        """Return a copy with some assignments' texts replaced, others added and extra params.

        ``replaced`` maps an assignment's target to its new text (which may read the extra
        params by their own names); ``added`` assignments are placed right after the one
        producing their target (a wrapped signal), or first when nothing in the unit produces it
        (a wrapped input). ``extra`` names the extra params (qualified, e.g. ``_e.U``).
        """
        out: list[Assignment] = []
        extra_symbols = {name: name for name in extra}
        wraps = {a.target: a for a in added}
        for a in wraps.values():
            if not any(b.target == a.target for b in self.assignments):
                out.append(_with_symbols(a, extra_symbols))
        for a in self.assignments:
            text = replaced.get(a.target, a.text)
            out.append(_with_symbols(replace(a, text=text), extra_symbols))
            if a.target in wraps:
                out.append(_with_symbols(wraps[a.target], extra_symbols))
        return UnitModel.from_spec(
            self.spec, out, (*self.param_names[len(self.spec.params) :], *extra)
        )

    def disturbed(self, states: Sequence[str]) -> UnitModel:
        """Return a copy whose derivatives of ``states`` each gain one extra input.

        The copy's inputs are the unit's followed by one disturbance per named state
        (``_w_0, _w_1, …``, in the order given, units of the state per second), added to that
        state's derivative: driven with ``w_k/dt`` held over sample ``k`` (``zoh``), the
        disturbance alone moves the state by ``w_k`` over the sample (process noise, docs/gap.md
        §Twin file). Driven with zeros it simulates as the unit does. ``param_names`` are
        unchanged.

        Parameters
        ----------
        states : sequence of str
            Qualified states (``<module>.<state>``) of :attr:`spec`.
        """
        unknown = [s for s in states if s not in self.spec.states]
        if unknown:
            raise DtwinValueError(
                f"states {', '.join(unknown)} are not the unit's (states: "
                f"{', '.join(self.spec.states) or 'none'})"
            )
        names = {_derivative_slot(s): f"_w_{i}" for i, s in enumerate(states)}
        assignments = [
            replace(a, text=f"({a.text}) + {names[a.target]}",
                    symbols={**a.symbols, names[a.target]: names[a.target]})
            if a.target in names else a
            for a in self.assignments
        ]  # fmt: skip
        spec = replace(self.spec, inputs=(*self.spec.inputs, *names.values()))
        return UnitModel.from_spec(spec, assignments, self.param_names[len(self.spec.params) :])

    def simulate(
        self,
        inputs: np.ndarray,
        theta: Sequence[float],
        starts: np.ndarray,
        stops: np.ndarray,
        x0: np.ndarray,
        dt: float,
        *,
        substeps: int = 1,
        linear: Sequence[bool] | None = None,
        limits: tuple[np.ndarray, np.ndarray] | None = None,
        t0: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Simulate the unit over windows; return its outputs and its states.

        Returns ``(outputs, states)``, shapes ``(n_samples, n_outputs)`` and ``(n_samples,
        n_states)``, NaN outside the windows.

        Parameters
        ----------
        inputs : numpy.ndarray, shape (n_samples, n_inputs)
            The unit's inputs at the samples, in :attr:`UnitSpec.inputs` order.
        theta : sequence of float, length ``len(param_names)``
            Param values.
        starts, stops : numpy.ndarray of int, shape (n_windows,)
            Window ``w`` covers samples ``starts[w] … stops[w] − 1``; others are NaN.
        x0 : numpy.ndarray, shape (n_windows, n_states)
            The states at each window's first sample.
        dt : float
            Sample period, s.
        substeps : int
            Runge-Kutta steps per sample (:func:`choose_substeps`).
        linear : sequence of bool, optional
            Per input: linear between samples (True) or held (False); default all linear.
        limits : (lo, hi), optional
            Bounds of each state, shape ``(n_states,)`` each (a ``state_limit``).
        t0 : float
            Time of sample 0, s.
        """
        starts = np.asarray(starts, dtype=np.int64)
        stops = np.asarray(stops, dtype=np.int64)
        n_states = len(self.spec.states)
        x0 = np.asarray(x0, dtype=np.float64).reshape(1, len(starts), n_states)
        y, states = self.simulate_batch(
            [inputs], [0], [theta], starts, stops, x0, dt, substeps=substeps, linear=linear,
            limits=None if limits is None else [limits], t0=t0,
        )  # fmt: skip
        n_samples = len(inputs)
        if len(starts) == 1 and starts[0] == 0 and stops[0] == n_samples:
            return y[0], states[0]  # one window over every sample (a live stream's step)
        rows = window_rows(starts, stops)
        full_y = np.full((n_samples, y.shape[2]), np.nan)
        full_states = np.full((n_samples, n_states), np.nan)
        full_y[rows] = y[0]
        full_states[rows] = states[0]
        return full_y, full_states

    def simulate_batch(
        self,
        input_sets: Sequence[np.ndarray],
        input_of: Sequence[int],
        thetas: Sequence[Sequence[float]],
        starts: np.ndarray,
        stops: np.ndarray,
        x0: np.ndarray,
        dt: float,
        *,
        substeps: int = 1,
        linear: Sequence[bool] | None = None,
        limits: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
        t0: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Simulate the unit over windows for several param vectors at once (one compiled pass).

        Each member's outputs and states are those :meth:`simulate` returns for it, bit for bit,
        on the windows' samples only.

        Parameters
        ----------
        input_sets : sequence of numpy.ndarray, each shape (n_samples, n_inputs)
            The distinct input series of the batch.
        input_of : sequence of int, length n_batch
            The input set each member reads.
        thetas : sequence of sequences of float, shape (n_batch, len(param_names))
            Each member's param values.
        starts, stops : numpy.ndarray of int, shape (n_windows,)
            The windows (as :meth:`simulate`).
        x0 : numpy.ndarray, shape (n_batch, n_windows, n_states)
            Each member's states at each window's first sample.
        dt, substeps, linear, t0
            As :meth:`simulate` (the same for every member).
        limits : sequence of (lo, hi), optional
            Each member's state bounds, shape ``(n_states,)`` each.

        Returns
        -------
        (outputs, states) : numpy.ndarray, shapes (n_batch, n_rows, n_outputs) and
            (n_batch, n_rows, n_states)
            Rows are the windows' samples one after the other (:func:`window_rows`).
        """
        n_batch = len(thetas)
        n_states = len(self.spec.states)
        bases = np.zeros((n_batch, len(self.slots)))
        index = np.array([self.slots[name] for name in self.param_names], dtype=np.int64)
        if len(index):
            bases[:, index] = np.asarray(thetas, dtype=np.float64).reshape(n_batch, len(index))
        layout = self.layout
        if linear is not None:
            layout = (*layout[:3], np.asarray(linear, dtype=np.bool_))
        lo = np.full((n_batch, n_states), -np.inf)
        hi = np.full((n_batch, n_states), np.inf)
        for b, bound in enumerate(limits or ()):
            if bound is not None:
                lo[b], hi[b] = bound
        n_samples, n_inputs = len(input_sets[0]), len(self.spec.inputs)
        sets = [np.ascontiguousarray(v, dtype=np.float64).reshape(n_samples, n_inputs)
                for v in input_sets]  # fmt: skip
        u = sets[0][None] if len(sets) == 1 else np.stack(sets)  # one set: no copy
        starts = np.asarray(starts, dtype=np.int64)
        return simulate_lanes(
            self.program,
            bases,
            layout,
            u,
            np.asarray(input_of, dtype=np.int64),
            self.out_slots,
            lo,
            hi,
            starts,
            np.asarray(stops, dtype=np.int64),
            np.ascontiguousarray(x0, dtype=np.float64).reshape(n_batch, len(starts), n_states),
            float(dt),
            float(t0),
            int(substeps),
            int(self.depth),
            self.stepping,
        )

    def simulate_chained(
        self,
        inputs: np.ndarray,
        theta: Sequence[float],
        starts: np.ndarray,
        stops: np.ndarray,
        x0: np.ndarray,
        reset: Sequence[int],
        values: np.ndarray,
        dt: float,
        *,
        substeps: int = 1,
        linear: Sequence[bool] | None = None,
    ) -> np.ndarray:
        """Run windows one after the other, each from the end of the previous; return the states.

        The first window starts from ``x0`` ``(n_states,)``; at each window's start the states
        at indices ``reset`` are set to ``values[w]`` (shape ``(n_windows, len(reset))``: a
        state recorded as an output, from the recording); a state whose window ends not finite
        passes on its start instead. No state bounds. Returns the states at every sample of the
        windows, shape ``(Σ (stops − starts), n_states)`` (:func:`window_rows`).
        """
        base = np.zeros(len(self.slots))
        for name, value in zip(self.param_names, theta, strict=False):
            base[self.slots[name]] = value
        layout = self.layout
        if linear is not None:
            layout = (*layout[:3], np.asarray(linear, dtype=np.bool_))
        n_states = len(self.spec.states)
        _, states = chain_windows(
            self.program, base, layout,
            np.ascontiguousarray(inputs, dtype=np.float64).reshape(len(inputs), -1),
            self.out_slots, np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64),
            np.asarray(x0, dtype=np.float64).reshape(n_states).copy(),
            np.asarray(reset, dtype=np.int64),
            np.ascontiguousarray(values, dtype=np.float64).reshape(len(starts), len(reset)),
            float(dt), 0.0, int(substeps), int(self.depth), self.stepping,
        )  # fmt: skip
        return states

    def derivatives(self, state: np.ndarray, inputs: np.ndarray, theta, t: float = 0.0):
        """Return the state derivatives at one point, shape ``(n_states,)`` (for Jacobians)."""
        values = {"t": t}
        values.update(zip(self.spec.inputs, inputs, strict=False))
        values.update(zip(self.spec.states, state, strict=False))
        values.update(zip(self.param_names, theta, strict=False))
        out = {}
        for a in self.assignments:
            expr = parse_expression(a.text, a.symbols)
            out[a.target] = values[a.target] = float(
                expr.evaluate({n: values[a.symbols[n]] for n in expr.names})
            )
        return np.array([out[_derivative_slot(s)] for s in self.spec.states])


_KINDS = {"euler": 1, "zoh": 2}


def _stepping(spec: UnitSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the kernels' per-state stepping arrays of a unit (:attr:`UnitModel.stepping`)."""
    n = len(spec.states)
    kinds = np.array([_KINDS.get(spec.stepping.get(q, ""), 0) for q in spec.states], np.int64)
    first, last = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    modules = [spec.module_of(q) for q in spec.states]
    for j, module in enumerate(modules):
        first[j] = modules.index(module)
        last[j] = n - modules[::-1].index(module)
    return kinds, first, last


def _with_symbols(assignment: Assignment, extra: Mapping[str, str]) -> Assignment:
    if not extra:
        return assignment
    return replace(assignment, symbols={**assignment.symbols, **extra})


def window_rows(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Return the samples of windows ``starts[w] … stops[w] − 1``, one window after the other.

    Returns
    -------
    numpy.ndarray of int64, shape (Σ (stops − starts),)
    """
    starts = np.asarray(starts, dtype=np.int64)
    lengths = np.asarray(stops, dtype=np.int64) - starts
    first = np.repeat(starts - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
    return first + np.arange(int(lengths.sum()), dtype=np.int64)


def choose_substeps(
    model: UnitModel, theta, states: np.ndarray, inputs: np.ndarray, dt: float
) -> int:
    """Runge-Kutta steps per sample: the smallest power of 2 with ``h·ρ ≤ STEP_RHO``.

    ``ρ`` is the largest eigenvalue magnitude of the Jacobian of the derivatives with respect to
    the states (central differences), its upper quartile over the given operating points (rows
    of ``states`` and ``inputs``: a kink such as ``sqrt(max(h, 0))`` at ``h = 0`` probed at one
    point does not set the step); at most :data:`MAX_SUBSTEPS`.
    """
    n = len(model.spec.states)
    if n == 0:
        return 1
    radii = [0.0]
    scale = np.maximum(np.nanstd(states, axis=0), 1e-9) if len(states) > 1 else np.ones(n)
    for state, u in zip(states, inputs, strict=True):
        jac = np.empty((n, n))
        for j in range(n):
            step = np.zeros(n)
            step[j] = 1e-4 * scale[j]
            up = model.derivatives(state + step, u, theta)
            down = model.derivatives(state - step, u, theta)
            jac[:, j] = (up - down) / (2 * step[j])
        if np.all(np.isfinite(jac)):
            radii.append(float(np.max(np.abs(np.linalg.eigvals(jac)))))
    # a kink (sqrt(max(h, 0)) at h = 0) probed at one point is not the unit's speed
    rho = float(np.quantile(radii, 0.75))
    substeps = 1
    while substeps < MAX_SUBSTEPS and dt / substeps * rho > STEP_RHO:
        substeps *= 2
    return substeps
