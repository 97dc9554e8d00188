"""Gaussian hidden Markov model of the residual regimes (paper §2.1 Eqs. (2)–(10), §4.2, §5).

A K-state HMM with diagonal-covariance Gaussian emissions (paper Eq. (3); depmixS4's
independent ``gaussian()`` responses, r_notes.md §4) is fitted by EM to z-scored residual
features, arrays time-first ``(T, D)``. EM runs hmmlearn 0.3.3's equations and scaled
recursions compiled with numba, one call per start, and its log-space recursions where the
scaled ones underflow (:mod:`dtwin._em_kernels`; the starts, statuses and fallback in
:mod:`dtwin._multistart`); hmmlearn itself is the reference engine (``engine="hmmlearn"``,
config ``hmm.engine``; :mod:`dtwin._em_reference`), and is imported only then.
``tests/concepts/test_hmm_engine.py`` holds the two engines to the same iterations, statuses
and numbers. dtwin adds what depmixS4 did and hmmlearn does not:

- z-scoring with the sample standard deviation (R's ``scale``), :func:`zscore`;
- depmixS4's random start: per-sample state weights drawn from Dirichlet(0.01) (almost a hard
  random assignment), emission parameters fitted to those weights, uniform initial and
  transition probabilities; several starts, best log-likelihood kept, every start recorded;
- a variance floor applied after every M-step (hmmlearn 0.3.3 applies ``min_covar`` only when
  it initialises covariances itself), which is the exact constrained M-step, so EM stays
  monotone;
- BIC sweeps that double a K's random starts while the second half still gains, fitting only
  the new half (the seeds are prefix-stable);
- an honest convergence verdict and depmixS4's relative stopping rule
  ``(LL − LL_old)/|LL_old| < tol``;
- the filtered (causal) posteriors ``P(S_t = k | e_1:t)``, the normalised forward variables of
  Eq. (4), :func:`filtered_posteriors`: rescaled products in √T blocks (vectorised), with an
  exact log-space loop as the fallback when a row underflows;
- BIC with depmixS4's parameter count ``p = (K−1) + K(K−1) + 2DK`` (Eq. (26)), :func:`bic_by_k`.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd

from dtwin._emissions import _log_emission
from dtwin._multistart import (
    ENGINES,
    GAUSSIAN,
    RESTART_COLUMNS,
    EmData,
    EmRun,
    decode,
    fit_one_start,
    fit_starts,
    one_blas_thread,
    restart_seeds,
)
from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_finite_array,
    require_positive,
)
from dtwin.state_tables import state_labels

if TYPE_CHECKING:
    from hmmlearn.hmm import GaussianHMM

# re-exported; figures and crosschecks import them from hmm_basics, without hmmlearn
from dtwin.hmm_basics import ZScored, n_hmm_params, zscore

__all__ = [
    "HmmFitError",
    "ZScored",
    "zscore",
    "HmmFit",
    "fit_hmm",
    "ScaledHmmFit",
    "fit_zscored_hmm",
    "hmm_summary",
    "n_hmm_params",
    "filtered_posteriors",
    "to_hmmlearn",
    "bic_by_k",
    "bic_row",
    "bic_minimum_bracketed",
    "split_fits",
    "STABLE_GAIN",
    "ENGINES",
]

logger = logging.getLogger(__name__)

#: Concentration of the Dirichlet draw of per-sample state weights (depmixS4 random start).
DIRICHLET_ALPHA = 0.01


class HmmFitError(DtwinValueError):
    """Every EM start failed or ended with an empty state."""


def _require_count(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise DtwinTypeError(f"{name} must be an integer (got {type(value).__name__}: {value!r})")
    if value < minimum:
        raise DtwinValueError(f"{name} must be >= {minimum} (got {value})")
    return int(value)


# --- the fitted model -----------------------------------------------------------------------


@dataclass(frozen=True)
class HmmFit:
    """A fitted diagonal-Gaussian HMM and its posteriors on the training sequence.

    Attributes
    ----------
    startprob : ndarray, shape (K,)
        Initial state distribution π (Eq. (8)).
    transmat : ndarray, shape (K, K)
        Transition matrix, ``transmat[i, j] = P(S_t = j | S_t−1 = i)``.
    means, sds : ndarray, shape (K, D)
        Emission means and standard deviations (z-units of the training features).
    log_likelihood : float
        ``log p(X)`` at the returned parameters.
    n_params : int
        ``(K−1) + K(K−1) + 2DK`` (r_notes.md §4).
    bic : float
        ``−2·log_likelihood + n_params·log(T)``.
    n_iter : int
        EM iterations (M-steps) of the best start.
    converged : bool
        Honest verdict for the best start: stopped by the tolerance before the iteration cap,
        finite parameters, log-likelihood never decreasing beyond round-off.
    restarts : DataFrame
        One row per start: ``restart`` (1-based), ``seed`` (integer seed of its generator),
        ``log_likelihood`` (NaN if it failed), ``n_iter``, ``converged``, ``status``
        (``ok``, ``max_iter``, ``not_monotone``, ``degenerate``, ``failed``),
        ``implementation`` (hmmlearn's ``scaling`` or ``log``), ``min_occupancy`` (smallest
        expected state occupancy, samples) and ``message``.
    best_restart : int
        ``restart`` number of the returned start.
    smoothed : ndarray, shape (T, K)
        Smoothed posteriors γ_t(k) = P(S_t = k | e_1:T) (Eq. (6)).
    filtered : ndarray, shape (T, K)
        Filtered (causal) posteriors P(S_t = k | e_1:t), the normalised α_t of Eq. (4).
    viterbi : ndarray of int, shape (T,)
        Viterbi path, states numbered 0 … K−1 (Eq. (10)).
    restart_viterbi : ndarray of int, shape (n_restarts, T)
        Viterbi path of every start's fitted model (row ``restart − 1``), ``−1`` throughout
        for starts that failed or degenerated; how much the starts disagree (paper §4.4;
        r_notes.md §5: depmixS4's restarts agree on 69–100 % of the samples).
    """

    startprob: np.ndarray
    transmat: np.ndarray
    means: np.ndarray
    sds: np.ndarray
    log_likelihood: float
    n_params: int
    bic: float
    n_iter: int
    converged: bool
    restarts: pd.DataFrame
    best_restart: int
    smoothed: np.ndarray
    filtered: np.ndarray
    viterbi: np.ndarray
    restart_viterbi: np.ndarray

    @property
    def n_states(self) -> int:
        """Number of hidden states K."""
        return len(self.startprob)

    @property
    def n_features(self) -> int:
        """Number of emission dimensions D."""
        return self.means.shape[1]


def to_hmmlearn(fit: HmmFit, implementation: str = "scaling") -> GaussianHMM:
    """Return an :class:`hmmlearn.hmm.GaussianHMM` holding the parameters of ``fit``.

    Use its public ``score``, ``decode`` and ``predict_proba`` on new z-scored data (z-scored
    with the training mean and sd, :meth:`ZScored.transform`). Imports hmmlearn.
    """
    from dtwin._em_reference import new_gaussian_model, set_gaussian_params

    model = new_gaussian_model(fit.n_states, implementation)
    model.n_features = fit.n_features
    return set_gaussian_params(model, fit.startprob, fit.transmat, fit.means, fit.sds**2)


def _require_engine(engine: Any) -> str:
    if engine not in ENGINES:
        raise DtwinValueError(f"engine must be one of {', '.join(ENGINES)} (got {engine!r})")
    return engine


def _em_data(X: np.ndarray) -> EmData:
    """``X`` as the EM engines read it: ``(x, x²)`` rows for the kernels, ``X`` for hmmlearn.

    The rows (T, 2D) are filled in place, without a (T, D) temporary for ``x²``.
    """
    n_features = X.shape[1]
    rows = np.empty((len(X), 2 * n_features), dtype=X.dtype)
    rows[:, :n_features] = X
    np.multiply(X, X, out=rows[:, n_features:])
    return EmData(GAUSSIAN, rows, X)


def _weighted_emissions(
    X: np.ndarray, weights: np.ndarray, var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(means, variances, occupancy)``: weighted ML emissions of a start.

    ``X`` is ``(T, D)``, ``weights`` ``(T, K)`` (each sample's weight on each state); means and
    variances are ``(K, D)``, the variances floored at ``var_floor``; occupancy ``(K,)`` is each
    state's total weight (NaN emissions where it is 0).
    """
    occupancy = weights.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        means = (weights.T @ X) / occupancy[:, None]
        variances = np.stack(
            [(weights[:, k] @ (X - means[k]) ** 2) / occupancy[k] for k in range(weights.shape[1])]
        )
    return means, np.maximum(variances, var_floor), occupancy


def _random_start(
    X: np.ndarray, n_states: int, rng: np.random.Generator, var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """depmixS4's random start: Dirichlet(0.01) sample weights, weighted ML emissions."""
    weights = rng.dirichlet(np.full(n_states, DIRICHLET_ALPHA), size=len(X))  # (T, K)
    return _weighted_emissions(X, weights, var_floor)


def _kmeanspp_start(
    X: np.ndarray, n_states: int, rng: np.random.Generator, var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k-means++ seeding: K samples drawn far apart, every sample to its nearest, ML emissions.

    Unlike the Dirichlet start, whose near-random assignment puts every state's mean close to
    the global mean, the states start apart (a way out of the sweep's low optima).
    """
    centres = [X[rng.integers(len(X))]]
    distance = ((X - centres[0]) ** 2).sum(axis=1)
    for _ in range(n_states - 1):
        total = distance.sum()
        pick = rng.choice(len(X), p=distance / total) if total > 0 else rng.integers(len(X))
        centres.append(X[pick])
        distance = np.minimum(distance, ((X - X[pick]) ** 2).sum(axis=1))
    nearest = np.argmin([((X - c) ** 2).sum(axis=1) for c in centres], axis=0)
    weights = np.eye(n_states)[nearest]
    return _weighted_emissions(X, weights, var_floor)


#: Random starts of :func:`fit_hmm`: depmixS4's (the paper's default) and k-means++.
START_METHODS = {"dirichlet": _random_start, "kmeans++": _kmeanspp_start}


def _split_start(
    means: np.ndarray, variances: np.ndarray, state: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Split ``state`` of a K-state fit in two: means ``μ ∓ ½σ`` (random signs per feature).

    Returns the K + 1 means and variances (the new state last, with the split one's variances).
    """
    delta = 0.5 * np.sqrt(variances[state]) * rng.choice([-1.0, 1.0], size=means.shape[1])
    new_means = np.vstack([means, means[state] + delta])
    new_means[state] = means[state] - delta
    return new_means, np.vstack([variances, variances[state]])


def split_fits(
    X: Any,
    means: Any,
    variances: Any,
    *,
    seed: int | Sequence[int] = 0,
    first_restart: int = 1,
    max_iter: int = 500,
    tol: float = 1e-8,
    var_floor: float = 1e-3,
    engine: str = "compiled",
) -> tuple[pd.DataFrame, tuple[np.ndarray, np.ndarray] | None]:
    """EM from every split of a K-state fit into K + 1 states (greedy growth of the model).

    Parameters
    ----------
    X : array-like, shape (T, D)
        z-scored features.
    means, variances : array-like, shape (K, D)
        Emission means and variances (z-units, z-units²) of the K-state fit to grow.
    seed : int or sequence of int, default 0
        Seed of the split directions.
    first_restart : int, default 1
        Number of the first split start in the returned table.
    max_iter, tol, var_floor, engine
        As :func:`fit_hmm`.

    Returns
    -------
    restarts : DataFrame
        One row per split state (K rows, columns of :attr:`HmmFit.restarts`; ``seed`` −1,
        ``message`` names the state split).
    best : tuple of ndarray or None
        Means and variances (K + 1, D) of the best usable split, None if none was usable.

    Notes
    -----
    Start ``j`` keeps the K-state fit's emissions and replaces state ``j`` by two states with
    means ``μ_j ∓ ½σ_j`` (a random sign per feature) and ``σ_j²``; π and A start uniform as
    in every start. Random starts spread over many optima at K ≥ 10 (the residuals are smooth,
    so many tilings of the run fit about equally well); growing the best K-state fit keeps
    what it found (split-and-merge EM, Ueda et al. 2000; greedy mixture learning).
    """
    X = require_finite_array("X", X, ndim=2)
    engine = _require_engine(engine)
    means = np.asarray(means, dtype=float)
    variances = np.asarray(variances, dtype=float)
    rng = np.random.default_rng(seed)
    data, options = _em_data(X), {"max_iter": max_iter, "tol": tol, "var_floor": var_floor}
    rows: list[dict[str, Any]] = []
    best: tuple[float, np.ndarray] | None = None
    with one_blas_thread():
        for state in range(len(means)):
            initial = np.stack(_split_start(means, variances, state, rng))
            occupancy = np.full(len(means) + 1, np.inf)
            row, run = fit_one_start(data, -1, (initial, occupancy), engine, options)
            note = f"split of state {state + 1} of the K={len(means)} fit"
            row["message"] = f"{note}; {row['message']}" if row["message"] else note
            rows.append({"restart": first_restart + state, **row})
            if run is not None and (best is None or row["log_likelihood"] > best[0]):
                best = (row["log_likelihood"], run.emission)
    table = pd.DataFrame(rows, columns=list(RESTART_COLUMNS))
    return table, None if best is None else (best[1][0].copy(), best[1][1].copy())


def _freeze(array: np.ndarray) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


def _em_options(
    X: np.ndarray,
    n_states: int,
    *,
    max_iter: int = 500,
    tol: float = 1e-8,
    var_floor: float = 1e-3,
    start: str = "dirichlet",
    engine: str = "compiled",
) -> dict[str, Any]:
    """Return :func:`fit_hmm`'s EM options checked (names and defaults as there)."""
    if start not in START_METHODS:
        raise DtwinValueError(f"start must be one of {', '.join(START_METHODS)} (got {start!r})")
    if len(X) <= n_states:
        raise DtwinValueError(f"X must have more rows than n_states={n_states} (got {len(X)})")
    return {
        "max_iter": _require_count("max_iter", max_iter, 1),
        "tol": require_positive("tol", tol),
        "var_floor": require_positive("var_floor", var_floor),
        "start": start,
        "engine": _require_engine(engine),
    }


def _gaussian_starts(
    X: np.ndarray,
    n_states: int,
    seeds: Sequence[int],
    first_restart: int,
    options: Mapping[str, Any],
) -> tuple[pd.DataFrame, dict[int, EmRun]]:
    """Run the random starts ``first_restart, …`` (one per seed) of :func:`fit_hmm`."""
    em = {key: options[key] for key in ("max_iter", "tol", "var_floor")}
    start_method = START_METHODS[options["start"]]

    def initial(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        means, variances, occupancy = start_method(X, n_states, rng, em["var_floor"])
        return np.stack([means, variances]), occupancy

    return fit_starts(
        _em_data(X), seeds, initial, options["engine"], em, first_restart, f"fit_hmm K={n_states}"
    )


def fit_hmm(
    X: Any,
    n_states: int,
    *,
    n_restarts: int = 10,
    seed: int | Sequence[int] = 0,
    max_iter: int = 500,
    tol: float = 1e-8,
    var_floor: float = 1e-3,
    start: str = "dirichlet",
    engine: str = "compiled",
    start_from: HmmFit | None = None,
) -> HmmFit:
    """Fit a diagonal Gaussian HMM by EM from several random starts and return the best.

    Parameters
    ----------
    X : array-like, shape (T, D)
        z-scored features (see :func:`zscore`); one row per sample.
    n_states : int
        Number of hidden states K (paper: 4).
    n_restarts : int, default 10
        Random starts; start ``i`` uses the generator seeded with the ``i``-th child of
        ``numpy.random.SeedSequence(seed)``.
    seed : int or sequence of int, default 0
        Entropy of the seed sequence; the same seed gives the same fit.
    max_iter : int, default 500
        EM iteration cap per start (depmixS4 ``maxit``).
    tol : float, default 1e-8
        Relative stopping tolerance: stop when ``(LL − LL_old)/|LL_old| < tol`` (depmixS4
        ``crit="relative"``).
    var_floor : float, default 1e-3
        Lower bound on every emission variance, z-units²; applied after each M-step.
    start : {"dirichlet", "kmeans++"}, default "dirichlet"
        Random start of each EM run: depmixS4's Dirichlet(0.01) sample weights (the paper's),
        or k-means++ seeding (states start apart; see :data:`START_METHODS`).
    engine : {"compiled", "hmmlearn"}, default "compiled"
        EM engine: the compiled kernels of :mod:`dtwin._em_kernels` (hmmlearn's equations and
        recursions, scaled and log-space; imports neither hmmlearn nor scikit-learn) or
        hmmlearn itself (the reference; config ``hmm.engine``).
    start_from : HmmFit, optional
        Instead of random starts, one EM run from this fit's emissions (means and variances,
        K × D as ``X``'s) and state occupancy (its smoothed posteriors' mean share × T): a fit
        on a sample of the rows continued to convergence on all of them. ``n_restarts`` and
        ``start`` are then unused and ``seed`` (an int) is the run's.

    Returns
    -------
    HmmFit
        Parameters, log-likelihood and BIC of the best start, the table of all starts, and
        the smoothed, filtered and Viterbi decodings of ``X``.

    Raises
    ------
    HmmFitError
        If no start produced a usable model (all failed or ended with an empty state).

    Notes
    -----
    Each start draws per-sample state weights ~ Dirichlet(0.01) (almost a hard random
    assignment), fits means and ML standard deviations to those weights, and sets π and A
    uniform (depmixS4's ``random.start``). EM (Eqs. (4)–(9)) runs the scaled forward-backward
    recursions (compiled, or hmmlearn's ``implementation="scaling"``), restarting from the
    same point in log space (the engine's ``"log"`` implementation) if they underflow; BLAS is
    held to one thread.
    A start is ``ok`` when the tolerance stopped it, its parameters are finite and its
    log-likelihood never fell by more than round-off;
    ``max_iter`` starts are usable but not converged; ``degenerate`` (a state with expected
    occupancy below :data:`MIN_OCCUPANCY` samples) and ``failed`` starts are recorded and skipped.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> X = np.concatenate([rng.normal(-2, 1, (100, 2)), rng.normal(2, 1, (100, 2))])
    >>> fit = fit_hmm(X, 2, n_restarts=3, seed=1)
    >>> fit.smoothed.shape, sorted(np.round(fit.means[:, 0]).tolist())
    ((200, 2), [-2.0, 2.0])
    """
    X = require_finite_array("X", X, ndim=2)
    n_states = _require_count("n_states", n_states, 1)
    n_restarts = _require_count("n_restarts", n_restarts, 1)
    options = _em_options(
        X, n_states, max_iter=max_iter, tol=tol, var_floor=var_floor, start=start, engine=engine
    )
    if start_from is not None:
        _require_start_from(start_from, n_states, X, seed)
    with one_blas_thread():
        if start_from is None:
            seeds = restart_seeds(seed, n_restarts)
            restarts, runs = _gaussian_starts(X, n_states, seeds, 1, options)
        else:
            em = {key: options[key] for key in ("max_iter", "tol", "var_floor")}
            point = np.stack([start_from.means, start_from.sds**2])
            occupancy = start_from.smoothed.mean(axis=0) * len(X)
            restarts, runs = fit_starts(
                _em_data(X), [int(seed)], lambda rng: (point, occupancy), options["engine"], em,
                label=f"fit_hmm K={n_states} from a fit",
            )  # fmt: skip
        return _assemble_fit(X, n_states, restarts, runs, options["engine"])


def _require_start_from(fit: Any, n_states: int, X: np.ndarray, seed: Any) -> None:
    """Check ``fit_hmm``'s ``start_from`` against ``X`` and ``n_states``, and its int seed."""
    if not isinstance(fit, HmmFit):
        raise DtwinTypeError(f"start_from must be an HmmFit (got {type(fit).__name__})")
    if fit.means.shape != (n_states, X.shape[1]):
        raise DtwinValueError(
            f"start_from must have {n_states} states of {X.shape[1]} features "
            f"(got means of shape {fit.means.shape})"
        )
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise DtwinTypeError(f"seed must be an int with start_from (got {seed!r})")


class ScaledHmmFit(NamedTuple):
    """Result of :func:`fit_zscored_hmm`: the z-scoring of the features and the fit on it."""

    scaled: ZScored
    fit: HmmFit


def fit_zscored_hmm(
    features: Any, n_states: int, *, seed: int | Sequence[int] = 0, **fit_options: Any
) -> ScaledHmmFit:
    """z-score ``features`` (R's ``scale``) and fit a K-state HMM to them (:func:`fit_hmm`).

    The paper's regime fit (§4.2) on any residual channels: the DAG's regime stages and
    ``dtwin regimes`` on a user's twin both fit through it.

    Parameters
    ----------
    features : DataFrame or array, shape (T, D)
        Raw feature columns, their own units.
    n_states : int
        K.
    seed : int or sequence of int
        Entropy of the EM starts (:func:`fit_hmm`).
    **fit_options
        ``n_restarts``, ``max_iter``, ``tol``, ``var_floor``, ``start``, ``engine``.

    Returns
    -------
    ScaledHmmFit
        ``scaled`` (:class:`ZScored`: the z-scored values, their means and sds) and ``fit``.
    """
    scaled = zscore(features)
    return ScaledHmmFit(scaled, fit_hmm(scaled.values, n_states, seed=seed, **fit_options))


def hmm_summary(fit: HmmFit, scaled: ZScored) -> dict[str, Any]:
    """Return the fitted model as plain data (for JSON): parameters, likelihood, all starts.

    Means and sds are in z-units of the training features; ``means_physical`` converts the
    means back to the features' units (``mean + sd·μ``).
    """
    labels = state_labels(fit.n_states)
    restarts = fit.restarts.copy()
    return {
        "n_states": fit.n_states,
        "features": list(scaled.columns),
        "n_samples": len(scaled.values),
        "log_likelihood": fit.log_likelihood,
        "n_params": fit.n_params,
        "bic": fit.bic,
        "n_iter": fit.n_iter,
        "converged": fit.converged,
        "best_restart": fit.best_restart,
        "states": labels,
        "startprob": fit.startprob,
        "transmat": fit.transmat,
        "means_z": fit.means,
        "sds_z": fit.sds,
        "means_physical": scaled.mean + scaled.sd * fit.means,
        "feature_mean": scaled.mean,
        "feature_sd": scaled.sd,
        "occupancy": fit.smoothed.sum(axis=0),
        "restarts": restarts.to_dict(orient="records"),
    }


def _require_usable(n_states: int, restarts: pd.DataFrame, runs: dict[int, EmRun]) -> None:
    if not runs:
        raise HmmFitError(
            f"fit_hmm: all {len(restarts)} starts failed or degenerated (K={n_states}); "
            f"statuses: {', '.join(restarts['status'])}"
        )


def _best_position(restarts: pd.DataFrame, runs: dict[int, EmRun]) -> int:
    """Return the row of the usable start with the highest log-likelihood (first of ties)."""
    numbers = restarts["restart"].to_numpy()
    values = restarts["log_likelihood"].to_numpy(dtype=float)
    rows = [row for row, number in enumerate(numbers) if int(number) in runs]
    return max(rows, key=lambda row: -math.inf if math.isnan(values[row]) else values[row])


def _best_restart(restarts: pd.DataFrame, runs: dict[int, EmRun]) -> int:
    """Return the number of the usable start with the highest log-likelihood (first of ties)."""
    return int(restarts["restart"].iloc[_best_position(restarts, runs)])


def _assemble_fit(
    X: np.ndarray, n_states: int, restarts: pd.DataFrame, runs: dict[int, EmRun], engine: str
) -> HmmFit:
    """Return the :class:`HmmFit` of the best usable start, with every start's Viterbi path."""
    _require_usable(n_states, restarts, runs)
    n_restarts = len(restarts)
    data = _em_data(X)
    restart_viterbi = np.full((n_restarts, len(X)), -1, dtype=int)
    for restart, run in runs.items():
        restart_viterbi[restart - 1] = decode(data, run, engine)
    del data  # the (x, x²) rows (T, 2D) are not needed by the filter below
    best = _best_restart(restarts, runs)
    run, best_row = runs[best], restarts.loc[restarts["restart"] == best].iloc[0]
    means, variances = run.emission
    filtered, _ = _forward_filter(X, run.startprob, run.transmat, means, variances)
    log_likelihood, n_params = float(run.history[-1]), n_hmm_params(n_states, X.shape[1])
    logger.info(
        "fit_hmm K=%d: best logL=%.4f (restart %d of %d; %d usable)",
        n_states,
        log_likelihood,
        best,
        n_restarts,
        len(runs),
    )
    return HmmFit(
        startprob=_freeze(run.startprob),
        transmat=_freeze(run.transmat),
        means=_freeze(means),
        sds=_freeze(np.sqrt(variances)),
        log_likelihood=log_likelihood,
        n_params=n_params,
        bic=-2.0 * log_likelihood + n_params * math.log(len(X)),
        n_iter=int(best_row["n_iter"]),
        converged=bool(best_row["converged"]),
        restarts=restarts,
        best_restart=best,
        smoothed=_freeze(run.posteriors),
        filtered=_freeze(filtered),
        viterbi=_freeze(restart_viterbi[best - 1]),
        restart_viterbi=_freeze(restart_viterbi),
    )


# --- filtering ------------------------------------------------------------------------------


def _forward_filter(
    X: np.ndarray,
    startprob: np.ndarray,
    transmat: np.ndarray,
    means: np.ndarray,
    variances: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Normalised forward recursion (Eq. (4)); returns (filtered (T, K), log p(X)).

    Vectorised: with ``β_t = exp(log b_t − max_k log b_t)`` and ``M_t = diag(β_t) Aᵀ`` the
    filtered vector is ``α_t ∝ M_t ⋯ M_1 α_0``. The series is cut into ~√T blocks; prefix
    products inside every block are built for all blocks at once (one batched 4×4 matrix
    product per position), the block entry vectors are chained sequentially (√T small
    steps), and every α_t is then one batched matrix-vector product. Products are rescaled
    at every step, so nothing overflows; if a row underflows to zero (a state sequence the
    transition matrix forbids) the exact log-space loop takes over.
    """
    emission = _log_emission(X, means, variances)  # log b, made β in place
    peak = emission.max(axis=1)
    emission -= peak[:, None]
    np.exp(emission, out=emission)
    first = startprob * emission[0]
    n_steps, n_states = emission.shape
    filtered = np.empty((n_steps, n_states))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        filtered[0] = first / first.sum()
        if n_steps > 1:
            filtered[1:] = _blocked_forward(filtered[0], emission[1:], transmat)
        predicted = filtered[:-1] @ transmat
        norms = np.einsum("tk,tk->t", predicted, emission[1:])
        log_likelihood = float(np.log(first.sum()) + peak[0] + np.sum(np.log(norms) + peak[1:]))
    if not (np.all(np.isfinite(filtered)) and np.isfinite(log_likelihood)):
        return _forward_filter_loop(X, startprob, transmat, means, variances)
    return filtered, log_likelihood


def _blocked_forward(start: np.ndarray, emission: np.ndarray, transmat: np.ndarray) -> np.ndarray:
    """Return the filtered vectors of steps 1 … n given that of step 0 (see above)."""
    n_steps, n_states = emission.shape
    block = max(1, math.isqrt(n_steps))
    n_blocks = -(-n_steps // block)
    beta = np.ones((n_blocks * block, n_states))
    beta[:n_steps] = emission
    beta = beta.reshape(n_blocks, block, n_states)
    transposed = transmat.T
    prefix = np.empty((n_blocks, block, n_states, n_states))
    for position in range(block):
        step = beta[:, position, :, None] * transposed
        prefix[:, position] = step if position == 0 else step @ prefix[:, position - 1]
        prefix[:, position] /= prefix[:, position].max(axis=(1, 2), keepdims=True)
    del beta
    entries = np.empty((n_blocks, n_states))
    alpha = start
    for index in range(n_blocks):
        entries[index] = alpha
        alpha = prefix[index, -1] @ alpha
        alpha = alpha / alpha.sum()
    alphas = np.einsum("bjik,bk->bji", prefix, entries).reshape(-1, n_states)[:n_steps]
    del prefix
    alphas /= alphas.sum(axis=1, keepdims=True)
    return alphas


def _forward_filter_loop(
    X: np.ndarray,
    startprob: np.ndarray,
    transmat: np.ndarray,
    means: np.ndarray,
    variances: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Normalised forward recursion (Eq. (4)), one step at a time in log space.

    Exact for any transition matrix (zeros included); slow for long series (a Python loop
    over T). The reference for :func:`_forward_filter` and its fallback.
    """
    log_b = _log_emission(X, means, variances)
    with np.errstate(divide="ignore"):
        log_a = np.log(transmat)
        log_alpha = np.log(startprob) + log_b[0]
    filtered = np.empty_like(log_b)
    log_likelihood = 0.0
    for t in range(len(log_b)):
        if t > 0:
            joint = log_alpha[:, None] + log_a  # (K, K): previous i → next j
            peak = joint.max(axis=0)
            finite_peak = np.where(np.isfinite(peak), peak, 0.0)
            with np.errstate(divide="ignore"):
                log_alpha = finite_peak + np.log(np.exp(joint - finite_peak).sum(axis=0)) + log_b[t]
        peak = log_alpha.max()
        log_norm = peak + math.log(np.exp(log_alpha - peak).sum())
        log_alpha = log_alpha - log_norm
        log_likelihood += log_norm
        filtered[t] = np.exp(log_alpha)
    return filtered, log_likelihood


def filtered_posteriors(fit: HmmFit, X: Any) -> np.ndarray:
    """Return the filtered (causal) posteriors ``P(S_t = k | e_1:t)`` of ``X`` under ``fit``.

    Parameters
    ----------
    fit : HmmFit
        A fitted model.
    X : array-like, shape (T, D)
        Features z-scored like the training data.

    Returns
    -------
    ndarray, shape (T, K)
        Row t depends on rows ``0 … t`` of ``X`` only; rows sum to 1.

    Notes
    -----
    The normalised forward variables of Eq. (4),
    ``α_t(j) ∝ (Σ_i α_t−1(i) A_ij) b_j(e_t)``, ``α_1(j) ∝ π_j b_j(e_1)``, computed in log
    space so that no state underflows; the emission log-densities come from two matrix
    products, so only the K×K recursion loops over time.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X = np.concatenate([rng.normal(-2, 1, (50, 1)), rng.normal(2, 1, (50, 1))])
    >>> fit = fit_hmm(X, 2, n_restarts=2, seed=0)
    >>> bool(np.allclose(filtered_posteriors(fit, X).sum(axis=1), 1.0))
    True
    """
    X = require_finite_array("X", X, ndim=2)
    if X.shape[1] != fit.n_features:
        raise DtwinValueError(f"X must have {fit.n_features} columns (got {X.shape[1]})")
    if len(X) == 0:
        raise DtwinValueError("X must have at least 1 row (got 0)")
    filtered, _ = _forward_filter(X, fit.startprob, fit.transmat, fit.means, fit.sds**2)
    return filtered


# --- model order ----------------------------------------------------------------------------


def bic_minimum_bracketed(bics: Sequence[float], rises: int = 2) -> bool:
    """Return True when the last ``rises`` BIC values each rose over the one before.

    The minimum over consecutive K is then bracketed: past it the BIC went up ``rises``
    times in a row.

    Examples
    --------
    >>> bic_minimum_bracketed([10, 8, 7, 9, 11])
    True
    >>> bic_minimum_bracketed([10, 8, 7, 9, 8])
    False
    """
    rises = _require_count("rises", rises, 1)
    values = [float(v) for v in bics]
    if len(values) <= rises:
        return False
    tail = values[-(rises + 1) :]
    return all(b > a for a, b in itertools.pairwise(tail))


def bic_row(
    n_states: int,
    restarts: pd.DataFrame,
    n_params: int,
    bic: float,
    converged: bool,
    source: str = "sweep",
    n_random: int | None = None,
) -> dict[str, Any]:
    """Return one row of :func:`bic_by_k`'s table from a fit's table of starts.

    Parameters
    ----------
    n_states : int
        K.
    restarts : DataFrame
        The fit's starts (:attr:`HmmFit.restarts`: ``log_likelihood``, ``status``), in order.
    n_params, bic, converged
        Of the best start (:attr:`HmmFit.n_params`, ``bic``, ``converged``).
    source : str, default "sweep"
        ``sweep`` (fitted by the sweep) or ``given`` (a dedicated fit reused).
    n_random : int, optional
        The first ``n_random`` rows are random starts, the rest split starts
        (:func:`split_fits`); None: all rows are random starts.

    Returns
    -------
    dict
        ``log_likelihood`` is the best over all starts, ``log_likelihood_half`` the best over
        the first half of the random starts (at least one) and every split start, so their
        difference shows whether doubling the random starts still helped; ``n_starts`` counts
        the random starts, ``n_split_starts`` the split ones.
    """
    statuses = restarts["status"].to_numpy(dtype=object)
    values = restarts["log_likelihood"].to_numpy(dtype=float)
    return _bic_row(n_states, statuses, values, n_params, bic, converged, source, n_random)


#: Statuses of the starts that give no usable model.
_UNUSABLE = ("failed", "degenerate")


def _usable(statuses: np.ndarray) -> np.ndarray:
    """Boolean mask (n,) of the statuses of usable starts."""
    return np.array([status not in _UNUSABLE for status in statuses], dtype=bool)


def _nanmax(values: np.ndarray) -> float:
    """Largest non-NaN value (NaN if there is none), as pandas' ``Series.max``."""
    finite = values[~np.isnan(values)]
    return float(finite.max()) if finite.size else math.nan


def _bic_row(
    n_states: int,
    statuses: np.ndarray,
    values: np.ndarray,
    n_params: int,
    bic: float,
    converged: bool,
    source: str,
    n_random: int | None,
) -> dict[str, Any]:
    """:func:`bic_row` from the starts' statuses and log-likelihoods, arrays (n,) in order."""
    usable = _usable(statuses)
    values = np.where(usable, values, math.nan)
    n_random = len(values) if n_random is None else int(n_random)
    half = max(1, n_random // 2)
    in_half = np.arange(len(values)) < half
    in_half[n_random:] = True
    return {
        "K": int(n_states),
        "log_likelihood": _nanmax(values),
        "n_params": int(n_params),
        "bic": float(bic),
        "converged": bool(converged),
        "n_usable": int(usable.sum()),
        "log_likelihood_half": _nanmax(values[in_half]),
        "n_starts": n_random,
        "n_split_starts": len(values) - n_random,
        "source": source,
    }


#: A K's best log-likelihood is "stable" when the second half of its random starts gains less
#: (log-likelihood units; the bar of Fig. 9's stability check, ``fig09_bic.STABLE_LOGLIK``).
STABLE_GAIN = 1.0


def _grown_splits(
    X: np.ndarray,
    k: int,
    entropy: list[int],
    grow_from: tuple[np.ndarray, np.ndarray] | None,
    fit_options: Mapping[str, Any],
) -> tuple[pd.DataFrame | None, tuple[np.ndarray, np.ndarray] | None]:
    """Return the splits of the best K − 1 fit (:func:`split_fits`), or (None, None)."""
    if grow_from is None or len(grow_from[0]) != k - 1:
        return None, None
    keys = ("max_iter", "tol", "var_floor", "engine")
    em = {key: fit_options[key] for key in keys if key in fit_options}
    return split_fits(X, *grow_from, seed=[*entropy, k, 2], **em)


def _combined_row(
    k: int,
    restarts: pd.DataFrame,
    runs: dict[int, EmRun],
    splits: pd.DataFrame | None,
    grown: tuple[np.ndarray, np.ndarray] | None,
    n_features: int,
    n_samples: int,
) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """Return the BIC row of a K's random and split starts, and the best emissions.

    Works on the tables' columns as arrays (a sweep calls it once per K and doubling; pandas
    indexing cost ~15 ms a call).
    """
    _require_usable(k, restarts, runs)
    n_random, position = len(restarts), _best_position(restarts, runs)
    run = runs[int(restarts["restart"].iloc[position])]
    best = (run.emission[0].copy(), run.emission[1].copy())
    log_likelihood = float(run.history[-1])
    converged = bool(restarts["converged"].iloc[position])
    statuses = restarts["status"].to_numpy(dtype=object)
    values = restarts["log_likelihood"].to_numpy(dtype=float)
    if splits is not None:
        split_statuses = splits["status"].to_numpy(dtype=object)
        split_values = splits["log_likelihood"].to_numpy(dtype=float)
        usable = np.flatnonzero(_usable(split_statuses) & ~np.isnan(split_values))
        if grown is not None and usable.size and split_values[usable].max() > log_likelihood:
            top = usable[np.argmax(split_values[usable])]
            log_likelihood, converged, best = (
                float(split_values[top]),
                bool(splits["converged"].iloc[top]),
                grown,
            )
        statuses = np.concatenate([statuses, split_statuses])
        values = np.concatenate([values, split_values])
    n_params = n_hmm_params(k, n_features)
    bic = -2.0 * log_likelihood + n_params * math.log(n_samples)
    row = _bic_row(k, statuses, values, n_params, bic, converged, "sweep", n_random)
    return row, best


def _sweep_row(
    X: np.ndarray,
    k: int,
    n_restarts: int,
    entropy: list[int],
    grow_from: tuple[np.ndarray, np.ndarray] | None,
    fit_options: Mapping[str, Any],
    max_restarts: int | None = None,
) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """One K of :func:`bic_by_k`: random starts, then the splits of the best K − 1 fit.

    With ``max_restarts``, the random starts are doubled while the second half still gains
    :data:`STABLE_GAIN` or more log-likelihood and the doubled count stays within
    ``max_restarts``; the seeds are prefix-stable, so only the new half is fitted.
    """
    options = _em_options(X, k, **fit_options)
    splits, grown = _grown_splits(X, k, entropy, grow_from, options)
    tables, runs, n = [], {}, 0
    target = n_restarts
    with one_blas_thread():
        while True:
            seeds = restart_seeds([*entropy, k], target, first=n)
            table, new_runs = _gaussian_starts(X, k, seeds, n + 1, options)
            tables.append(table)
            runs.update(new_runs)
            n = target
            restarts = pd.concat(tables, ignore_index=True)
            row, best = _combined_row(k, restarts, runs, splits, grown, X.shape[1], len(X))
            gain = row["log_likelihood"] - row["log_likelihood_half"]
            if max_restarts is None or gain < STABLE_GAIN or 2 * n > max_restarts:
                return row, best
            logger.info("bic_by_k K=%d: %d starts gain %.3f over %d; doubling", k, n, gain, n // 2)
            target = 2 * n


def _given_params(row: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """Pop a given row's emission means and sds (z-units) as (means, variances), if present."""
    means, sds = row.pop("means_z", None), row.pop("sds_z", None)
    if means is None or sds is None:
        return None
    return np.asarray(means, dtype=float), np.asarray(sds, dtype=float) ** 2


def bic_by_k(
    X: Any,
    ks: Sequence[int],
    *,
    n_restarts: int = 5,
    seed: int | Sequence[int] = 0,
    k_max: int | None = None,
    stop_after_rises: int = 2,
    given: Mapping[int, Mapping[str, Any]] | None = None,
    split_starts: bool = False,
    max_restarts: int | None = None,
    **fit_options: Any,
) -> pd.DataFrame:
    """Fit one HMM per number of states and tabulate the BIC (paper §5, Eq. (26)).

    Parameters
    ----------
    X : array-like, shape (T, D)
        z-scored features.
    ks : sequence of int
        Numbers of states always fitted (paper: 2 … 9).
    n_restarts : int, default 5
        Random starts per K (CovarianceAnalysis.Rmd: 5).
    seed : int or sequence of int, default 0
        K's starts derive from ``SeedSequence([*seed, K])``, so a K's result does not depend
        on which other K are swept (without ``split_starts``).
    k_max : int, optional
        Extend K one by one past ``max(ks)`` until :func:`bic_minimum_bracketed` (the BIC rose
        ``stop_after_rises`` times in a row) or ``K = k_max``. None: ``ks`` only.
    stop_after_rises : int, default 2
        Consecutive rises that bracket the minimum.
    given : mapping of int to dict, optional
        Rows (:func:`bic_row`) to use as they are for their K: the dedicated K = 4 fit of
        Figs. 4/7, so that the sweep and the figures share one fit. A row may carry the fit's
        ``means_z`` and ``sds_z`` (K, D) for ``split_starts``; they are not tabulated.
    split_starts : bool, default False
        Also start EM from every split of the best fit at K − 1 (:func:`split_fits`; seed
        ``[*seed, K, 2]``) when K − 1 was swept just before, and keep the best of all starts.
    max_restarts : int, optional
        Double a K's random starts (``n_restarts``, ``2·n_restarts``, ...) while the second
        half of them still gains :data:`STABLE_GAIN` or more log-likelihood over the first
        (split starts counted in both halves), up to ``max_restarts``. None: ``n_restarts``.
    **fit_options
        Passed to :func:`fit_hmm` (``max_iter``, ``tol``, ``var_floor``, ``start``).

    Returns
    -------
    DataFrame
        One row per K (:func:`bic_row`): ``K``, ``log_likelihood``, ``n_params``, ``bic``
        (``−2·logL + n_params·log T``), ``converged``, ``n_usable``, ``log_likelihood_half``,
        ``n_starts``, ``n_split_starts``, ``source``.
    """
    X = require_finite_array("X", X, ndim=2)
    ks = sorted(_require_count("ks[]", k, 1) for k in ks)
    entropy = [int(seed)] if isinstance(seed, (int, np.integer)) else [int(s) for s in seed]
    if not ks:
        raise DtwinValueError("ks must list at least one number of states (got none)")
    given = dict(given or {})
    k_last = max(ks) if k_max is None else max(max(ks), _require_count("k_max", k_max, 1))
    rows: list[dict[str, Any]] = []
    best: tuple[np.ndarray, np.ndarray] | None = None
    with one_blas_thread():  # one scan of the BLAS libraries per sweep
        for k in [*ks, *range(max(ks) + 1, k_last + 1)]:
            if k > max(ks) and bic_minimum_bracketed([r["bic"] for r in rows], stop_after_rises):
                break
            if k in given:
                row = dict(given[k])
                best = _given_params(row)
                row.setdefault("n_split_starts", 0)
            else:
                grow_from = best if split_starts else None
                row, best = _sweep_row(
                    X, k, n_restarts, entropy, grow_from, fit_options, max_restarts
                )
            rows.append(row)
            logger.info(
                "bic_by_k K=%d: logL=%.3f (first half of the random starts %.3f) BIC=%.3f "
                "(%d/%d usable, %d split starts)",
                k,
                row["log_likelihood"],
                row["log_likelihood_half"],
                row["bic"],
                row["n_usable"],
                row["n_starts"] + row["n_split_starts"],
                row["n_split_starts"],
            )
    return pd.DataFrame(rows)
