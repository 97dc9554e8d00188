"""The monitor's compiled loops: the regime filter and the novelty test over residual rows.

:func:`filter_rows` is the normalised forward recursion of the regime HMM (paper Eq. (4)) over
a chunk of z-scored residual rows, continuing from the previous row's filtered vector; a row
with a missing value is a prediction step only. :func:`standardise_rows` and
:func:`cusum_rows` are the novelty test (:mod:`dtwin.monitor.novelty`): the rows standardised by
the nominal regimes' prediction, then the CUSUMs on their AR innovations. They give the same
bits whether a series is run in one call or in chunks (the stream and ``dtwin regimes`` run the
same code). Without numba they run in Python (:mod:`dtwin._jit`). Arrays are time-first.
"""

from __future__ import annotations

import math

import numpy as np

from dtwin._jit import njit

__all__ = ["filter_rows", "standardise_rows", "cusum_rows", "warm_up"]


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


def warm_up() -> None:
    """Compile the filter and the CUSUMs into numba's on-disk cache."""
    filter_rows(np.zeros((2, 1)), np.zeros((2, 1)), np.ones((2, 1)), np.zeros(2),
                np.full((2, 2), 0.5), np.full(2, 0.5), True)  # fmt: skip
    posteriors = np.full((2, 2), 0.5)
    x = standardise_rows(np.zeros((2, 1)), posteriors, np.full(2, 0.5), True, np.full((2, 2), 0.5),
                         np.zeros((1, 1)), np.ones((1, 1)), np.ones(1, dtype=np.bool_))  # fmt: skip
    cusum_rows(x, np.zeros((1, 1)), np.zeros((1, 2)), np.ones(1), np.zeros((1, 3)), 1.0, 4.0,
               10.0, np.zeros(2, dtype=np.bool_))  # fmt: skip
