"""Intervals of a proportion ``k / n``: how often a claim held, how often the diagnoser was right.

The claims across random draws and sweep replicates (:mod:`dtwin.claims`, Fig. 12) and the gap
benchmark's scores all report a share of successes with its Wilson score interval; this module
is its one implementation.
"""

from __future__ import annotations

import math
import operator

from scipy.special import ndtri  # scipy.stats.norm.ppf's own kernel, without loading scipy.stats

from dtwin._validation import DtwinValueError

__all__ = ["wilson_interval"]


def _count(name: str, value: object) -> int:
    """Return ``value`` as a Python int (numpy integers included); bools and floats are errors."""
    if isinstance(value, bool):
        raise DtwinValueError(f"{name} must be an integer (got {value!r})")
    try:
        return operator.index(value)
    except TypeError:
        raise DtwinValueError(f"{name} must be an integer (got {value!r})") from None


def wilson_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Return the Wilson score interval of the proportion ``k / n``.

    Parameters
    ----------
    k : int
        Successes, ``0 <= k <= n`` (numpy integers are accepted).
    n : int
        Trials, ``n >= 0``.
    level : float, default 0.95
        Coverage of the interval, in (0, 1).

    Returns
    -------
    (low, high) : tuple of float
        ``(p̂ + z²/2n ∓ z·sqrt(p̂(1−p̂)/n + z²/4n²)) / (1 + z²/n)`` with ``p̂ = k/n`` and ``z``
        the ``(1 + level)/2`` normal quantile (Wilson 1927), clipped to [0, 1] and widened to
        hold ``p̂`` (at ``k = 0`` or ``k = n`` round-off can leave a bound 1e-17 past it).
        ``(nan, nan)`` when ``n = 0``: a share of no trials has no interval.

    Raises
    ------
    DtwinValueError
        If ``k`` or ``n`` is not an integer, ``n < 0``, ``k`` is outside ``[0, n]`` or
        ``level`` outside (0, 1).

    Notes
    -----
    ``z`` comes from :func:`scipy.special.ndtri`, the kernel of ``scipy.stats.norm.ppf``;
    the bounds agree with ``statsmodels.stats.proportion.proportion_confint(method="wilson")``
    within 1e-15.

    Examples
    --------
    >>> [round(v, 4) for v in wilson_interval(8, 10)]
    [0.4902, 0.9433]
    >>> wilson_interval(0, 0)
    (nan, nan)
    """
    n = _count("n", n)
    k = _count("k", k)
    if n < 0:
        raise DtwinValueError(f"n must be an integer >= 0 (got {n!r})")
    if not 0 <= k <= n:
        raise DtwinValueError(f"k must be an integer in [0, n={n}] (got {k!r})")
    if not 0 < level < 1:
        raise DtwinValueError(f"level must be in (0, 1) (got {level!r})")
    if n == 0:
        return math.nan, math.nan
    z = float(ndtri(0.5 + level / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return min(max(0.0, centre - half), p), max(min(1.0, centre + half), p)
