"""Recordings of the asset: load and validate a ``RECORDING.csv`` for the gap diagnoser.

Specification: docs/gap.md §Recording format and §Bad input.

A recording has a header row, then one row per sample: column ``t`` (seconds, uniform step) and
any of the module signals of :data:`dtwin.wiring.SIGNALS` (``u_cmd, u_act, x, v, y_A, y_B,
y_fused, z``). Columns with other names are ignored (and listed in the report). Arrays are
time-first, shape ``(n_samples,)``.

Row numbers in error messages count data rows from 1 (the header is not a row), so row ``r``
is line ``r + 1`` of the file.
"""

from __future__ import annotations

import io
import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.wiring import MODULES, SIGNALS

__all__ = [
    "MIN_SAMPLES",
    "STEP_TOLERANCE",
    "Recording",
    "read_recording",
    "recording_from_frame",
    "diagnosable_modules",
]

logger = logging.getLogger(__name__)

#: Fewest samples a recording may have.
MIN_SAMPLES = 200
#: Largest allowed deviation of one time step from dt, as a fraction of dt (rounding aside).
STEP_TOLERANCE = 0.01
_MAX_ROWS_LISTED = 5


@dataclass(frozen=True)
class Recording:
    """A validated recording.

    Attributes
    ----------
    t : numpy.ndarray, shape (n_samples,)
        Time stamps, s.
    dt : float
        Sample period, s: ``(t[-1] − t[0]) / (n_samples − 1)`` (robust to rounded stamps).
    signals : dict of str to numpy.ndarray
        The module signals present, each shape ``(n_samples,)``, in the recording's units.
    ignored : tuple of str
        Columns that are not module signals.
    time_resolution : float
        Rounding step of the printed time stamps (0 when unknown), s.
    """

    t: np.ndarray
    dt: float
    signals: dict[str, np.ndarray] = field(repr=False)
    ignored: tuple[str, ...] = ()
    time_resolution: float = 0.0

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return len(self.t)

    def has(self, *names: str) -> bool:
        """Return True if every signal in ``names`` is present."""
        return all(name in self.signals for name in names)


def _rows(mask: np.ndarray) -> str:
    rows = np.flatnonzero(mask) + 1
    listed = ", ".join(str(r) for r in rows[:_MAX_ROWS_LISTED])
    more = f" and {len(rows) - _MAX_ROWS_LISTED} more" if len(rows) > _MAX_ROWS_LISTED else ""
    return f"row{'s' if len(rows) > 1 else ''} {listed}{more}"


def _decimals(text: str) -> int:
    text = text.strip().lower()
    mantissa, _, exponent = text.partition("e")
    decimals = len(mantissa.partition(".")[2])
    try:
        return decimals - int(exponent) if exponent else decimals
    except ValueError:
        return decimals


def _time_resolution(raw: pd.Series) -> float:
    """Return the rounding step implied by the printed time stamps (0 if they are not text)."""
    if pd.api.types.is_numeric_dtype(raw):
        return 0.0
    decimals = max((_decimals(str(value)) for value in raw.iloc[: min(len(raw), 2000)]), default=0)
    return 10.0 ** (-decimals) if decimals < 15 else 0.0


def _numeric_column(name: str, raw: pd.Series) -> np.ndarray:
    values = pd.to_numeric(raw, errors="coerce")
    text_bad = values.isna().to_numpy() & raw.notna().to_numpy()
    if not pd.api.types.is_numeric_dtype(raw):
        stripped = raw.astype(str).str.strip().str.lower()
        text_bad &= ~stripped.isin(["nan", "inf", "-inf", "+inf", "infinity", "-infinity", ""])
    if text_bad.any():
        first = raw[text_bad].iloc[0]
        raise DtwinValueError(
            f"recording column '{name}' must be numeric (got {first!r} at {_rows(text_bad)})"
        )
    array = values.to_numpy(dtype=float)
    bad = ~np.isfinite(array)
    if bad.any():
        raise DtwinValueError(
            f"recording column '{name}' must be finite (got NaN/inf at {_rows(bad)})"
        )
    return array


def _check_time(t: np.ndarray, resolution: float) -> float:
    steps = np.diff(t)
    back = steps <= 0
    if back.any():
        row = int(np.flatnonzero(back)[0]) + 2
        raise DtwinValueError(
            f"recording column 't' must increase (got {float(t[row - 2])!r} then "
            f"{float(t[row - 1])!r} at row {row})"
        )
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    eps = 1e-12 * abs(t).max()
    # rounded stamps: a step may be off by one rounding step, a stamp (dt fitted) by one too
    off_step = np.abs(steps - dt) > STEP_TOLERANCE * dt + resolution * (1.0 + 1e-9) + eps
    grid_error = np.abs(t - (t[0] + dt * np.arange(len(t))))
    off_grid = grid_error > STEP_TOLERANCE * dt + resolution * (1.0 + 1e-9) + eps
    if off_step.any() or off_grid.any():
        if off_step.any():
            row = int(np.argmax(np.abs(steps - dt))) + 2
        else:
            row = max(2, int(np.argmax(grid_error)) + 1)
        raise DtwinValueError(
            f"recording column 't' must have a uniform step (dt = {dt:.6g} s): steps vary by "
            f"more than 1 % of dt beyond the stamps' rounding (got a step of "
            f"{steps[row - 2]:.6g} s at row {row})"
        )
    return dt


def recording_from_frame(frame: pd.DataFrame) -> Recording:
    """Return a validated :class:`Recording` from a table with column ``t`` and module signals.

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per sample. Values may be text (as read from CSV with ``dtype=str``) so that the
        rounding of the time stamps can be recognised.

    Raises
    ------
    DtwinValueError
        On a missing ``t`` or no diagnosable module, a non-numeric or non-finite value (rows
        named), a decreasing or non-uniform ``t``, or fewer than :data:`MIN_SAMPLES` samples.

    Examples
    --------
    >>> t = np.arange(300) * 0.02
    >>> rec = recording_from_frame(pd.DataFrame({"t": t, "u_act": np.sin(t), "x": np.cos(t)}))
    >>> rec.n_samples, round(rec.dt, 6), sorted(rec.signals)
    (300, 0.02, ['u_act', 'x'])
    """
    frame = frame.rename(columns=lambda name: str(name).strip())
    duplicated = sorted({c for c in frame.columns if list(frame.columns).count(c) > 1})
    if duplicated:
        raise DtwinValueError(f"recording has duplicate column(s): {', '.join(duplicated)}")
    if "t" not in frame.columns:
        raise DtwinValueError(
            f"recording is missing column 't' (got columns: {', '.join(frame.columns) or 'none'})"
        )
    present = [name for name in SIGNALS if name in frame.columns]
    if len(frame) < MIN_SAMPLES:
        raise DtwinValueError(
            f"recording must have at least {MIN_SAMPLES} samples (got {len(frame)})"
        )
    ignored = tuple(c for c in frame.columns if c != "t" and c not in SIGNALS)
    signals = {name: _numeric_column(name, frame[name]) for name in present}
    modules = diagnosable_modules(signals)
    if not modules:
        needs = "; ".join(f"{m.name}: {', '.join(m.inputs)} -> {m.output}" for m in MODULES)
        raise DtwinValueError(
            "recording has no module whose input and output columns are both present "
            f"(got: {', '.join(present) or 'none'}; needs one of {needs})"
        )
    resolution = _time_resolution(frame["t"])
    t = _numeric_column("t", frame["t"])
    dt = _check_time(t, resolution)
    if ignored:
        logger.info("ignoring recording columns that are not module signals: %s", ignored)
    return Recording(t=t, dt=dt, signals=signals, ignored=ignored, time_resolution=resolution)


def read_recording(source: str | os.PathLike | io.TextIOBase) -> Recording:
    """Read ``RECORDING.csv`` and return a validated :class:`Recording`.

    Parameters
    ----------
    source : path or text stream
        A CSV file with a header row (see the module docstring).

    Raises
    ------
    DtwinValueError
        If the file cannot be read or parsed, or on any check of :func:`recording_from_frame`.
    """
    try:
        frame = pd.read_csv(source, dtype=str, skipinitialspace=True, keep_default_na=False)
    except FileNotFoundError as error:
        raise DtwinValueError(f"recording file not found: {source}") from error
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        first_line = str(error).strip().splitlines()[0] if str(error).strip() else "empty file"
        raise DtwinValueError(f"recording could not be parsed as CSV: {first_line}") from error
    frame = frame.replace({"": np.nan})
    return recording_from_frame(frame)


def diagnosable_modules(signals: Mapping[str, np.ndarray]) -> list[str]:
    """Return the names of the modules whose input and output signals are all present.

    M4 needs ``x`` and ``z``; its input ``v`` is optional (the twin's own definition
    ``v_k = (x_{k+1} − x_k)/dt`` of the Euler plant replaces it).
    """
    names = []
    for module in MODULES:
        inputs = [s for s in module.inputs if not (module.name == "M4" and s == "v")]
        if all(s in signals for s in inputs) and module.output in signals:
            names.append(module.name)
    return names
