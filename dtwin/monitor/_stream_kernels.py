"""The monitor's compiled loops: the regime filter, the novelty test, the sample lines' text.

:func:`filter_rows` is the normalised forward recursion of the regime HMM (paper Eq. (4)) over
a chunk of z-scored residual rows, continuing from the previous row's filtered vector; a row
with a missing value is a prediction step only. :func:`standardise_rows` and
:func:`cusum_rows` are the novelty test (:mod:`dtwin.monitor.novelty`): the rows standardised by
the nominal regimes' prediction, then the CUSUMs on their AR innovations. They give the same
bits whether a series is run in one call or in chunks (the stream and ``dtwin regimes`` run the
same code). :func:`write_lines` writes the sample lines (:mod:`dtwin.monitor.sample_lines`).
Without numba they run in Python (:mod:`dtwin._jit`). Arrays are time-first.
"""

from __future__ import annotations

import math

import numpy as np

from dtwin._jit import njit

__all__ = [
    "filter_rows",
    "standardise_rows",
    "cusum_rows",
    "write_lines",
    "FIELD_REPR",
    "FIELD_G",
    "FIELD_TEXT",
    "warm_up",
]

#: Kinds of a line's fields (:func:`write_lines`): ``%r`` of a float, ``%.<p>g``, ``%s``.
FIELD_REPR, FIELD_G, FIELD_TEXT = 0, 1, 2
#: Veltkamp's splitter 2^27 + 1 (an exact product of two doubles, :func:`_two_product`).
_SPLITTER = 134217729.0
#: The range of magnitudes written here; others are left to Python (undecided).
_SMALLEST, _LARGEST = 1e-250, 1e250


@njit(cache=True)
def _predict(alpha, transmat, propagate, predicted):  # pragma: no cover - compiled
    """``predicted = alpha @ transmat`` (or ``alpha`` itself when not ``propagate``)."""
    k = alpha.shape[0]
    for j in range(k):
        if not propagate:
            predicted[j] = alpha[j]
            continue
        total = 0.0
        for i in range(k):
            total += alpha[i] * transmat[i, j]
        predicted[j] = total


@njit(cache=True)
def _log_emissions(row, means, precision, log_norm, log_b) -> float:  # pragma: no cover
    """Fill ``log_b`` with each state's Gaussian log density of ``row``; return their maximum."""
    peak = -np.inf
    for j in range(means.shape[0]):
        quadratic = 0.0
        for c in range(row.shape[0]):
            gap = row[c] - means[j, c]
            quadratic += gap * gap * precision[j, c]
        log_b[j] = log_norm[j] - 0.5 * quadratic
        peak = max(peak, log_b[j])
    return peak


@njit(cache=True)
def _update(alpha, predicted, log_b, peak):  # pragma: no cover - compiled
    """``alpha ∝ predicted · exp(log_b − peak)``; the emissions alone if nothing is reachable."""
    k = alpha.shape[0]
    norm = 0.0
    for j in range(k):
        alpha[j] = predicted[j] * math.exp(log_b[j] - peak)
        norm += alpha[j]
    if not norm > 0.0:
        norm = 0.0
        for j in range(k):
            alpha[j] = math.exp(log_b[j] - peak)
            norm += alpha[j]
    for j in range(k):
        alpha[j] /= norm


@njit(cache=True)
def filter_rows(z, means, precision, log_norm, transmat, alpha, fresh):  # pragma: no cover
    """Return the filtered posteriors of the rows of ``z``, continuing from ``alpha``.

    Parameters
    ----------
    z : ndarray, shape (n, D)
        z-scored residual rows; a row with a NaN is a prediction step (no emission).
    means, precision : ndarray, shape (K, D)
        Emission means and inverse variances (z-units).
    log_norm : ndarray, shape (K,)
        ``−½ Σ_d log(2π σ_kd²)``.
    transmat : ndarray, shape (K, K)
        ``transmat[i, j] = P(S_t = j | S_t−1 = i)``.
    alpha : ndarray, shape (K,)
        The previous row's filtered vector, or the initial distribution when ``fresh``;
        left at the last row's filtered vector.
    fresh : bool
        Row 0 is the first of a sequence (``alpha`` is the initial distribution, not propagated).

    Returns
    -------
    ndarray, shape (n, K)
        ``P(S_t = k | e_1:t)``, rows summing to 1.
    """
    n = z.shape[0]
    k = means.shape[0]
    out = np.empty((n, k))
    predicted = np.empty(k)
    log_b = np.empty(k)
    for t in range(n):
        _predict(alpha, transmat, not (fresh and t == 0), predicted)
        if np.isnan(z[t]).any():
            alpha[:] = predicted
        else:
            peak = _log_emissions(z[t], means, precision, log_norm, log_b)
            _update(alpha, predicted, log_b, peak)
        out[t] = alpha
    return out


@njit(cache=True)
def standardise_rows(  # pragma: no cover - compiled
    z, posteriors, before, fresh, transmat, means, variances, nominal
):
    """Return z-scored rows standardised by the nominal regimes' one-step predictive density.

    Parameters
    ----------
    z : ndarray, shape (n, C)
        z-scored residual rows (NaN where missing).
    posteriors : ndarray, shape (n, S)
        The filter's output for the rows (:func:`filter_rows`; S = K + 1 states).
    before : ndarray, shape (S,)
        The filtered vector before row 0 (the initial distribution when ``fresh``).
    fresh : bool
        Row 0 starts a sequence: its prediction is ``before`` itself.
    transmat : ndarray, shape (S, S)
    means, variances : ndarray, shape (K, C)
        The fitted regimes' emission means and variances, z-units.
    nominal : ndarray of bool, shape (K,)

    Returns
    -------
    ndarray, shape (n, C)
        ``(z − m) / s``: ``m``, ``s²`` the mean and variance of the nominal regimes' mixture
        weighted by their predicted probabilities ``P(S_t = k | e_1:t−1)`` (renormalised; equal
        weights when none is predicted).
    """
    n, c = z.shape
    k = means.shape[0]
    s = transmat.shape[0]
    out = np.empty((n, c))
    weights = np.empty(k)
    for t in range(n):
        total = 0.0
        for j in range(k):
            if not nominal[j]:
                weights[j] = 0.0
                continue
            if t == 0 and fresh:
                w = before[j]
            else:
                w = 0.0
                for i in range(s):
                    w += (before[i] if t == 0 else posteriors[t - 1, i]) * transmat[i, j]
            weights[j] = w
            total += w
        if not total > 0.0:
            total = 0.0
            for j in range(k):
                weights[j] = 1.0 if nominal[j] else 0.0
                total += weights[j]
        for d in range(c):
            mean = 0.0
            second = 0.0
            for j in range(k):
                w = weights[j] / total
                mean += w * means[j, d]
                second += w * (variances[j, d] + means[j, d] * means[j, d])
            out[t, d] = (z[t, d] - mean) / math.sqrt(max(second - mean * mean, 1e-12))
    return out


@njit(cache=True)
def cusum_rows(x, history, coef, sigma, stats, shift, ratio, threshold, held):  # pragma: no cover
    """Return the novelty statistic of each standardised row, continuing ``history``, ``stats``.

    Parameters
    ----------
    x : ndarray, shape (n, C)
        Standardised rows (:func:`standardise_rows`); NaN where missing.
    history : ndarray, shape (L, C)
        The L rows before ``x`` (NaN where unknown: at a start); left at the last L rows.
    coef : ndarray, shape (C, L + 1) or wider
        Per channel the AR intercept, then ``a_1 … a_L`` (:mod:`dtwin.monitor.novelty`).
    sigma : ndarray, shape (C,)
        Per channel the innovation's standard deviation.
    stats : ndarray, shape (C, 3)
        Per channel the CUSUMs of a mean shift up, down and a variance increase (nats); left at
        the last row's.
    shift, ratio : float
        The mean shift (innovation sds) and the variance ratio the CUSUMs are designed for.
    threshold : float
        ``h``, nats; each statistic is capped at ``2h``.
    held : ndarray of bool, shape (n,)
        Rows whose statistics stay as they were (after a bridged gap).

    Returns
    -------
    ndarray, shape (n,)
        The largest statistic over channels and tests after each row, in units of ``h``. A
        channel whose row or one of its lags is missing keeps its statistics.
    """
    n, c = x.shape
    lags = history.shape[0]
    out = np.empty(n)
    half_shift2 = 0.5 * shift * shift
    log_term = 0.5 * math.log(ratio)
    square_term = 0.5 * (1.0 - 1.0 / ratio)
    cap = 2.0 * threshold
    for t in range(n):
        peak = 0.0
        for j in range(c):
            e = x[t, j] - coef[j, 0]
            for i in range(1, lags + 1):
                e -= coef[j, i] * (x[t - i, j] if t >= i else history[lags + t - i, j])
            e /= sigma[j]
            if not (held[t] or np.isnan(e)):
                gains = (shift * e - half_shift2, -shift * e - half_shift2,
                         square_term * e * e - log_term)  # fmt: skip
                for i in range(3):
                    stats[j, i] = min(max(0.0, stats[j, i] + gains[i]), cap)
            for i in range(3):
                peak = max(peak, stats[j, i])
        out[t] = peak / threshold
    if n >= lags:
        history[:, :] = x[n - lags :]
    else:
        history[: lags - n] = history[n:].copy()
        history[lags - n :] = x
    return out


# --- the sample lines' text ------------------------------------------------------------------


@njit(cache=True, inline="always")
def _two_product(a, b):  # pragma: no cover - compiled
    """``(p, e)`` with ``p + e = a·b`` exactly (Dekker's product, no over- or underflow)."""
    p = a * b
    t = _SPLITTER * a
    a_hi = t - (t - a)
    a_lo = a - a_hi
    t = _SPLITTER * b
    b_hi = t - (t - b)
    b_lo = b - b_hi
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


@njit(cache=True)
def _round_digits(x, p, powers, zero):  # pragma: no cover - compiled
    """Return ``x > 0``'s ``p`` significant digits correctly rounded: ``(n, e, distance)``.

    ``x ≈ n·10^(e − p + 1)`` with ``10^(p−1) ≤ n < 10^p`` (``p ≤ 17``); ``distance`` is
    ``|x − n·10^(e−p+1)|`` in units of ``10^(e−p+1)`` (at most one half). ``x·10^(p−1−e)`` is
    formed in double-double arithmetic (``powers[zero + k]`` is ``10^k`` as a (high, low) pair:
    relative error about 1e-31); when its fraction lies within 1e-6 of one half (a tie, or too
    close to tell) the digits are undecided: ``n = −1`` (``e`` still ``x``'s exponent); ``n =
    −2`` if the scaling went wrong (never seen).
    """
    bottom, top = powers[zero + p - 1, 0], powers[zero + p, 0]  # exact: p ≤ 22
    e = int(math.floor(math.log10(x)))
    s_hi, s_lo = 0.0, 0.0
    for _ in range(3):  # log10 may be one off near a power of ten
        k = zero + p - 1 - e
        hi, lo = _two_product(x, powers[k, 0])
        lo += x * powers[k, 1]
        s_hi = hi + lo
        s_lo = lo - (s_hi - hi)
        if s_hi < bottom or (s_hi == bottom and s_lo < 0.0):
            e -= 1
        elif s_hi > top or (s_hi == top and s_lo >= 0.0):
            e += 1
        else:
            break
    whole = math.floor(s_hi)  # exact, as s_hi - whole (s_hi < 10^17: spacing up to 16)
    rest = (s_hi - whole) + s_lo
    carry = math.floor(rest)
    n = int(whole) + int(carry)
    fraction = rest - carry
    if n < int(bottom) - 1 or n >= int(top):
        return -2, e, 0.0
    if abs(fraction - 0.5) < 1e-6:
        return -1, e, 0.5
    if fraction < 0.5:
        return n, e, fraction
    if n + 1 == int(top):
        return int(bottom), e + 1, (1.0 - fraction) / 10.0  # in units of the new last digit
    return n + 1, e, 1.0 - fraction


@njit(cache=True)
def _shortest_digits(a, powers, zero):  # pragma: no cover - compiled
    """Return the fewest digits that read back as ``a > 0`` (``repr``'s): ``(n, e, p)``.

    Reading digits back gives the double nearest to them, ``a`` when they lie within half an
    ulp of it; of ``p`` digits the nearest are the correctly rounded ones (the interval is
    symmetric: not for a power of two, left undecided). ``n = −1`` when undecided: a power of
    two, or the distance too close to half an ulp to tell (1e-9 relative), or ``a`` about
    halfway between two candidates that could read back. Seventeen digits always read back.
    """
    mantissa, exponent = math.frexp(a)
    if mantissa == 0.5:
        return -1, 0, 0
    half_ulp = math.ldexp(1.0, exponent - 54)
    for q in range(1, 18):
        n, e, distance = _round_digits(a, q, powers, zero)
        if n == -2:
            return -1, 0, 0
        half = half_ulp * powers[zero + q - 1 - e, 0]  # half an ulp in units of the last digit
        if n == -1:  # about halfway between two candidates
            if half < 0.5 * (1.0 - 1e-5):
                continue  # neither reads back
            return -1, 0, 0
        if distance < half * (1.0 - 1e-9):
            return n, e, q
        if distance <= half * (1.0 + 1e-9):
            return -1, 0, 0
    return -1, 0, 0


@njit(cache=True, inline="always")
def _put_scientific(buf, pos, count, e, digits):  # pragma: no cover - compiled
    """Write ``d.ddde±XX`` (at least two exponent digits); return the end."""
    buf[pos] = digits[0]
    pos += 1
    if count > 1:
        buf[pos] = 46
        pos += 1
        for i in range(1, count):
            buf[pos] = digits[i]
            pos += 1
    buf[pos], buf[pos + 1] = 101, 45 if e < 0 else 43  # e-, e+
    pos += 2
    magnitude = abs(e)
    width = 3 if magnitude >= 100 else 2
    for i in range(width - 1, -1, -1):
        buf[pos + i] = 48 + magnitude % 10
        magnitude //= 10
    return pos + width


@njit(cache=True)
def _put_digits(buf, pos, n, count, e, upper, dot_zero, digits):  # pragma: no cover
    """Write the digits ``n`` (``count`` of them, no trailing zero) with exponent ``e``.

    As Python's ``%g``: ``d.ddde±XX`` when ``e < −4`` or ``e ≥ upper``, else positional;
    ``dot_zero`` adds repr's ``.0`` to a whole number. Returns the end.
    """
    for i in range(count - 1, -1, -1):
        digits[i] = 48 + n % 10
        n //= 10
    if e < -4 or e >= upper:
        return _put_scientific(buf, pos, count, e, digits)
    if e < 0:  # 0.000ddd
        buf[pos], buf[pos + 1] = 48, 46
        pos += 2
        for _ in range(-e - 1):
            buf[pos] = 48
            pos += 1
        for i in range(count):
            buf[pos] = digits[i]
            pos += 1
        return pos
    for i in range(max(count, e + 1)):  # ddd.ddd or ddd000
        if i == e + 1:
            buf[pos] = 46
            pos += 1
        buf[pos] = digits[i] if i < count else 48
        pos += 1
    if dot_zero and count <= e + 1:
        buf[pos], buf[pos + 1] = 46, 48
        pos += 2
    return pos


@njit(cache=True)
def _write_float(buf, pos, x, p, shortest, digits, powers, zero):  # pragma: no cover
    """Write ``'%.<p>g' % x`` (or ``repr(x)`` when ``shortest``) at ``buf[pos]``; return the end.

    Returns −1 when undecided (:func:`_round_digits`, :func:`_shortest_digits`), not finite or
    outside ``[_SMALLEST, _LARGEST]``.
    """
    if not math.isfinite(x):
        return -1
    if x < 0.0 or (x == 0.0 and math.copysign(1.0, x) < 0.0):
        buf[pos] = 45  # -
        pos += 1
    a = abs(x)
    if a == 0.0:
        buf[pos], buf[pos + 1], buf[pos + 2] = 48, 46, 48  # 0.0, or 0 for %g
        return pos + (3 if shortest else 1)
    if a < _SMALLEST or a > _LARGEST:
        return -1
    if shortest:
        n, e, p = _shortest_digits(a, powers, zero)
    else:
        n, e, _ = _round_digits(a, p, powers, zero)
    if n < 0:
        return -1
    upper = 16 if shortest else p  # repr turns to an exponent at 1e16, %.<p>g at 10^p
    count = p
    while count > 1 and n % 10 == 0:
        n //= 10
        count -= 1
    return _put_digits(buf, pos, n, count, e, upper, shortest, digits)


@njit(cache=True)
def write_lines(floats, choices, kinds, precisions, literals, literal_ends, texts, text_ends,
                powers):  # fmt: skip
    # pragma: no cover - compiled
    """Write one line per row of ``floats`` from a template; return ``(text, ends, written)``.

    A line is ``literals`` piece 0, field 0, piece 1, field 1, …, the last piece (piece ``f``
    is ``literals[literal_ends[f − 1]:literal_ends[f]]``, UTF-8 bytes). Field ``f`` of kind
    ``kinds[f]`` writes the row's next float (``floats`` ``(n, n_floats)``) as ``repr``
    (:data:`FIELD_REPR`) or as ``'%.<precisions[f]>g'`` (:data:`FIELD_G`), or its next text
    (:data:`FIELD_TEXT`: text ``choices[row, j]`` of ``texts``, ended at ``text_ends``), each
    digit for digit as Python writes it. ``powers`` ``(2·Z + 1, 2)``: ``10^k`` as a (high, low)
    pair at row ``Z + k`` (``Z`` ≥ 268). Returns the bytes ``text`` (uint8), each line's end
    in it, shape ``(n,)``, and whether it was written, bool ``(n,)``: a row holding a float
    this loop leaves undecided (:func:`_write_float`) is not written (Python writes it).
    """
    n, n_fields = floats.shape[0], kinds.shape[0]
    longest = 0
    for c in range(text_ends.shape[0]):
        longest = max(longest, text_ends[c] - (text_ends[c - 1] if c else 0))
    width = literal_ends[n_fields] + n_fields * max(longest, 32)
    buf = np.empty(n * width, dtype=np.uint8)
    ends = np.empty(n, dtype=np.int64)
    written = np.ones(n, dtype=np.bool_)
    digits = np.empty(20, dtype=np.uint8)
    zero = (powers.shape[0] - 1) // 2
    pos = 0
    for row in range(n):
        start, column, text, piece = pos, 0, 0, 0
        for f in range(n_fields + 1):
            for b in range(piece, literal_ends[f]):
                buf[pos] = literals[b]
                pos += 1
            piece = literal_ends[f]
            if f == n_fields:
                break
            if kinds[f] == FIELD_TEXT:
                c = choices[row, text]
                text += 1
                for b in range(text_ends[c - 1] if c else 0, text_ends[c]):
                    buf[pos] = texts[b]
                    pos += 1
                continue
            pos = _write_float(buf, pos, floats[row, column], precisions[f],
                               kinds[f] == FIELD_REPR, digits, powers, zero)  # fmt: skip
            column += 1
            if pos < 0:
                break
        if pos < 0:
            pos = start
            written[row] = False
        ends[row] = pos
    return buf[:pos], ends, written


def warm_up() -> None:
    """Compile the filter, the CUSUMs and the line writer into numba's on-disk cache."""
    from dtwin.monitor.sample_lines import LineTemplate  # it imports this module

    LineTemplate("%r %s %.12g\n", ("a",)).render(np.ones((1, 2)), np.zeros((1, 1)))
    filter_rows(np.zeros((2, 1)), np.zeros((2, 1)), np.ones((2, 1)), np.zeros(2),
                np.full((2, 2), 0.5), np.full(2, 0.5), True)  # fmt: skip
    posteriors = np.full((2, 2), 0.5)
    x = standardise_rows(np.zeros((2, 1)), posteriors, np.full(2, 0.5), True, np.full((2, 2), 0.5),
                         np.zeros((1, 1)), np.ones((1, 1)), np.ones(1, dtype=np.bool_))  # fmt: skip
    cusum_rows(x, np.zeros((1, 1)), np.zeros((1, 2)), np.ones(1), np.zeros((1, 3)), 1.0, 4.0,
               10.0, np.zeros(2, dtype=np.bool_))  # fmt: skip
