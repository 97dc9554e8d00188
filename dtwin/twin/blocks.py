"""The built-in blocks of a twin table, each lowered to a module's equations.

Specification: docs/gap.md §Twin file (Blocks). A module of the table may name a built-in
``block`` instead of writing its own equations; :func:`lower_block` turns it into the same
parts an equations module has (states, params, derivative and equation texts, the outputs that
are states), so everything downstream reads one kind of module. The registry :data:`BLOCKS`
is data: one :class:`Block` per block with its params (defaults and rules), its numbers of
inputs and outputs and its lowering function.

============================  =====================================================================
block                         law (``u`` the input signal(s); states are the block's own names)
============================  =====================================================================
``lag``                       params ``tau`` (required, > 0), ``gain`` = 1, ``bias`` = 0; state
                              ``y``: ``dy/dt = (gain·u − y)/tau``; output ``y + bias``
``mass_spring_damper``        params ``m`` (> 0), ``c`` (≥ 0), ``k`` (≥ 0); one input (force);
                              states ``x``, ``v``: ``dx/dt = v``, ``dv/dt = (u − c·v − k·x)/m``;
                              outputs ``[x]`` or ``[x, v]`` by position
``integrator``                param ``gain`` = 1; state ``y``: ``dy/dt = gain·u``; output ``y``
``gain``                      params ``gain`` = 1, ``bias`` = 0; output ``gain·u + bias``
``weighted_sum``              param ``weights`` (a list, one per input) → params ``w1 … wn``;
                              output ``w1·u1 + … + wn·un`` (left to right)
``state_space``               ``A`` (n×n), ``B`` (n×m), ``C`` (p×n), ``D`` (p×m, default 0),
                              continuous time; states ``s1 … sn``; ``ds/dt = A s + B u``,
                              ``y = C s + D u``
============================  =====================================================================

Lowering rules:

- Every param of a block is read by its texts, so a re-fit can move any of them. A ``lag``'s
  output is therefore always the equation ``y + bias`` (even for ``bias`` = 0) and never listed
  in ``output_states``; the outputs that *are* states are the ``mass_spring_damper``'s ``x`` and
  ``v`` and the ``integrator``'s ``y``.
- ``state_space``: every entry of ``A``, ``B`` and ``C`` is a param (``a11``, ``b21``, ``c12``…;
  ``a1_12`` style when a dimension exceeds 9) and appears in the texts, zeros included, so
  every entry can be re-fitted. A zero entry of ``D`` is a structural zero (no direct
  feedthrough, no param): only the non-zero entries of ``D`` become params ``d11``…, so a
  ``state_space`` without ``D`` has no algebraic path from input to output. ``n + m`` is at
  most :data:`MAX_STATE_SPACE_TERMS` (the length of one derivative's sum).
- ``weights`` become ``w1 … wn``.
- A block's input signal may not share a name with one of the block's states or params
  (``y``, ``x``, ``v``, ``tau``…): the lowered texts read the signal by its name.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from dtwin._validation import DtwinValueError

__all__ = [
    "BLOCKS",
    "MAX_STATE_SPACE_TERMS",
    "Block",
    "BlockError",
    "BlockParam",
    "Lowered",
    "lower_block",
]

#: Most terms ``n + m`` of one ``state_space`` derivative (keeps the text within the parser's
#: nesting bound, :data:`dtwin.twin.expressions.MAX_DEPTH`).
MAX_STATE_SPACE_TERMS = 30


class BlockError(DtwinValueError):
    """A block module's entry that breaks the block's rules.

    ``key`` is the entry (``params.tau``), ``rule`` the message without the key and ``token``
    the offending name or value.
    """

    def __init__(self, key: str, rule: str, token: str = "") -> None:
        super().__init__(f"{key}: {rule}")
        self.key = key
        self.rule = rule
        self.token = token


@dataclass(frozen=True)
class BlockParam:
    """One param of a block as the user writes it.

    Attributes
    ----------
    name : str
    default : float or None
        None: required.
    rule : str
        ``"any"``, ``"positive"`` (> 0) or ``"nonnegative"`` (≥ 0), scalars only.
    kind : str
        ``"scalar"``, ``"vector"`` (a list) or ``"matrix"`` (a list of rows).
    """

    name: str
    default: float | None = None
    rule: str = "any"
    kind: str = "scalar"


@dataclass(frozen=True)
class Lowered:
    """A block module as equations: what :func:`lower_block` returns.

    Attributes
    ----------
    states : tuple of str
        The block's state names (``("x", "v")``).
    params : dict of str to float
        Every param, defaults filled in, vectors and matrices expanded (``w1``, ``a11``).
    derivatives : dict of str to str
        State → derivative text.
    equations : dict of str to str
        Output signal → text, for the outputs that are not states.
    output_states : dict of str to str
        Output signal → the state it equals.
    """

    states: tuple[str, ...]
    params: dict[str, float]
    derivatives: dict[str, str]
    equations: dict[str, str]
    output_states: dict[str, str]


@dataclass(frozen=True)
class Block:
    """A built-in block: its params, its numbers of inputs and outputs, its lowering.

    Attributes
    ----------
    name : str
    params : tuple of BlockParam
    n_inputs : int or None
        Inputs it takes; None: any number (``weighted_sum`` ≥ 1, ``state_space`` ≥ 0).
    n_outputs : tuple of int or None
        Allowed numbers of outputs; None: any number ≥ 1.
    states : tuple of str
        Its state names (``state_space``: ``s1 … sn``, sized by ``A``, so empty here).
    lower : callable
        ``lower(inputs, outputs, values) -> Lowered``; ``values`` maps each param to a float
        (scalar) or a float array (vector, matrix; None when an optional one is absent).
    """

    name: str
    params: tuple[BlockParam, ...]
    n_inputs: int | None
    n_outputs: tuple[int, ...] | None
    states: tuple[str, ...]
    lower: Callable[[tuple[str, ...], tuple[str, ...], dict], Lowered]


def _lag(inputs, outputs, values) -> Lowered:
    u = inputs[0]
    return Lowered(
        states=("y",),
        params={name: values[name] for name in ("tau", "gain", "bias")},
        derivatives={"y": f"(gain*{u} - y)/tau"},
        equations={outputs[0]: "y + bias"},
        output_states={},
    )


def _mass_spring_damper(inputs, outputs, values) -> Lowered:
    u = inputs[0]
    return Lowered(
        states=("x", "v"),
        params={name: values[name] for name in ("m", "c", "k")},
        derivatives={"x": "v", "v": f"({u} - c*v - k*x)/m"},
        equations={},
        output_states=dict(zip(outputs, ("x", "v"), strict=False)),
    )


def _integrator(inputs, outputs, values) -> Lowered:
    return Lowered(("y",), {"gain": values["gain"]}, {"y": f"gain*{inputs[0]}"}, {},
                   {outputs[0]: "y"})  # fmt: skip


def _gain(inputs, outputs, values) -> Lowered:
    params = {"gain": values["gain"], "bias": values["bias"]}
    return Lowered((), params, {}, {outputs[0]: f"gain*{inputs[0]} + bias"}, {})


def _weighted_sum(inputs, outputs, values) -> Lowered:
    weights = values["weights"]
    if len(weights) != len(inputs):
        raise BlockError(
            "params.weights",
            f"needs one weight per input ({len(inputs)}; got {len(weights)})",
            str(len(weights)),
        )
    params = {f"w{i}": float(w) for i, w in enumerate(weights, 1)}
    text = " + ".join(f"w{i}*{u}" for i, u in enumerate(inputs, 1))
    return Lowered((), params, {}, {outputs[0]: text}, {})


def _shaped(key: str, value: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a matrix of ``shape``; a flat list fits a single row or column."""
    if value is None:
        return np.zeros(shape)
    if value.ndim == 1 and 1 in shape and value.size == shape[0] * shape[1]:
        return value.reshape(shape)
    if value.ndim == 1 and value.size == 0 and 0 in shape:
        return np.zeros(shape)
    if value.shape != shape:
        got = "×".join(map(str, value.shape))
        raise BlockError(f"params.{key}", f"must be {shape[0]}×{shape[1]} (got {got})", got)
    return value


def _entry_names(letter: str, shape: tuple[int, int], wide: bool) -> np.ndarray:
    sep = "_" if wide else ""
    rows, cols = shape
    return np.array(
        [[f"{letter}{i + 1}{sep}{j + 1}" for j in range(cols)] for i in range(rows)], dtype=object
    ).reshape(shape)


def _sum_text(terms: Sequence[str]) -> str:
    return " + ".join(terms) if terms else "0.0"


def _state_space(inputs, outputs, values) -> Lowered:
    a = values["A"]
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        got = "×".join(map(str, a.shape))
        raise BlockError("params.A", f"must be a square n×n matrix, n ≥ 1 (got {got})", got)
    n, m, p = a.shape[0], len(inputs), len(outputs)
    if n + m > MAX_STATE_SPACE_TERMS:
        raise BlockError("params.A", f"n + m is at most {MAX_STATE_SPACE_TERMS} (got {n + m})",
                         str(n + m))  # fmt: skip
    if values["B"] is None and m > 0:
        raise BlockError("params.B", f"is required with {m} input(s)", "B")
    b = _shaped("B", values["B"], (n, m))
    c = _shaped("C", values["C"], (p, n))
    d = _shaped("D", values["D"], (p, m))
    wide = max(n, m, p) > 9
    names = {key: _entry_names(key.lower(), mat.shape, wide) for key, mat in
             (("A", a), ("B", b), ("C", c), ("D", d))}  # fmt: skip
    states = tuple(f"s{i + 1}" for i in range(n))
    params: dict[str, float] = {}
    for key, mat in (("A", a), ("B", b), ("C", c)):
        params.update(zip(names[key].ravel(), map(float, mat.ravel()), strict=True))
    derivatives = {
        s: _sum_text([f"{names['A'][i, j]}*{states[j]}" for j in range(n)]
                     + [f"{names['B'][i, j]}*{inputs[j]}" for j in range(m)])
        for i, s in enumerate(states)
    }  # fmt: skip
    equations = {}
    for i, out in enumerate(outputs):
        feed = [j for j in range(m) if d[i, j] != 0.0]
        params.update({names["D"][i, j]: float(d[i, j]) for j in feed})
        equations[out] = _sum_text([f"{names['C'][i, j]}*{states[j]}" for j in range(n)]
                                   + [f"{names['D'][i, j]}*{inputs[j]}" for j in feed])  # fmt: skip
    return Lowered(states, params, derivatives, equations, {})


_P = BlockParam
#: The built-in blocks by name.
BLOCKS: dict[str, Block] = {
    block.name: block
    for block in (
        Block("lag", (_P("tau", None, "positive"), _P("gain", 1.0), _P("bias", 0.0)), 1, (1,),
              ("y",), _lag),
        Block("mass_spring_damper", (_P("m", None, "positive"), _P("c", None, "nonnegative"),
              _P("k", None, "nonnegative")), 1, (1, 2), ("x", "v"), _mass_spring_damper),
        Block("integrator", (_P("gain", 1.0),), 1, (1,), ("y",), _integrator),
        Block("gain", (_P("gain", 1.0), _P("bias", 0.0)), 1, (1,), (), _gain),
        Block("weighted_sum", (_P("weights", kind="vector"),), None, (1,), (), _weighted_sum),
        Block("state_space", (_P("A", kind="matrix"), _P("B", 0.0, kind="matrix"),
              _P("C", kind="matrix"), _P("D", 0.0, kind="matrix")), None, None, (),
              _state_space),
    )
}  # fmt: skip


def _is_number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))


def _scalar(key: str, value, rule: str) -> float:
    if not _is_number(value):
        shown = f"{type(value).__name__} {value!r}"
        if isinstance(value, bool):
            shown = str(value).lower()
        raise BlockError(
            key, f"must be a number (got {shown})", shown if isinstance(value, bool) else str(value)
        )
    number = float(value)
    if not np.isfinite(number):
        raise BlockError(key, f"must be finite (got {value!r})", str(value))
    if rule == "positive" and number <= 0:
        raise BlockError(key, f"must be > 0 (got {value!r})", str(value))
    if rule == "nonnegative" and number < 0:
        raise BlockError(key, f"must be >= 0 (got {value!r})", str(value))
    return number


def _array(key: str, value, kind: str) -> np.ndarray:
    """Read a vector (list of numbers, or one number) or a matrix (list of rows, or one number)."""
    if _is_number(value):
        return np.full((1, 1) if kind == "matrix" else (1,), _scalar(key, value, "any"))
    if not isinstance(value, (list, tuple)):
        form = "a list of rows" if kind == "matrix" else "a list of numbers"
        raise BlockError(key, f"must be {form} (got {type(value).__name__})", str(value)[:40])
    rows = [list(r) if isinstance(r, (list, tuple)) else r for r in value]
    nested = [isinstance(r, list) for r in rows]
    if kind == "matrix" and all(nested) and rows:
        if len({len(r) for r in rows}) > 1:
            raise BlockError(key, "rows must have the same length", str(len(rows[-1])))
        flat = [x for r in rows for x in r]
        shape = (len(rows), len(rows[0]))
    elif any(nested):
        raise BlockError(key, "must be a list of numbers", str(value)[:40])
    else:
        flat, shape = rows, (len(rows),)
    for i, x in enumerate(flat):
        _scalar(f"{key}[{i}]", x, "any")
    return np.array(flat, dtype=float).reshape(shape)


def _read_params(block: Block, raw: Mapping) -> dict:
    """Read the block's param values from a module's ``params`` (defaults filled in)."""
    known = {p.name: p for p in block.params}
    for name in raw:
        if name not in known:
            own = ", ".join(known)
            raise BlockError(
                f"params.{name}", f"unknown param of block '{block.name}' (its params: {own})",
                str(name),
            )  # fmt: skip
    values: dict = {}
    for p in block.params:
        key = f"params.{p.name}"
        if p.name not in raw or raw[p.name] is None:
            if p.default is None:
                raise BlockError(key, f"is required by block '{block.name}'", p.name)
            values[p.name] = p.default if p.kind == "scalar" else None
        elif p.kind == "scalar":
            values[p.name] = _scalar(key, raw[p.name], p.rule)
        else:
            values[p.name] = _array(key, raw[p.name], p.kind)
    return values


def _check_counts(block: Block, inputs: Sequence[str], outputs: Sequence[str]) -> None:
    if block.n_inputs is not None and len(inputs) != block.n_inputs:
        raise BlockError(
            "inputs", f"block '{block.name}' takes {block.n_inputs} input(s) (got {len(inputs)})",
            str(len(inputs)),
        )  # fmt: skip
    if block.name == "weighted_sum" and not inputs:
        raise BlockError("inputs", "block 'weighted_sum' takes at least one input", "0")
    allowed = block.n_outputs
    if (allowed is not None and len(outputs) not in allowed) or not outputs:
        counts = " or ".join(map(str, allowed)) if allowed else "at least 1"
        raise BlockError(
            "outputs", f"block '{block.name}' gives {counts} output(s) (got {len(outputs)})",
            str(len(outputs)),
        )  # fmt: skip


def lower_block(
    name: str, inputs: Sequence[str], outputs: Sequence[str], params: Mapping | None
) -> Lowered:
    """Return a block module lowered to states, params and expression texts.

    Parameters
    ----------
    name : str
        A key of :data:`BLOCKS`.
    inputs, outputs : sequence of str
        The module's signal names (already valid names).
    params : mapping or None
        The module's ``params`` entry: the block's own param names → numbers (lists for
        ``weights``, lists of rows for ``A``, ``B``, ``C``, ``D``).

    Returns
    -------
    Lowered

    Raises
    ------
    BlockError
        An unknown block, a wrong number of inputs or outputs, an unknown, missing or bad
        param, inconsistent matrix shapes, or an input named like one of the block's states
        or params; ``key`` names the entry.

    Examples
    --------
    >>> low = lower_block("mass_spring_damper", ["F"], ["x", "v"], {"m": 2, "c": 0.1, "k": 3})
    >>> low.derivatives["v"], low.output_states
    ('(F - c*v - k*x)/m', {'x': 'x', 'v': 'v'})
    """
    if name not in BLOCKS:
        known = ", ".join(BLOCKS)
        raise BlockError("block", f"unknown block '{name}' (blocks: {known})", str(name))
    block = BLOCKS[name]
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        raise BlockError(
            "params", f"must be a mapping of param names to numbers (got "
            f"{type(params).__name__} {params!r:.40})", str(params)[:40],
        )  # fmt: skip
    _check_counts(block, inputs, outputs)
    lowered = block.lower(tuple(inputs), tuple(outputs), _read_params(block, params))
    for signal in inputs:
        kind = "state" if signal in lowered.states else "param" if signal in lowered.params else ""
        if kind:
            raise BlockError(
                "inputs", f"'{signal}' is also the name of a {kind} of block '{name}' "
                "(rename the signal)", signal,
            )  # fmt: skip
    return lowered
