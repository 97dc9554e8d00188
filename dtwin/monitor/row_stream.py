"""A live stream of recording rows, read as it comes and refused row by row when it is hostile.

Specification: docs/monitor.md §Streams. Rows are CSV lines: a header naming the columns (``t``
and the twin's signals, in any order, other columns ignored), then one line per sample. A
header may come again (a file rotated, streams joined): the columns are then re-read. Every
line that cannot be used is **refused** with a reason, reported (:class:`StreamEvent`) and
counted, never dropped silently:

``no_header`` (a row before any header), ``missing_column`` (the current header lacks a signal
the twin reads), ``malformed`` (another number of fields than the header's), ``missing_value``
(an empty field or ``nan``), ``non_numeric``, ``non_finite`` (``inf``), ``out_of_range`` (beyond
the signal's admitted range), ``duplicate_time`` (the time of the previous row),
``backward_time`` (earlier than it), ``empty`` (a blank line).

A row later than one period after the previous one is used: up to ``max_gap`` missing samples
are bridged (``time_gap``: the twin runs through them, the filter predicts), a longer jump
restarts the monitor (``time_jump``: a new settling period). :class:`LineSource` reads standard
input or follows a file being appended, reopening it when it is replaced or truncated
(rotation), and returns what is available in one piece.
"""

from __future__ import annotations

import codecs
import io
import math
import os
import select
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "REASONS",
    "StreamEvent",
    "ParsedRows",
    "RowParser",
    "LineSource",
]

#: Reasons a row is refused.
REASONS: tuple[str, ...] = (
    "no_header", "missing_column", "malformed", "missing_value", "non_numeric", "non_finite",
    "out_of_range", "duplicate_time", "backward_time", "empty",
)  # fmt: skip
#: Largest deviation of a row's time from the sample grid that is still on it, in periods.
GRID_TOLERANCE = 0.25
#: Pieces of at least this many lines are parsed by pandas' C parser.
PANDAS_LINES = 256
_MISSING = {"", "nan", "na", "null", "none"}


@dataclass(frozen=True)
class StreamEvent:
    """Something the stream did: a refused row, a header, a gap or a jump (for standard error).

    ``row`` counts the stream's lines from 1 (headers included).
    """

    kind: str
    row: int
    detail: str = ""
    line: str = ""

    def to_mapping(self) -> dict[str, Any]:
        """Return the event as one JSON object's fields."""
        out: dict[str, Any] = {"event": self.kind, "row": self.row}
        if self.detail:
            out["detail"] = self.detail
        if self.line:
            out["line"] = self.line[:120]
        return out


@dataclass
class ParsedRows:
    """Usable rows of a piece of the stream, in order.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Time, s.
    values : ndarray, shape (m, n_columns)
        The twin's signals, in the parser's ``columns`` order.
    gap : ndarray of int, shape (m,)
        Samples missing just before each row (bridged).
    restart : ndarray of bool, shape (m,)
        A jump in time just before the row: the monitor restarts there.
    events : list of StreamEvent
    """

    t: np.ndarray
    values: np.ndarray
    gap: np.ndarray
    restart: np.ndarray
    events: list[StreamEvent] = field(default_factory=list)


class RowParser:
    """Turn lines into usable rows (module docstring), keeping the header and the last time.

    Parameters
    ----------
    columns : sequence of str
        The signals a row must carry (besides ``t``), in the order of ``ParsedRows.values``.
    dt : float
        Sample period, s.
    max_gap : int
        Most missing samples bridged; a longer jump restarts.
    header : sequence of str, optional
        The columns of a stream without a header line.
    ranges : mapping of str to (float, float), optional
        Each signal's admitted range; a value beyond it is refused (``out_of_range``).
    """

    def __init__(self, columns: Sequence[str], dt: float, max_gap: int, header=None, ranges=None):
        self.columns, self.dt, self.max_gap = tuple(columns), float(dt), int(max_gap)
        bounds = [(ranges or {}).get(c, (-np.inf, np.inf)) for c in self.columns]
        self.low = np.array([b[0] for b in bounds], dtype=float)
        self.high = np.array([b[1] for b in bounds], dtype=float)
        self.counts: Counter[str] = Counter()
        self.rows_read = self.headers = self.line_number = 0
        self.last_t: float | None = None
        self.width = 0
        self.index: np.ndarray | None = None
        self.missing: tuple[str, ...] = ()
        if header is not None:
            self._set_header([str(c).strip() for c in header], 0, [])

    def _set_header(self, names: list[str], row: int, events: list[StreamEvent]) -> None:
        self.headers += 1
        self.width = len(names)
        self.missing = tuple(c for c in ("t", *self.columns) if c not in names)
        if self.missing:
            self.index = None
            events.append(StreamEvent("missing_column", row, ", ".join(self.missing)))
        else:
            self.index = np.array([names.index(c) for c in ("t", *self.columns)])
            if self.headers > 1:  # the first header is the stream's own: no event
                events.append(StreamEvent("header", row, ", ".join(names)))

    def _is_header(self, fields: list[str]) -> bool:
        """Return whether a line is a header: names with ``t``, or a first line of text."""
        names = [f.strip() for f in fields]
        if "t" in names and not any(_is_number(name) for name in names):
            return True
        first = names[0].lower()
        return self.index is None and first not in _MISSING and not _is_number(first)

    def parse(self, lines: Sequence[str]) -> ParsedRows:
        """Parse the next lines (without their line ends); return the usable rows."""
        events: list[StreamEvent] = []
        fast = self._fast(lines)
        if fast is not None:
            return fast
        times, rows, gaps, restarts = [], [], [], []
        for line in lines:
            self.line_number += 1
            row = self._row(line, events)
            if row is None:
                continue
            placed = self._place(row[0], line, events)
            if placed is None:
                continue
            times.append(row[0])
            rows.append(row[1:])
            gaps.append(placed[0])
            restarts.append(placed[1])
        return ParsedRows(
            np.array(times, dtype=float),
            np.array(rows, dtype=float).reshape(len(rows), len(self.columns)),
            np.array(gaps, dtype=np.int64),
            np.array(restarts, dtype=bool),
            events,
        )

    def _refuse(self, reason: str, line: str, events: list[StreamEvent], detail: str = "") -> None:
        self.counts[reason] += 1
        events.append(StreamEvent(reason, self.line_number, detail, line))

    def _row(self, line: str, events: list[StreamEvent]) -> list[float] | None:
        """Return the row's ``t`` and signals as floats, or None (refused, or a header)."""
        if not line.strip():
            self.rows_read += 1
            self._refuse("empty", line, events)
            return None
        fields = line.split(",")
        if self._is_header(fields):
            self._set_header([f.strip() for f in fields], self.line_number, events)
            return None
        self.rows_read += 1
        if self.index is None:
            reason = "missing_column" if self.headers else "no_header"
            self._refuse(reason, line, events, ", ".join(self.missing))
            return None
        if len(fields) != self.width:
            self._refuse("malformed", line, events, f"{len(fields)} fields, header {self.width}")
            return None
        values = []
        for name, position in zip(("t", *self.columns), self.index.tolist(), strict=True):
            text = fields[position].strip()
            if text.lower() in _MISSING:
                self._refuse("missing_value", line, events, name)
                return None
            try:
                value = float(text)
            except ValueError:
                self._refuse("non_numeric", line, events, f"{name} = {text[:20]!r}")
                return None
            if not math.isfinite(value):
                self._refuse("non_finite", line, events, name)
                return None
            values.append(value)
        signals = np.array(values[1:])
        outside = np.flatnonzero((signals < self.low) | (signals > self.high))
        if outside.size:
            name = self.columns[outside[0]]
            self._refuse("out_of_range", line, events, f"{name} = {float(signals[outside[0]])!r}")
            return None
        return values

    def _place(self, t: float, line: str, events) -> tuple[int, bool] | None:
        """``(missing samples before, restart)`` of a row at time ``t``, or None (refused)."""
        last = self.last_t
        if last is None:
            self.last_t = t
            return 0, True
        steps = (t - last) / self.dt
        if abs(steps) <= GRID_TOLERANCE:
            self._refuse("duplicate_time", line, events, f"t = {t!r}")
            return None
        if steps < 0:
            self._refuse("backward_time", line, events, f"t = {t!r} after {last!r}")
            return None
        self.last_t = t
        missing = max(int(round(steps)) - 1, 0)
        if missing > self.max_gap:
            events.append(StreamEvent("time_jump", self.line_number, f"{missing} samples"))
            return 0, True
        if missing:
            events.append(StreamEvent("time_gap", self.line_number, f"{missing} samples"))
        return missing, False

    def _fast(self, lines: Sequence[str]) -> ParsedRows | None:
        """Every line a plain row on the grid after the previous one: parse them at once."""
        if self.index is None or not lines or self.last_t is None:
            return None
        table = _numbers(lines, self.width)
        if table is None:
            return None
        table = table[:, self.index]
        t = table[:, 0]
        steps = np.empty(len(t))
        steps[0] = t[0] - self.last_t
        np.subtract(t[1:], t[:-1], out=steps[1:])
        steps /= self.dt
        if not np.isfinite(table).all() or (np.abs(steps - 1.0) > GRID_TOLERANCE).any():
            return None
        signals = table[:, 1:]
        if (signals < self.low).any() or (signals > self.high).any():
            return None
        self.line_number += len(lines)
        self.rows_read += len(lines)
        self.last_t = float(table[-1, 0])
        n = len(table)
        return ParsedRows(
            table[:, 0], table[:, 1:], np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
        )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _numbers(lines: Sequence[str], width: int) -> np.ndarray | None:
    """Return the lines as a float table (n, width), or None if one is not plain numbers.

    Long pieces go through pandas' C parser (the same correctly rounded values as ``float``);
    a field that is not a number, a line of another width or a blank line gives None.
    """
    if len(lines) >= PANDAS_LINES:
        import pandas as pd

        try:
            table = pd.read_csv(io.StringIO("\n".join(lines)), header=None, dtype=float,
                                skip_blank_lines=False,
                                engine="c").to_numpy()  # fmt: skip
        except (ValueError, pd.errors.ParserError):
            return None
    else:
        try:
            table = np.array([line.split(",") for line in lines], dtype=float)
        except ValueError:
            return None
    if table.ndim != 2 or table.shape != (len(lines), width):
        return None
    return table


class LineSource:
    """Lines from standard input or a followed file, in pieces of what is available.

    Parameters
    ----------
    stream : text stream, optional
        Read until its end (standard input).
    follow : path, optional
        A file being appended: read to its end, then wait for more; reopened from its start
        when it is replaced (another inode) or truncated. Ends only on an interrupt.
    poll : float
        Seconds between looks at a followed file, and the longest wait for input before
        :meth:`pieces` yields an empty piece (so background work is looked after).
    max_lines : int
        Most lines of one piece.
    """

    def __init__(
        self, stream: IO[str] | None = None, follow: str | os.PathLike | None = None,
        poll: float = 0.1, max_lines: int = 8192,
    ):  # fmt: skip
        self.stream, self.path = stream, None if follow is None else Path(follow)
        self.poll, self.max_lines = poll, max_lines
        self.partial = ""
        self.decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        self.handle = None
        self.inode = None
        self.rotations = 0

    def pieces(self):
        """Yield lists of complete lines (an empty list when nothing came within ``poll``)."""
        while True:
            text = self._read()
            if text is None:
                if self.partial:
                    yield [self.partial]
                    self.partial = ""
                return
            text = self.partial + text
            lines = text.split("\n")
            self.partial = lines.pop()
            lines = [line.rstrip("\r") for line in lines]
            for first in range(0, len(lines), self.max_lines):
                yield lines[first : first + self.max_lines]
            if not lines:
                yield []

    def _read(self) -> str | None:
        """Return what is available now ('' after ``poll`` s), or None at the end of input."""
        if self.path is not None:
            return self._read_followed()
        try:
            fd = self.stream.fileno()
        except (AttributeError, OSError, ValueError):
            fd = None  # an in-memory stream
        if fd is None:
            text = self.stream.read(1 << 16)
            return text or None
        ready, _, _ = select.select([fd], [], [], self.poll)
        if not ready:
            return ""
        data = os.read(fd, 1 << 16)
        if not data:
            return self.decoder.decode(b"", final=True) or None
        return self.decoder.decode(data)  # a character cut between reads waits for its rest

    def _read_followed(self) -> str:
        if self.handle is None:
            if not self.path.exists():
                time.sleep(self.poll)
                return ""
            self.handle = open(self.path, encoding="utf-8", errors="replace")  # noqa: SIM115
            self.inode = os.fstat(self.handle.fileno()).st_ino
        text = self.handle.read(1 << 16)
        if text:
            return text
        if self._rotated():
            self.handle.close()
            self.handle, self.rotations = None, self.rotations + 1
            return "\n" if self.partial else ""
        time.sleep(self.poll)
        return ""

    def _rotated(self) -> bool:
        try:
            now = os.stat(self.path)
        except FileNotFoundError:
            return False
        return now.st_ino != self.inode or now.st_size < self.handle.tell()
