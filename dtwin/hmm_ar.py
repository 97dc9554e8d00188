"""Switching autoregressive HMM: a Gaussian AR(1) emission per state (paper §5, future work).

The paper's regime HMM (:mod:`dtwin.hmm`) treats the residual features as i.i.d. Gaussian
given the state, although their lag-1 autocorrelation is 0.999 (§4.1); §5 names a switching
autoregressive emission as the natural extension. Here every state ``k`` and feature ``d``
has its own AR(1) law

    ``x_t,d | S_t = k, x_t−1 ~ N(c_kd + φ_kd · x_t−1,d,  σ²_kd)``            (diagonal)

so a state is a level *and* a dynamic. Parameters per state and feature: the intercept
``c`` (equivalently the stationary mean ``c/(1 − φ)``), the AR coefficient ``φ`` and the
innovation variance ``σ²``; with K states and D features the model has
``(K−1) + K(K−1) + 3DK`` free parameters (:func:`n_ar_hmm_params`).

The likelihood is conditional on the first sample: EM sees the ``T − 1`` pairs
``(x_t, x_t−1)`` as one row each (with their squares and product, shape ``(T − 1, 5D)``),
and every state sequence, posterior and Viterbi path refers to samples ``1 … T−1``; sample 0
is given the state of sample 1.

EM runs in the compiled kernels of :mod:`dtwin._em_kernels` (hmmlearn's scaled
forward-backward, π and A updates and Viterbi, written out in numba) through the multi-start
harness the Gaussian HMM uses (:mod:`dtwin._multistart`); the reference engine
(``engine="hmmlearn"``) extends :class:`hmmlearn.base.BaseHMM` through the emission hooks its
own model classes implement (:mod:`dtwin._em_reference`). The M-step is per state and feature
a weighted least-squares regression of ``x_t`` on ``(1, x_t−1)`` with weights γ_t(k), and its
residual variance floored at ``var_floor`` (the exact constrained maximiser, so EM stays
monotone). Random starts, the stopping rule and the start table follow :func:`dtwin.hmm.fit_hmm`
(depmixS4's Dirichlet(0.01) start, relative tolerance). ``tests/concepts/test_hmm_ar.py`` checks the
log-likelihood against a forward recursion written out by hand, and recovery of known AR
coefficients and states.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dtwin._emissions import _ar_mstep, _moments
from dtwin._multistart import (
    AR1,
    EmData,
    available_engine,
    decode,
    fit_starts,
    kernel_array,
    one_blas_thread,
    restart_seeds,
)
from dtwin._validation import DtwinValueError, require_finite_array, require_positive
from dtwin.hmm import (
    DIRICHLET_ALPHA,
    HmmFitError,
    _freeze,
    _require_count,
    _require_engine,
    bic_minimum_bracketed,
    bic_row,
)

__all__ = [
    "ArHmmFit",
    "ArBicSweep",
    "n_ar_hmm_params",
    "sample_ar_hmm",
    "fit_ar_hmm",
    "score_ar_hmm",
    "ar_bic_by_k",
]

logger = logging.getLogger(__name__)


def n_ar_hmm_params(n_states: int, n_features: int) -> int:
    """Return the free-parameter count ``(K−1) + K(K−1) + 3·D·K`` of the diagonal AR(1)-HMM.

    π has K−1 free values, A K(K−1); each state and feature has an intercept, an AR
    coefficient and an innovation variance.

    Examples
    --------
    >>> n_ar_hmm_params(4, 10)
    135
    """
    return (n_states - 1) + n_states * (n_states - 1) + 3 * n_features * n_states


# --- the emission model ---------------------------------------------------------------------


def _design(X: np.ndarray) -> np.ndarray:
    """Return the rows ``(y, x, y², y·x, x²)`` of the pairs ``y = x_t``, ``x = x_t−1``: (T−1, 5D).

    Both the emission log-density and the M-step's weighted sums are linear in these
    columns, so each is one matrix product per EM iteration.
    """
    y, x = X[1:], X[:-1]
    return np.hstack([y, x, y * y, y * x, x * x])


# --- the fitted model -----------------------------------------------------------------------


@dataclass(frozen=True)
class ArHmmFit:
    """A fitted AR(1)-HMM and its decoding of the training sequence.

    Attributes
    ----------
    startprob : ndarray, shape (K,)
        π, the state distribution of sample 1 (the first sample with a predecessor).
    transmat : ndarray, shape (K, K)
        ``transmat[i, j] = P(S_t = j | S_t−1 = i)``.
    intercepts, coefs, sds : ndarray, shape (K, D)
        ``c``, ``φ`` and the innovation standard deviation ``σ`` per state and feature
        (z-units of the training features).
    log_likelihood : float
        ``log p(x_1 … x_T−1 | x_0)`` at the returned parameters.
    n_params : int
        :func:`n_ar_hmm_params`.
    bic : float
        ``−2·log_likelihood + n_params·log(T − 1)`` (``T − 1`` modelled samples).
    n_iter : int
        EM iterations of the best start.
    converged : bool
        The best start stopped by the tolerance with finite, monotone log-likelihoods.
    restarts : DataFrame
        One row per start, the columns of :attr:`dtwin.hmm.HmmFit.restarts`.
    best_restart : int
        ``restart`` number of the returned start.
    smoothed : ndarray, shape (T, K)
        Smoothed posteriors (row 0 repeats row 1: sample 0 only conditions).
    viterbi : ndarray of int, shape (T,)
        Viterbi path, states 0 … K−1 (sample 0 takes the state of sample 1).
    """

    startprob: np.ndarray
    transmat: np.ndarray
    intercepts: np.ndarray
    coefs: np.ndarray
    sds: np.ndarray
    log_likelihood: float
    n_params: int
    bic: float
    n_iter: int
    converged: bool
    restarts: pd.DataFrame
    best_restart: int
    smoothed: np.ndarray
    viterbi: np.ndarray

    @property
    def n_states(self) -> int:
        """Number of hidden states K."""
        return len(self.startprob)

    @property
    def n_features(self) -> int:
        """Number of features D."""
        return self.coefs.shape[1]

    @property
    def means(self) -> np.ndarray:
        """Stationary means ``c/(1 − φ)`` per state and feature, NaN where ``|φ| ≥ 1``."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.abs(self.coefs) < 1.0, self.intercepts / (1.0 - self.coefs), np.nan)


def sample_ar_hmm(
    startprob: Any,
    transmat: Any,
    intercepts: Any,
    coefs: Any,
    sds: Any,
    n_steps: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Draw a sequence from an AR(1)-HMM; return ``(X (T, D), states (T,))``.

    Sample 0 has state ``~ startprob`` and value ``c/(1 − φ)`` of that state plus one
    innovation (the stationary mean, or ``c`` where ``|φ| ≥ 1``); sample t follows
    ``x_t = c_k + φ_k x_t−1 + σ_k ε_t`` with ``k = S_t``.

    Examples
    --------
    >>> X, s = sample_ar_hmm([1.0], [[1.0]], [[0.0]], [[0.5]], [[1.0]], 5,
    ...                      np.random.default_rng(0))
    >>> X.shape, s.tolist()
    ((5, 1), [0, 0, 0, 0, 0])
    """
    n_steps = _require_count("n_steps", n_steps, 1)
    startprob, transmat = np.asarray(startprob, float), np.asarray(transmat, float)
    c, phi, sd = (np.atleast_2d(np.asarray(a, float)) for a in (intercepts, coefs, sds))
    n_states = len(startprob)
    states = np.empty(n_steps, dtype=int)
    states[0] = rng.choice(n_states, p=startprob)
    for t in range(1, n_steps):
        states[t] = rng.choice(n_states, p=transmat[states[t - 1]])
    noise = rng.standard_normal((n_steps, c.shape[1])) * sd[states]
    X = np.empty_like(noise)
    k = states[0]
    stationary = np.where(np.abs(phi[k]) < 1.0, c[k] / (1.0 - np.clip(phi[k], -0.999, 0.999)), c[k])
    X[0] = stationary + noise[0]
    for t in range(1, n_steps):
        k = states[t]
        X[t] = c[k] + phi[k] * X[t - 1] + noise[t]
    return X, states


# --- EM from random starts ------------------------------------------------------------------


def _random_emission(
    design: np.ndarray, n_states: int, rng: np.random.Generator, var_floor: float
) -> tuple[np.ndarray, np.ndarray]:
    """depmixS4's random start: Dirichlet(0.01) pair weights, the weighted M-step on them.

    Returns the emission ``(c, φ, σ²)`` stacked, shape (3, K, D), and the weights' occupancy.
    """
    weights = rng.dirichlet(np.full(n_states, DIRICHLET_ALPHA), size=len(design))
    return np.stack(_ar_mstep(_moments(weights, design), var_floor)), weights.sum(axis=0)


def fit_ar_hmm(
    X: Any,
    n_states: int,
    *,
    n_restarts: int = 10,
    seed: int | Sequence[int] = 0,
    max_iter: int = 500,
    tol: float = 1e-8,
    var_floor: float = 1e-6,
    engine: str = "compiled",
) -> ArHmmFit:
    """Fit a diagonal Gaussian AR(1)-HMM by EM from several random starts; return the best.

    Parameters
    ----------
    X : array-like, shape (T, D)
        Features (z-scored, :func:`dtwin.hmm.zscore`); at least ``n_states + 2`` rows.
    n_states : int
        Number of hidden states K.
    n_restarts : int, default 10
        Random starts; start ``i`` uses the ``i``-th child of ``SeedSequence(seed)``.
    seed : int or sequence of int, default 0
        Entropy of the seed sequence.
    max_iter : int, default 500
        EM iteration cap per start.
    tol : float, default 1e-8
        Relative tolerance: stop when ``(LL − LL_old)/|LL_old| < tol``.
    var_floor : float, default 1e-6
        Lower bound on every innovation variance σ², z-units² (innovations of a series with
        lag-1 ACF 0.999 have variance ~2e-3 of the series', so the Gaussian HMM's floor of
        1e-3 would be far too high).
    engine : {"compiled", "hmmlearn"}, default "compiled"
        EM engine, as :func:`dtwin.hmm.fit_hmm`.

    Returns
    -------
    ArHmmFit

    Raises
    ------
    HmmFitError
        If every start failed or ended with an empty state.

    Notes
    -----
    E-step: hmmlearn's forward-backward on the emission densities
    ``N(x_t | c_k + φ_k x_t−1, diag σ_k²)`` (the forward recursion of Eq. (4) with this
    ``b_k``). M-step: π and A as in Eqs. (7)–(8); per state and feature the γ-weighted
    regression of ``x_t`` on ``(1, x_t−1)``.

    Examples
    --------
    >>> X, _ = sample_ar_hmm([0.5, 0.5], [[0.98, 0.02], [0.02, 0.98]], [[0.0], [2.0]],
    ...                      [[0.9], [0.0]], [[0.1], [0.1]], 400, np.random.default_rng(0))
    >>> fit = fit_ar_hmm(X, 2, n_restarts=3, seed=0)
    >>> sorted((np.round(fit.coefs[:, 0], 1) + 0.0).tolist())
    [0.0, 0.9]
    """
    X = require_finite_array("X", X, ndim=2)
    n_states = _require_count("n_states", n_states, 1)
    n_restarts = _require_count("n_restarts", n_restarts, 1)
    max_iter = _require_count("max_iter", max_iter, 1)
    tol = require_positive("tol", tol)
    var_floor = require_positive("var_floor", var_floor)
    if len(X) < n_states + 2:
        raise DtwinValueError(
            f"X must have at least n_states + 2 = {n_states + 2} rows (got {len(X)})"
        )
    options = {"max_iter": max_iter, "tol": tol, "var_floor": var_floor}
    engine = _require_engine(engine)
    design = _design(X)
    data = EmData(AR1, design, design)
    with one_blas_thread():
        restarts, runs = fit_starts(
            data,
            restart_seeds(seed, n_restarts),
            lambda rng: _random_emission(design, n_states, rng, var_floor),
            engine,
            options,
            label=f"fit_ar_hmm K={n_states}",
        )
        if not runs:
            raise HmmFitError(
                f"fit_ar_hmm: all {n_restarts} starts failed or degenerated (K={n_states}); "
                f"statuses: {', '.join(restarts['status'])}"
            )
        usable = restarts[restarts["restart"].isin(runs)]
        best = int(usable.loc[usable["log_likelihood"].idxmax(), "restart"])
        run = runs[best]
        viterbi = decode(data, run, engine).astype(int)
    best_row = restarts.loc[restarts["restart"] == best].iloc[0]
    n_params = n_ar_hmm_params(n_states, X.shape[1])
    log_likelihood = float(best_row["log_likelihood"])
    logger.info(
        "fit_ar_hmm K=%d: best logL=%.4f (start %d of %d)",
        n_states,
        log_likelihood,
        best,
        n_restarts,
    )
    intercepts, coefs, variances = run.emission
    return ArHmmFit(
        startprob=_freeze(run.startprob),
        transmat=_freeze(run.transmat),
        intercepts=_freeze(intercepts),
        coefs=_freeze(coefs),
        sds=_freeze(np.sqrt(variances)),
        log_likelihood=log_likelihood,
        n_params=n_params,
        bic=-2.0 * log_likelihood + n_params * math.log(len(design)),
        n_iter=int(best_row["n_iter"]),
        converged=bool(best_row["converged"]),
        restarts=restarts,
        best_restart=best,
        smoothed=_freeze(np.vstack([run.posteriors[:1], run.posteriors])),
        viterbi=_freeze(np.concatenate([viterbi[:1], viterbi])),
    )


def score_ar_hmm(fit: ArHmmFit, X: Any) -> float:
    """Return ``log p(x_1 … x_T−1 | x_0)`` of ``X`` (shape (T, D), T ≥ 2) under ``fit``."""
    X = require_finite_array("X", X, ndim=2)
    if X.shape[1] != fit.n_features or len(X) < 2:
        raise DtwinValueError(f"X must have shape (T >= 2, {fit.n_features}) (got {X.shape})")
    design = _design(X)
    data = EmData(AR1, design, design)
    emission = np.stack([fit.intercepts, fit.coefs, fit.sds**2])
    arrays = (design, emission, fit.startprob, fit.transmat)
    if available_engine("compiled") == "compiled":
        from dtwin import _em_kernels as kernels

        return float(kernels.score(data.kind, *(kernel_array(a) for a in arrays)))
    from dtwin._em_reference import score  # no numba: hmmlearn's log space

    return score(data, fit.startprob, fit.transmat, emission, "log")


# --- model order ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ArBicSweep:
    """Result of :func:`ar_bic_by_k`.

    Attributes
    ----------
    table : DataFrame
        One row per K, the columns of :func:`dtwin.hmm.bic_row` (``K``, ``log_likelihood``,
        ``n_params``, ``bic``, ``converged``, ``n_usable``, ``log_likelihood_half``,
        ``n_starts``, ``source``).
    fits : dict of int to ArHmmFit
        The best fit at every K of the table.
    """

    table: pd.DataFrame
    fits: dict[int, ArHmmFit]


def ar_bic_by_k(
    X: Any,
    ks: Sequence[int],
    *,
    n_restarts: int = 5,
    seed: int | Sequence[int] = 0,
    k_max: int | None = None,
    stop_after_rises: int = 2,
    **fit_options: Any,
) -> ArBicSweep:
    """Fit one AR(1)-HMM per K and tabulate its BIC, as :func:`dtwin.hmm.bic_by_k` does.

    K's starts derive from ``SeedSequence([*seed, K])``; past ``max(ks)`` K grows until the
    BIC rose ``stop_after_rises`` times in a row or ``K = k_max``. ``fit_options`` go to
    :func:`fit_ar_hmm` (``max_iter``, ``tol``, ``var_floor``).
    """
    X = require_finite_array("X", X, ndim=2)
    ks = sorted(_require_count("ks[]", k, 1) for k in ks)
    if not ks:
        raise DtwinValueError("ks must list at least one number of states (got none)")
    entropy = [int(seed)] if isinstance(seed, (int, np.integer)) else [int(s) for s in seed]
    k_last = max(ks) if k_max is None else max(max(ks), _require_count("k_max", k_max, 1))
    rows, fits = [], {}
    for k in [*ks, *range(max(ks) + 1, k_last + 1)]:
        if k > max(ks) and bic_minimum_bracketed([r["bic"] for r in rows], stop_after_rises):
            break
        fit = fit_ar_hmm(X, k, n_restarts=n_restarts, seed=[*entropy, k], **fit_options)
        rows.append(bic_row(k, fit.restarts, fit.n_params, fit.bic, fit.converged))
        fits[k] = fit
        logger.info("ar_bic_by_k K=%d: logL=%.3f BIC=%.3f", k, fit.log_likelihood, fit.bic)
    return ArBicSweep(table=pd.DataFrame(rows), fits=fits)
