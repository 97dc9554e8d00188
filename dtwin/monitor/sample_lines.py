"""The monitor's sample lines written by a compiled loop, the same text as Python's ``%``.

Specification: docs/monitor.md §dtwin monitor. A sample line is a ``%`` template (``%r`` for
the time, ``%s`` for a label, ``%.<p>g`` for a number): :class:`LineTemplate` splits it once
into literal pieces and fields, and :meth:`LineTemplate.render` writes many rows at once with
:func:`dtwin.monitor._stream_kernels.write_lines`, which writes each number digit for digit as
Python does (correctly rounded digits from double-double arithmetic, Python's layout rules). A
row holding a number that loop leaves undecided (a rounding tie or too close to one, a
magnitude beyond 1e±250, a non-finite value; rare) is written by ``template % values``
itself, as are fewer than :data:`FEWEST_COMPILED` rows and every row without numba. So the
text is always ``template % values``.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from dtwin._jit import HAVE_NUMBA
from dtwin._validation import DtwinValueError
from dtwin.monitor._stream_kernels import FIELD_G, FIELD_REPR, FIELD_TEXT, write_lines

__all__ = ["LineTemplate", "powers_of_ten", "FEWEST_COMPILED", "POWER_RANGE"]

#: A field of a template: ``%r``, ``%s`` or ``%.<p>g``.
_FIELD = re.compile(r"%(?:(r)|(s)|\.(\d+)g)")
#: Powers of ten held as double-doubles: ``10^k`` for ``|k| ≤`` this.
POWER_RANGE = 300
#: Fewest rows written by the compiled loop: calling it costs about 10 µs, Python's ``%`` 10 µs a
#: row (a live stream's one line is Python's).
FEWEST_COMPILED = 4


@functools.cache
def powers_of_ten(k_max: int = POWER_RANGE) -> np.ndarray:
    """Return ``10^k`` for ``k = −k_max … k_max`` as (high, low) double pairs, shape (2·k_max+1, 2).

    ``high`` is ``10^k`` correctly rounded and ``low`` the rest correctly rounded (exact
    rational arithmetic), so ``high + low`` is ``10^k`` to about 1e-32 relative. Read-only.
    """
    out = np.empty((2 * k_max + 1, 2))
    for k in range(-k_max, k_max + 1):
        exact = Fraction(10) ** k
        high = float(exact)
        out[k + k_max] = high, float(exact - Fraction(high))
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class LineTemplate:
    """A ``%`` template split into literal pieces and fields.

    Attributes
    ----------
    template : str
        The template: only ``%r`` (floats), ``%s`` (texts) and ``%.<p>g`` (floats, ``p ≤ 17``)
        fields.
    texts : tuple of str
        The texts a ``%s`` field may take (a row names them by index).
    """

    template: str
    texts: tuple[str, ...]

    def __post_init__(self) -> None:
        pieces, kinds, precisions = [], [], []
        last = 0
        for match in _FIELD.finditer(self.template):
            pieces.append(self.template[last : match.start()])
            last = match.end()
            shortest, text, precision = match.groups()
            kinds.append(FIELD_REPR if shortest else FIELD_TEXT if text else FIELD_G)
            precisions.append(int(precision) if precision else 0)
            if precision and not 1 <= int(precision) <= 17:
                raise DtwinValueError(
                    f"template field {match.group(0)} must have 1 to 17 digits (got {precision})"
                )
        pieces.append(self.template[last:])
        if any("%" in piece for piece in pieces):
            raise DtwinValueError(f"template holds a field other than %r, %s, %.<p>g: "
                                  f"{self.template!r}")  # fmt: skip
        encoded = [piece.encode() for piece in pieces]
        names = [text.encode() for text in self.texts]
        set_ = object.__setattr__
        set_(self, "_kinds", np.array(kinds, dtype=np.int64))
        set_(self, "_precisions", np.array(precisions, dtype=np.int64))
        set_(self, "_literals", np.frombuffer(b"".join(encoded), dtype=np.uint8).copy())
        set_(self, "_literal_ends", np.cumsum([len(b) for b in encoded], dtype=np.int64))
        set_(self, "_texts", np.frombuffer(b"".join(names), dtype=np.uint8).copy())
        set_(self, "_text_ends", np.cumsum([len(b) for b in names], dtype=np.int64))
        set_(self, "_powers", powers_of_ten() if HAVE_NUMBA else None)

    @property
    def n_floats(self) -> int:
        """Number of float fields (``%r`` and ``%.<p>g``)."""
        return int(np.sum(self._kinds != FIELD_TEXT))

    def render(self, floats: np.ndarray, choices: np.ndarray) -> str:
        """Return ``template % values`` for every row, one after the other.

        Parameters
        ----------
        floats : numpy.ndarray, shape (n, n_floats)
            Each row's float fields in template order.
        choices : numpy.ndarray of int, shape (n, n_text_fields)
            Each row's ``%s`` fields in template order, as indices into :attr:`texts`.
        """
        floats = np.ascontiguousarray(floats, dtype=np.float64)
        choices = np.ascontiguousarray(choices, dtype=np.int64).reshape(len(floats), -1)
        if not HAVE_NUMBA or len(floats) < FEWEST_COMPILED:
            return "".join(self._python(floats, choices, range(len(floats))))
        text, ends, written = write_lines(
            floats, choices, self._kinds, self._precisions, self._literals, self._literal_ends,
            self._texts, self._text_ends, self._powers,
        )  # fmt: skip
        if written.all():
            return text.tobytes().decode()
        missing = np.flatnonzero(~written)
        parts, start = [], 0
        for row, line in zip(missing.tolist(), self._python(floats, choices, missing), strict=True):
            parts += [text[start : ends[row]].tobytes(), line.encode()]  # the rows before, it
            start = ends[row]
        parts.append(text[start:].tobytes())
        return b"".join(parts).decode()

    def _python(self, floats: np.ndarray, choices: np.ndarray, rows) -> list[str]:
        """Return the rows' lines written by ``template % values``."""
        out = []
        for row in rows:
            numbers, names = iter(floats[row].tolist()), iter(choices[row].tolist())
            values = [self.texts[next(names)] if kind == FIELD_TEXT else next(numbers)
                      for kind in self._kinds.tolist()]  # fmt: skip
            out.append(self.template % tuple(values))
        return out
