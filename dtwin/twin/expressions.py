"""A user's equation text as data: parsed against an allowlist, lowered to a postfix program.

Specification: docs/gap.md §Twin file (Expressions). An expression such as
``"a1*sqrt(max(h1, 0)) - a2*sqrt(max(h2, 0))"`` is parsed by :func:`ast.parse` (mode ``eval``)
and walked with an **allowlist**: numbers, declared names (the module's params, states and input
signals, and ``t``), ``+ - * / **``, unary ``-`` and ``+``, and calls of the functions in
:data:`FUNCTIONS` by name with positional arguments. Everything else — attributes, subscripts,
keywords, lambdas, comparisons, strings, imports, method calls — is refused with
:class:`ExpressionError` naming the token. Nothing is ever ``eval``-ed or ``exec``-ed.

The tree is lowered to a postfix program (:class:`Expression`: an ``(n_ops, 2)`` int64 array of
``(opcode, argument)`` and a float64 constant pool) that :mod:`dtwin.twin._kernels` runs in a
compiled loop and :meth:`Expression.evaluate` runs over numpy arrays. Bounds keep a hostile text
from hanging or exhausting memory: at most :data:`MAX_TEXT` characters, :data:`MAX_NODES` tree
nodes and :data:`MAX_DEPTH` levels of nesting; arithmetic is float64, so a tower of powers
overflows to ``inf`` (refused later as not finite) instead of building a huge integer.
"""

from __future__ import annotations

import ast
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field

import numpy as np

from dtwin._validation import DtwinValueError

__all__ = [
    "FUNCTIONS",
    "MAX_TEXT",
    "MAX_NODES",
    "MAX_DEPTH",
    "Expression",
    "ExpressionError",
    "parse_expression",
]

#: Longest expression text, characters.
MAX_TEXT = 2000
#: Most nodes of an expression's tree.
MAX_NODES = 500
#: Deepest nesting of an expression's tree.
MAX_DEPTH = 40

# Opcodes of the postfix program (dtwin.twin._kernels.run_program reads the same numbers).
OP_CONST, OP_VAR, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW, OP_NEG, OP_FUNC1, OP_FUNC2, OP_IPOW = (
    range(11)
)
#: Pop the top of the stack into slot ``arg`` (ends each assignment of a unit's program).
OP_STORE = 11
#: Functions of one argument, by their code in ``OP_FUNC1``.
UNARY_FUNCTIONS: tuple[str, ...] = (
    "sqrt",
    "exp",
    "log",
    "sin",
    "cos",
    "tan",
    "tanh",
    "abs",
    "sign",
)
#: Functions of two arguments, by their code in ``OP_FUNC2``.
BINARY_FUNCTIONS: tuple[str, ...] = ("min", "max")
#: Every function an expression may call.
FUNCTIONS: frozenset[str] = frozenset(UNARY_FUNCTIONS + BINARY_FUNCTIONS)
#: Integer exponents lowered to repeated multiplication (``x**3`` is ``x*x*x``).
_INTEGER_POWERS = range(2, 5)

_BINARY_OPS = {ast.Add: OP_ADD, ast.Sub: OP_SUB, ast.Mult: OP_MUL, ast.Div: OP_DIV}
_NUMPY_UNARY = (np.sqrt, np.exp, np.log, np.sin, np.cos, np.tan, np.tanh, np.abs, np.sign)
_NUMPY_BINARY = (np.minimum, np.maximum)


class ExpressionError(DtwinValueError):
    """An expression text that is not in the allowed language; ``token`` names the culprit."""

    def __init__(self, message: str, token: str = "") -> None:
        super().__init__(message)
        self.token = token


@dataclass(frozen=True)
class Expression:
    """A parsed expression: its text, the names it reads and its postfix program.

    Attributes
    ----------
    text : str
        The text as written.
    names : tuple of str
        The declared names it reads, in order of first use; ``OP_VAR`` arguments index them.
    code : numpy.ndarray, shape (n_ops, 2), int64
        ``(opcode, argument)`` pairs in postfix order.
    consts : numpy.ndarray, shape (n_consts,), float64
        The constant pool (``OP_CONST`` arguments index it).
    depth : int
        The largest stack depth the program reaches.
    """

    text: str
    names: tuple[str, ...]
    code: np.ndarray = field(repr=False)
    consts: np.ndarray = field(repr=False)
    depth: int = 1

    def bound(self, slots: Mapping[str, int]) -> np.ndarray:
        """Return the program with ``OP_VAR`` arguments replaced by ``slots[name]``.

        Returns
        -------
        numpy.ndarray, shape (n_ops, 2), int64
        """
        code = self.code.copy()
        is_var = code[:, 0] == OP_VAR
        lookup = np.array([slots[name] for name in self.names], dtype=np.int64)
        if is_var.any():
            code[is_var, 1] = lookup[code[is_var, 1]]
        return code

    def evaluate(self, values: Mapping[str, float | np.ndarray]) -> float | np.ndarray:
        """Evaluate the program over numpy values (every name in :attr:`names` must be given).

        Examples
        --------
        >>> parse_expression("a*sqrt(max(h, 0)) - 2**3", ["a", "h"]).evaluate({"a": 2.0, "h": 9.0})
        -2.0
        """
        missing = [name for name in self.names if name not in values]
        if missing:
            raise DtwinValueError(f"expression '{self.text}' needs a value of {missing[0]}")
        with np.errstate(all="ignore"):
            return _evaluate(self, values)


def _evaluate(expr: Expression, values: Mapping[str, float | np.ndarray]):
    stack: list = []
    for op, arg in expr.code.tolist():
        if op == OP_CONST:
            stack.append(expr.consts[arg])
        elif op == OP_VAR:
            stack.append(np.asarray(values[expr.names[arg]], dtype=float))
        elif op == OP_NEG:
            stack.append(-stack.pop())
        elif op == OP_FUNC1:
            stack.append(_NUMPY_UNARY[arg](stack.pop()))
        elif op == OP_IPOW:
            base = stack.pop()
            result = base
            for _ in range(arg - 1):
                result = result * base
            stack.append(result)
        else:
            right, left = stack.pop(), stack.pop()
            stack.append(_binary(op, arg, left, right))
    result = stack.pop()
    return float(result) if np.ndim(result) == 0 else result


def _binary(op: int, arg: int, left, right):
    if op == OP_ADD:
        return left + right
    if op == OP_SUB:
        return left - right
    if op == OP_MUL:
        return left * right
    if op == OP_DIV:
        return np.divide(left, right)
    if op == OP_POW:
        return np.power(left, right)
    return _NUMPY_BINARY[arg](left, right)


class _Lowering:
    """Walk an allowed tree and emit its postfix program."""

    def __init__(self, symbols: Collection[str]) -> None:
        self.symbols = symbols
        self.names: list[str] = []
        self.consts: list[float] = []
        self.code: list[tuple[int, int]] = []
        self.nodes = 0

    def emit(self, node: ast.AST, depth: int) -> int:
        """Emit ``node``'s program; return the stack depth it needs."""
        self.nodes += 1
        if self.nodes > MAX_NODES or depth > MAX_DEPTH:
            limit = f"{MAX_NODES} nodes" if self.nodes > MAX_NODES else f"{MAX_DEPTH} levels"
            raise ExpressionError(
                f"expression is too large (more than {limit})",
                token=_token(node),
            )
        if isinstance(node, ast.Constant):
            return self._constant(node)
        if isinstance(node, ast.Name):
            return self._name(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            need = self.emit(node.operand, depth + 1)
            if isinstance(node.op, ast.USub):
                self.code.append((OP_NEG, 0))
            return need
        if isinstance(node, ast.BinOp) and type(node.op) in (*_BINARY_OPS, ast.Pow):
            return self._binop(node, depth)
        if isinstance(node, ast.Call):
            return self._call(node, depth)
        raise ExpressionError(f"'{_token(node)}' is not allowed in an expression", _token(node))

    def _constant(self, node: ast.Constant) -> int:
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ExpressionError(f"'{_token(node)}' is not a number", _token(node))
        number = float(value)
        if not np.isfinite(number):
            raise ExpressionError(f"'{_token(node)}' is not a finite number", _token(node))
        self.consts.append(number)
        self.code.append((OP_CONST, len(self.consts) - 1))
        return 1

    def _name(self, node: ast.Name) -> int:
        name = node.id
        if name in FUNCTIONS:
            raise ExpressionError(f"function '{name}' used as a value", name)
        if name not in self.symbols:
            raise ExpressionError(f"unknown name '{name}'", name)
        if name not in self.names:
            self.names.append(name)
        self.code.append((OP_VAR, self.names.index(name)))
        return 1

    def _binop(self, node: ast.BinOp, depth: int) -> int:
        exponent = _integer_exponent(node)
        left = self.emit(node.left, depth + 1)
        if exponent is not None:
            self.nodes += 1
            self.code.append((OP_IPOW, exponent))
            return left
        right = self.emit(node.right, depth + 1)
        op = OP_POW if isinstance(node.op, ast.Pow) else _BINARY_OPS[type(node.op)]
        self.code.append((op, 0))
        return max(left, right + 1)

    def _call(self, node: ast.Call, depth: int) -> int:
        if not isinstance(node.func, ast.Name):
            raise ExpressionError(
                f"'{_token(node.func)}' is not a function name", _token(node.func)
            )
        name = node.func.id
        if name not in FUNCTIONS:
            raise ExpressionError(f"unknown function '{name}'", name)
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"function '{name}' takes positional arguments only", name)
        arity = 1 if name in UNARY_FUNCTIONS else 2
        if len(node.args) != arity:
            raise ExpressionError(
                f"function '{name}' takes {arity} argument{'s' if arity > 1 else ''} "
                f"(got {len(node.args)})",
                name,
            )
        need = 0
        for position, argument in enumerate(node.args):
            need = max(need, position + self.emit(argument, depth + 1))
        if arity == 1:
            self.code.append((OP_FUNC1, UNARY_FUNCTIONS.index(name)))
        else:
            self.code.append((OP_FUNC2, BINARY_FUNCTIONS.index(name)))
        return need


def _integer_exponent(node: ast.BinOp) -> int | None:
    """Return n of ``x**n`` for a literal n in 2..4 (lowered to multiplication), else None."""
    if not isinstance(node.op, ast.Pow) or not isinstance(node.right, ast.Constant):
        return None
    value = node.right.value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return int(value) if float(value) in _INTEGER_POWERS else None


def _token(node: ast.AST) -> str:
    """Return the source text of a node, shortened, or its kind."""
    try:
        text = ast.unparse(node)
    except (ValueError, RecursionError):  # pragma: no cover - defensive
        text = type(node).__name__
    return text if len(text) <= 40 else text[:37] + "..."


def parse_expression(text: str, symbols: Collection[str]) -> Expression:
    """Parse an expression text against an allowlist and lower it to a postfix program.

    Parameters
    ----------
    text : str
        The expression, e.g. ``"q - a1*sqrt(max(h1, 0))"``.
    symbols : collection of str
        The names it may read (the module's params, states, inputs and ``t``).

    Returns
    -------
    Expression

    Raises
    ------
    ExpressionError
        On anything outside the language (the message names the token; ``error.token``), a
        syntax error, or a text longer than :data:`MAX_TEXT` or deeper than :data:`MAX_DEPTH`.

    Examples
    --------
    >>> expr = parse_expression("h2 + offset", ["h2", "offset"])
    >>> expr.names, expr.code.tolist()
    (('h2', 'offset'), [[1, 0], [1, 1], [2, 0]])
    >>> parse_expression("__import__('os')", ["h2"])
    Traceback (most recent call last):
    ...
    dtwin.twin.expressions.ExpressionError: unknown function '__import__'
    """
    if not isinstance(text, str) and isinstance(text, (int, float)) and not isinstance(text, bool):
        text = repr(float(text))
    if not isinstance(text, str):
        raise ExpressionError(f"expression must be text (got {type(text).__name__})", str(text))
    if len(text) > MAX_TEXT:
        raise ExpressionError(f"expression is longer than {MAX_TEXT} characters", text[:20])
    if not text.strip():
        raise ExpressionError("expression is empty", "")
    tree = _parse_tree(text)
    lowering = _Lowering(frozenset(symbols))
    depth = lowering.emit(tree.body, 1)
    return Expression(
        text=text,
        names=tuple(lowering.names),
        code=np.array(lowering.code, dtype=np.int64).reshape(-1, 2),
        consts=np.array(lowering.consts, dtype=np.float64),
        depth=depth,
    )


def _parse_tree(text: str) -> ast.Expression:
    """``ast.parse`` in eval mode, its failures as :class:`ExpressionError`."""
    if text.count("(") > MAX_DEPTH:
        raise ExpressionError(
            f"expression is too large (more than {MAX_DEPTH} levels of nesting)", "("
        )
    try:
        return ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        where = f" at character {error.offset}" if error.offset else ""
        token = (error.text or text).strip()[max((error.offset or 1) - 1, 0) :][:10]
        raise ExpressionError(f"syntax error{where} ('{token}')", token) from None
    except (ValueError, RecursionError, MemoryError) as error:
        raise ExpressionError(
            f"expression cannot be parsed ({type(error).__name__})", text[:20]
        ) from None
