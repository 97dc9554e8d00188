"""Argument checks shared by the public functions of :mod:`dtwin`.

Every helper takes the argument's *name* so that messages read
"name, rule, observed value", e.g. ``twin.fusion.alpha must be in [0, 1] (got 1.3)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = [
    "DtwinValueError",
    "DtwinTypeError",
    "require_positive",
    "require_nonnegative",
    "require_in_range",
    "require_finite_array",
    "require_min_length",
    "require_mapping",
    "require_number",
    "require_seed",
]


class DtwinValueError(ValueError):
    """A value is malformed or out of range (subclasses :class:`ValueError`)."""


class DtwinTypeError(TypeError):
    """A value has the wrong type (subclasses :class:`TypeError`)."""


def require_number(name: str, value: Any) -> float:
    """Return ``value`` as a finite float or raise :class:`DtwinTypeError`/`DtwinValueError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise DtwinTypeError(f"{name} must be a number (got {type(value).__name__}: {value!r})")
    value = float(value)
    if not np.isfinite(value):
        raise DtwinValueError(f"{name} must be finite (got {value})")
    return value


def require_seed(name: str, value: Any) -> int:
    """Return ``value`` as a seed, an integer >= 0.

    An integral float such as ``11.0`` counts, as it does for JSON Schema's ``integer``.

    Examples
    --------
    >>> require_seed("simulation.seed", 11.0)
    11
    """
    number = require_number(name, value)
    if number < 0 or not number.is_integer():
        raise DtwinValueError(f"{name} must be an integer >= 0 (got {value!r})")
    return int(value)


def require_positive(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite number > 0."""
    value = require_number(name, value)
    if value <= 0:
        raise DtwinValueError(f"{name} must be > 0 (got {value})")
    return value


def require_nonnegative(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite number >= 0."""
    value = require_number(name, value)
    if value < 0:
        raise DtwinValueError(f"{name} must be >= 0 (got {value})")
    return value


def require_in_range(name: str, value: Any, low: float, high: float) -> float:
    """Return ``value`` as a float if ``low <= value <= high``."""
    value = require_number(name, value)
    if not low <= value <= high:
        raise DtwinValueError(f"{name} must be in [{low:g}, {high:g}] (got {value})")
    return value


def require_finite_array(name: str, values: Any, ndim: int | None = 1) -> np.ndarray:
    """Return ``values`` as a float array, checking its dimension and that it holds no NaN/inf."""
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise DtwinTypeError(f"{name} must be numeric (got {type(values).__name__})") from error
    if ndim is not None and array.ndim != ndim:
        raise DtwinValueError(f"{name} must be {ndim}-dimensional (got shape {array.shape})")
    bad = ~np.isfinite(array)
    if bad.any():
        first = int(np.flatnonzero(bad.ravel())[0])
        raise DtwinValueError(
            f"{name} must be finite (got {int(bad.sum())} NaN/inf values, "
            f"first at flat index {first})"
        )
    return array


def require_min_length(name: str, values: np.ndarray, minimum: int) -> None:
    """Raise :class:`DtwinValueError` if ``len(values) < minimum``."""
    if len(values) < minimum:
        raise DtwinValueError(f"{name} must have at least {minimum} samples (got {len(values)})")


def require_mapping(name: str, value: Any) -> Mapping:
    """Return ``value`` if it is a mapping (a dict-like YAML section)."""
    if not isinstance(value, Mapping):
        raise DtwinTypeError(f"{name} must be a mapping (got {type(value).__name__}: {value!r})")
    return value
