"""Recordings of the asset: load and validate a ``RECORDING.csv`` for the gap diagnoser.

Specification: docs/gap.md §Recording format and §Bad input.

A recording has a header row, then one row per sample: column ``t`` (seconds, uniform step) and
any of the module signals of :data:`dtwin.twin.wiring.SIGNALS` (``u_cmd, u_act, x, v, y_A, y_B,
y_fused, z``). Columns with other names are ignored (and listed in the report). Arrays are
time-first, shape ``(n_samples,)``.

Row numbers in error messages count data rows from 1 (the header is not a row), so row ``r``
is line ``r + 1`` of the file.
"""

from __future__ import annotations

import io
import logging
import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.twin.wiring import MODULES, SIGNALS

__all__ = [
    "MIN_SAMPLES",
    "OUTLIER_GAP",
    "OUTLIER_QUANTILE",
    "MAX_MAGNITUDE",
    "STEP_TOLERANCE",
    "Recording",
    "read_recording",
    "recording_from_frame",
    "recording_with_columns",
    "DERIVED_INPUTS",
    "diagnosable_modules",
]

logger = logging.getLogger(__name__)

#: Fewest samples a recording may have.
MIN_SAMPLES = 200
#: Module inputs a recording may leave out, because the diagnoser derives them from another
#: column: the velocity ``v`` (which the KPI reads) from the position ``x``
#: (:func:`dtwin.gap.models.velocity_from_position`).
DERIVED_INPUTS: frozenset[str] = frozenset({"v"})
#: Largest allowed deviation of one time step from dt, as a fraction of dt (rounding aside).
STEP_TOLERANCE = 0.01
#: Outlier rule (docs/gap.md §Bad input): the bulk of a column is its values between the
#: ``OUTLIER_QUANTILE`` and ``1 − OUTLIER_QUANTILE`` quantiles, and its spread the width of that
#: range; values beyond an empty gap wider than ``OUTLIER_GAP`` spreads (on either side of the
#: bulk) are isolated outliers, and the recording is refused.
OUTLIER_QUANTILE = 0.01
#: Widest empty gap between the bulk of a column and its extreme values, in spreads of the bulk.
OUTLIER_GAP = 10.0
#: Largest magnitude a signal value may have (its square must stay far from float64 overflow).
MAX_MAGNITUDE = 1e100
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


def outlier_mask(values: np.ndarray) -> np.ndarray:
    """Return which samples of one column are isolated outliers (docs/gap.md §Bad input).

    Parameters
    ----------
    values : numpy.ndarray, shape (n_samples,)
        Finite values of one column.

    Returns
    -------
    numpy.ndarray of bool, shape (n_samples,)
        True where a value lies beyond an empty gap wider than :data:`OUTLIER_GAP` times the
        spread of the column's bulk (its central ``1 − 2·OUTLIER_QUANTILE`` of values). A spike
        is refused whatever its size once it clears that gap; steps, pulses and clipped stretches
        fill the range between their levels with at least 1 % of the samples (or with rising and
        falling edges) and are not outliers.

    Examples
    --------
    >>> x = np.sin(np.arange(300) / 10.0)
    >>> x[7] = 1e11
    >>> np.flatnonzero(outlier_mask(x))
    array([7])
    >>> bool(outlier_mask(np.sign(np.sin(np.arange(300) / 10.0))).any())
    False
    """
    with np.errstate(over="ignore", invalid="ignore"):
        low, high = np.quantile(values, [OUTLIER_QUANTILE, 1.0 - OUTLIER_QUANTILE])
        allowed = OUTLIER_GAP * (high - low)
        mask = np.zeros(len(values), dtype=bool)
        for sign, edge in ((1.0, high), (-1.0, low)):
            beyond = np.sort(sign * values[sign * values > sign * edge])
            if beyond.size == 0:
                continue
            gaps = np.diff(beyond, prepend=sign * edge)
            wide = np.flatnonzero(gaps > allowed)
            if wide.size:
                mask |= sign * values >= beyond[wide[0]]
    return mask


def _check_outliers(name: str, values: np.ndarray) -> None:
    huge = np.abs(values) > MAX_MAGNITUDE
    if huge.any():
        raise DtwinValueError(
            f"recording column '{name}' must have values within ±{MAX_MAGNITUDE:g} (got "
            f"{values[huge][0]:.3g} at {_rows(huge)})"
        )
    mask = outlier_mask(values)
    if not mask.any():
        return
    bulk = values[~mask]
    low, high = float(bulk.min()), float(bulk.max())
    spread = float(np.subtract(*np.quantile(values, [1.0 - OUTLIER_QUANTILE, OUTLIER_QUANTILE])))
    worst = values[mask][np.argmax(np.abs(values[mask] - np.median(values)))]
    distance = max(worst - high, low - worst)
    size = (
        f"{distance / spread:.2g}× the bulk's spread {spread:.3g}"
        if spread > 0
        else (f"the other values are all {low:.6g}")
    )
    count = int(mask.sum())
    raise DtwinValueError(
        f"recording column '{name}' has {count} isolated outlier{'s' if count > 1 else ''} "
        f"(worst {worst:.3g}, {size}) at {_rows(mask)}; values beyond a gap of {OUTLIER_GAP:g} "
        "spreads from the bulk are refused: remove or repair them"
    )


def _check_used_signals(signals: Mapping[str, np.ndarray], modules: list[str]) -> None:
    """Refuse outliers in any signal a diagnosable module uses, and a constant module output."""
    used = [m for m in MODULES if m.name in modules]
    names = {s for m in used for s in (*m.inputs, m.output) if s in signals}
    for name in (s for s in SIGNALS if s in names):
        _check_outliers(name, signals[name])
    for module in used:
        values = signals[module.output]
        if float(np.ptp(values)) <= 1e-12 * float(np.max(np.abs(values))):
            raise DtwinValueError(
                f"recording column '{module.output}' (output of {module.name}) must vary over "
                f"the recording (got the constant {values[0]:g}); a dead channel cannot be "
                "diagnosed"
            )


def _checked_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """Return ``frame`` with stripped column names, refusing duplicates, no ``t``, too few rows."""
    frame = frame.rename(columns=lambda name: str(name).strip())
    duplicated = sorted({c for c in frame.columns if list(frame.columns).count(c) > 1})
    if duplicated:
        raise DtwinValueError(f"recording has duplicate column(s): {', '.join(duplicated)}")
    if "t" not in frame.columns:
        raise DtwinValueError(
            f"recording is missing column 't' (got columns: {', '.join(frame.columns) or 'none'})"
        )
    if len(frame) < MIN_SAMPLES:
        raise DtwinValueError(
            f"recording must have at least {MIN_SAMPLES} samples (got {len(frame)})"
        )
    return frame


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
    frame = _checked_frame(frame)
    present = [name for name in SIGNALS if name in frame.columns]
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
    _check_used_signals(signals, modules)
    if ignored:
        logger.info("ignoring recording columns that are not module signals: %s", ignored)
    return Recording(t=t, dt=dt, signals=signals, ignored=ignored, time_resolution=resolution)


def recording_with_columns(frame: pd.DataFrame, wanted: Collection[str]) -> Recording:
    """Return a validated :class:`Recording` of the columns ``wanted`` (a twin table's signals).

    As :func:`recording_from_frame`, but the signals are the table's, not the paper chain's:
    every column of ``wanted`` present becomes a signal (checked for non-numeric, non-finite
    and outlying values), the others are ignored.
    """
    frame = _checked_frame(frame)
    present = [name for name in frame.columns if name in set(wanted)]
    ignored = tuple(c for c in frame.columns if c != "t" and c not in set(wanted))
    signals = {name: _numeric_column(name, frame[name]) for name in present}
    for name, values in signals.items():
        _check_outliers(name, values)
    resolution = _time_resolution(frame["t"])
    t = _numeric_column("t", frame["t"])
    dt = _check_time(t, resolution)
    return Recording(t=t, dt=dt, signals=signals, ignored=ignored, time_resolution=resolution)


def read_recording(
    source: str | os.PathLike | io.TextIOBase, columns: Collection[str] | None = None
) -> Recording:
    """Read ``RECORDING.csv`` and return a validated :class:`Recording`.

    Parameters
    ----------
    source : path or text stream
        A CSV file with a header row (see the module docstring).
    columns : collection of str, optional
        A twin table's signals (:func:`recording_with_columns`); default the paper chain's.

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
    if columns is not None:
        return recording_with_columns(frame, columns)
    return recording_from_frame(frame)


def diagnosable_modules(signals: Mapping[str, np.ndarray]) -> list[str]:
    """Return the names of the modules whose input and output signals are all present.

    M4 needs ``x`` and ``z``; its input ``v`` is optional (the twin's own definition
    ``v_k = (x_{k+1} − x_k)/dt`` of the Euler plant replaces it).
    """
    names = []
    for module in MODULES:
        inputs = [s for s in module.inputs if s not in DERIVED_INPUTS]
        if all(s in signals for s in inputs) and module.output in signals:
            names.append(module.name)
    return names
