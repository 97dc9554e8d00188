"""Gaussian hidden Markov model of the residual regimes (paper §2.1 Eqs. (2)–(10), §4.2, §5).

A K-state HMM with diagonal-covariance Gaussian emissions (paper Eq. (3); depmixS4's
independent ``gaussian()`` responses, r_notes.md §4) is fitted by EM to z-scored residual
features, arrays time-first ``(T, D)``. EM runs in :class:`hmmlearn.hmm.GaussianHMM` through
its public methods (``fit``, ``score``, ``score_samples``, ``decode``, ``predict_proba``) and two
documented extension points: the convergence monitor (``monitor_``, here
``_DepmixMonitor``, which also applies the variance floor) and the emission hook
``_compute_log_likelihood`` (``_MatmulGaussianHMM``, O(T·K) memory; checked against hmmlearn's
own density by the tests). dtwin adds what depmixS4 did and hmmlearn does not:

- z-scoring with the sample standard deviation (R's ``scale``), :func:`zscore`;
- depmixS4's random start: per-sample state weights drawn from Dirichlet(0.01) (almost a hard
  random assignment), emission parameters fitted to those weights, uniform initial and
  transition probabilities; several starts, best log-likelihood kept, every start recorded;
- a variance floor applied after every M-step (hmmlearn 0.3.3 applies ``min_covar`` only when
  it initialises covariances itself), which is the exact constrained M-step, so EM stays
  monotone;
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
from typing import Any

import numpy as np
import pandas as pd
from hmmlearn import _hmmc
from hmmlearn.base import ConvergenceMonitor
from hmmlearn.hmm import GaussianHMM
from hmmlearn.utils import normalize
from threadpoolctl import threadpool_limits

from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_finite_array,
    require_positive,
)

# re-exported; figures and crosschecks import them from hmm_basics, without hmmlearn
from dtwin.hmm_basics import ZScored, n_hmm_params, zscore

__all__ = [
    "HmmFitError",
    "ZScored",
    "zscore",
    "HmmFit",
    "fit_hmm",
    "n_hmm_params",
    "filtered_posteriors",
    "to_hmmlearn",
    "bic_by_k",
    "bic_row",
    "bic_minimum_bracketed",
    "split_fits",
    "STABLE_GAIN",
]

logger = logging.getLogger(__name__)

#: Concentration of the Dirichlet draw of per-sample state weights (depmixS4 random start).
DIRICHLET_ALPHA = 0.01

#: A state whose expected occupancy ``Σ_t γ_t(k)`` falls below this many samples is "empty"
#: (half a sample, so that a state holding one outlier sample is not flagged by round-off).
MIN_OCCUPANCY = 0.5

#: Log-likelihood drops smaller than this times ``max(1, |LL|)`` count as round-off.
_LL_DROP_RTOL = 1e-9

_RESTART_COLUMNS = (
    "restart",
    "seed",
    "log_likelihood",
    "n_iter",
    "converged",
    "status",
    "implementation",
    "min_occupancy",
    "message",
)


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


class _MatmulGaussianHMM(GaussianHMM):
    """GaussianHMM whose diagonal log-densities are two matrix products, with a lean E-step.

    hmmlearn 0.3.3 evaluates ``((X[:, None, :] − μ)² / σ²).sum(-1)``, a T×K×D temporary
    (320 MB and ~0.7 s per E-step at T = 1e6, D = 10, K = 4). This override of the emission
    hook (``_compute_log_likelihood``, the method hmmlearn's own emission classes define) gives
    the same values from ``X²·(1/σ²)ᵀ − 2X·(μ/σ²)ᵀ`` in O(T·K) memory. The E-step of the
    ``scaling`` implementation (``_do_estep``, :func:`_lean_scaling_estep`) runs hmmlearn's own
    compiled forward, backward and ξ-sum on the same arrays in the same order, and differs only
    in memory: the densities are exponentiated in place and freed after the ξ-sum, and the
    posteriors overwrite the forward lattice instead of being a fifth T×K copy (T = 1e6,
    K = 4, D = 10: ~110 MB per iteration instead of ~210 MB, benchmarks/hmm_fit.py).
    These are the places dtwin goes below hmmlearn's public methods; ``tests/test_hmm.py``
    checks both against hmmlearn's own density and E-step (the latter bit for bit) on every
    run, so a release that changes the hooks fails loudly (hmmlearn is pinned
    ``>=0.3.3,<0.4``).
    """

    def _compute_log_likelihood(self, X: np.ndarray) -> np.ndarray:
        variances = np.maximum(_variances(self), np.finfo(float).tiny)
        return _log_emission(X, self.means_, variances)

    def _do_estep(self, X: np.ndarray, lengths: Any) -> tuple[dict[str, Any], float]:
        if self.implementation != "scaling" or len(lengths) != 1 or self.params != "stmc":
            return super()._do_estep(X, lengths)
        return _lean_scaling_estep(self, X)


def _lean_scaling_estep(model: _MatmulGaussianHMM, X: np.ndarray) -> tuple[dict[str, Any], float]:
    """Return the statistics and log p(X) of hmmlearn's scaling E-step in three T×K arrays.

    The same calls and arithmetic as hmmlearn 0.3.3's ``_do_estep`` → ``_fit_scaling`` →
    ``_accumulate_sufficient_statistics`` (so the statistics are bit-identical), but the
    emission densities are exponentiated in place and freed after the ξ-sum, and the
    posteriors ``γ ∝ α·β`` (Eq. (6)) are formed in the forward lattice. Peak memory beyond
    ``X`` is one T×D temporary (``X²``) or ~3·T·K floats, whichever is larger, instead of
    ~5·T·K floats plus a T×D temporary.
    """
    stats = model._initialize_sufficient_statistics()
    frameprob = model._compute_log_likelihood(X)
    with np.errstate(under="ignore"):
        np.exp(frameprob, out=frameprob)
    log_prob, forward, scaling = _hmmc.forward_scaling(model.startprob_, model.transmat_, frameprob)
    backward = _hmmc.backward_scaling(model.startprob_, model.transmat_, frameprob, scaling)
    xi_sum = (
        _hmmc.compute_scaling_xi_sum(forward, model.transmat_, backward, frameprob)
        if len(X) > 1
        else None
    )
    del frameprob, scaling
    posteriors = np.multiply(forward, backward, out=forward)
    del backward
    normalize(posteriors, axis=1)
    stats["nobs"] += 1
    stats["start"] += posteriors[0]
    if xi_sum is not None:
        stats["trans"] += xi_sum
    stats["post"] += posteriors.sum(axis=0)
    stats["obs"] += posteriors.T @ X
    stats["obs**2"] += posteriors.T @ X**2
    return stats, log_prob


def _new_model(n_states: int, implementation: str, n_iter: int = 1) -> GaussianHMM:
    # Priors switched off (covars_prior=0, covars_weight=1, means_weight=0, Dirichlet priors 1):
    # the M-step is plain maximum likelihood, as depmixS4's.
    return _MatmulGaussianHMM(
        n_components=n_states,
        covariance_type="diag",
        startprob_prior=1.0,
        transmat_prior=1.0,
        means_prior=0.0,
        means_weight=0.0,
        covars_prior=0.0,
        covars_weight=1.0,
        algorithm="viterbi",
        n_iter=n_iter,
        tol=0.0,
        params="stmc",
        init_params="",
        implementation=implementation,
    )


def _set_params(
    model: GaussianHMM,
    startprob: np.ndarray,
    transmat: np.ndarray,
    means: np.ndarray,
    variances: np.ndarray,
) -> GaussianHMM:
    model.startprob_ = np.array(startprob, dtype=float)
    model.transmat_ = np.array(transmat, dtype=float)
    model.means_ = np.array(means, dtype=float)
    model.covars_ = np.array(variances, dtype=float)
    return model


def _variances(model: GaussianHMM) -> np.ndarray:
    # The public ``covars_`` of a diagonal model is the full (K, D, D) matrix.
    return np.diagonal(model.covars_, axis1=1, axis2=2).copy()


def to_hmmlearn(fit: HmmFit, implementation: str = "scaling") -> GaussianHMM:
    """Return an :class:`hmmlearn.hmm.GaussianHMM` holding the parameters of ``fit``.

    Use its public ``score``, ``decode`` and ``predict_proba`` on new z-scored data (z-scored
    with the training mean and sd, :meth:`ZScored.transform`).
    """
    model = _new_model(fit.n_states, implementation)
    model.n_features = fit.n_features
    return _set_params(model, fit.startprob, fit.transmat, fit.means, fit.sds**2)


class _EmError(Exception):
    """EM produced non-finite values for one start."""


def _random_start(
    X: np.ndarray, n_states: int, rng: np.random.Generator, var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """depmixS4's random start: Dirichlet(0.01) sample weights, weighted ML emissions."""
    weights = rng.dirichlet(np.full(n_states, DIRICHLET_ALPHA), size=len(X))  # (T, K)
    occupancy = weights.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        means = (weights.T @ X) / occupancy[:, None]
        variances = np.stack(
            [(weights[:, k] @ (X - means[k]) ** 2) / occupancy[k] for k in range(n_states)]
        )
    return means, np.maximum(variances, var_floor), occupancy


def _kmeanspp_start(
    X: np.ndarray, n_states: int, rng: np.random.Generator, var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k-means++ seeding: K samples drawn far apart, every sample to its nearest, ML emissions.

    Unlike the Dirichlet start, whose near-random assignment puts every state's mean close to
    the global mean, the states start apart (issue 12 item 4: the sweep's low optimum).
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
    occupancy = weights.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        means = (weights.T @ X) / occupancy[:, None]
        variances = np.stack(
            [(weights[:, k] @ (X - means[k]) ** 2) / occupancy[k] for k in range(n_states)]
        )
    return means, np.maximum(variances, var_floor), occupancy


#: Random starts of :func:`fit_hmm`: depmixS4's (the paper's default) and k-means++.
START_METHODS = {"dirichlet": _random_start, "kmeans++": _kmeanspp_start}


class _DepmixMonitor(ConvergenceMonitor):
    """hmmlearn convergence monitor with depmixS4's rule and a variance floor.

    hmmlearn documents subclassing :class:`~hmmlearn.base.ConvergenceMonitor` to change the
    stopping rule. ``report`` runs once per EM iteration, right after the M-step: it records
    the log-likelihood of the parameters that entered the iteration and floors the new
    variances (the exact M-step under ``σ² ≥ var_floor``, so EM stays monotone). ``converged``
    stops on ``(LL − LL_old)/|LL_old| < tol``, at the iteration cap, or on non-finite values.
    """

    def __init__(self, model: GaussianHMM, tol: float, n_iter: int, var_floor: float):
        super().__init__(tol, n_iter, verbose=False)
        self.model = model
        self.var_floor = var_floor
        self.log_likelihoods: list[float] = []
        self.stopped_by_tol = False
        self.non_finite = False

    def report(self, log_prob: float) -> None:
        super().report(log_prob)
        self.log_likelihoods.append(float(log_prob))
        model = self.model
        variances = _variances(model)
        finite = (
            np.isfinite(log_prob)
            and np.isfinite(variances).all()
            and np.isfinite(model.means_).all()
            and np.isfinite(model.transmat_).all()
            and np.isfinite(model.startprob_).all()
        )
        if not finite:
            self.non_finite = True
            return
        model.covars_ = np.maximum(variances, self.var_floor)

    @property
    def converged(self) -> bool:
        history = self.log_likelihoods
        if self.non_finite or self.iter >= self.n_iter:
            return True
        if len(history) >= 2 and (history[-1] - history[-2]) < self.tol * abs(history[-2]):
            self.stopped_by_tol = True
            return True
        return False


def _run_em(
    X: np.ndarray,
    means: np.ndarray,
    variances: np.ndarray,
    implementation: str,
    max_iter: int,
    tol: float,
    var_floor: float,
) -> tuple[GaussianHMM, list[float], bool]:
    """Run EM in one hmmlearn ``fit`` from the given emission start, π and A uniform.

    Returns the model, the log-likelihood history (LL of the parameters entering each
    iteration, then of the final parameters) and whether the tolerance stopped it.
    """
    n_states = len(means)
    model = _new_model(n_states, implementation, n_iter=max_iter)
    uniform = np.full(n_states, 1.0 / n_states)
    _set_params(model, uniform, np.tile(uniform, (n_states, 1)), means, variances)
    monitor = _DepmixMonitor(model, tol, max_iter, var_floor)
    model.monitor_ = monitor
    model.fit(X)
    if monitor.non_finite:
        raise _EmError(f"non-finite log-likelihood or parameters ({implementation})")
    final, posteriors = model.score_samples(X)
    if not np.isfinite(final):
        raise _EmError(f"non-finite final log-likelihood ({implementation})")
    model.occupancy_ = posteriors.sum(axis=0)
    return model, [*monitor.log_likelihoods, float(final)], monitor.stopped_by_tol


def _monotone(history: Sequence[float]) -> bool:
    steps = np.diff(history)
    if steps.size == 0:
        return True
    allowed = _LL_DROP_RTOL * max(1.0, float(np.max(np.abs(history))))
    return bool(steps.min() >= -allowed)


def _fit_one_start(
    X: np.ndarray,
    n_states: int,
    seed: int,
    max_iter: int,
    tol: float,
    var_floor: float,
    start: str = "dirichlet",
    initial: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[dict[str, Any], GaussianHMM | None]:
    """Run EM from one start: a random one (``start``, seeded) or ``initial`` (means, variances)."""
    row: dict[str, Any] = {
        "seed": seed,
        "log_likelihood": math.nan,
        "n_iter": 0,
        "converged": False,
        "status": "failed",
        "implementation": "",
        "min_occupancy": math.nan,
        "message": "",
    }
    if initial is None:
        means, variances, occupancy = START_METHODS[start](
            X, n_states, np.random.default_rng(seed), var_floor
        )
    else:
        means, variances = initial
        occupancy = np.full(n_states, np.inf)
    if not np.all(occupancy >= MIN_OCCUPANCY) or not np.isfinite(means).all():
        row.update(status="degenerate", min_occupancy=float(np.min(occupancy)))
        row["message"] = f"random start left a state with < {MIN_OCCUPANCY} samples of weight"
        return row, None
    messages = []
    for implementation in ("scaling", "log"):
        try:
            model, history, stopped = _run_em(
                X, means, variances, implementation, max_iter, tol, var_floor
            )
        except (_EmError, ValueError, FloatingPointError, RuntimeError) as error:
            messages.append(f"{implementation}: {error}")
            continue
        break
    else:
        row["message"] = "; ".join(messages)
        return row, None
    occupancy = model.occupancy_
    monotone = _monotone(history)
    row.update(
        log_likelihood=history[-1],
        n_iter=len(history) - 1,
        implementation=implementation,
        min_occupancy=float(occupancy.min()),
        message="; ".join(messages),
    )
    if occupancy.min() < MIN_OCCUPANCY:
        row["status"] = "degenerate"
        row["message"] = (row["message"] + "; " if messages else "") + "a state emptied"
    elif not monotone:
        row["status"] = "not_monotone"
    elif not stopped:
        row["status"] = "max_iter"
    else:
        row.update(status="ok", converged=True)
    return row, model


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
    max_iter, tol, var_floor
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
    means = np.asarray(means, dtype=float)
    variances = np.asarray(variances, dtype=float)
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    with threadpool_limits(limits=1):
        for state in range(len(means)):
            initial = _split_start(means, variances, state, rng)
            row, model = _fit_one_start(
                X, len(means) + 1, -1, max_iter, tol, var_floor, initial=initial
            )
            note = f"split of state {state + 1} of the K={len(means)} fit"
            row["message"] = f"{note}; {row['message']}" if row["message"] else note
            rows.append({"restart": first_restart + state, **row})
            usable = model is not None and row["status"] != "degenerate"
            if usable and (best is None or row["log_likelihood"] > best[0]):
                best = (row["log_likelihood"], model.means_.copy(), _variances(model))
    table = pd.DataFrame(rows, columns=list(_RESTART_COLUMNS))
    return table, None if best is None else (best[1], best[2])


def _restart_seeds(seed: int | Sequence[int], n_restarts: int) -> list[int]:
    children = np.random.SeedSequence(seed).spawn(n_restarts)
    return [int(child.generate_state(1, dtype=np.uint32)[0]) for child in children]


def _freeze(array: np.ndarray) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


def _fit_starts(
    X: np.ndarray,
    n_states: int,
    seed: int | Sequence[int],
    n_restarts: int,
    max_iter: int,
    tol: float,
    var_floor: float,
    start: str = "dirichlet",
) -> tuple[pd.DataFrame, dict[int, GaussianHMM]]:
    """Run every EM start; return the table of starts and the usable models by start number.

    The table has the columns of :data:`_RESTART_COLUMNS`, one row per start (1-based
    ``restart``); failed and degenerate starts are in the table but not among the models.
    """
    rows = []
    models: dict[int, GaussianHMM] = {}
    for restart, start_seed in enumerate(_restart_seeds(seed, n_restarts), start=1):
        row, model = _fit_one_start(X, n_states, start_seed, max_iter, tol, var_floor, start)
        rows.append({"restart": restart, **row})
        logger.info(
            "fit_hmm K=%d restart %d/%d: status=%s logL=%.4f n_iter=%d",
            n_states,
            restart,
            n_restarts,
            row["status"],
            row["log_likelihood"],
            row["n_iter"],
        )
        if model is not None and row["status"] != "degenerate":
            models[restart] = model
    return pd.DataFrame(rows, columns=list(_RESTART_COLUMNS)), models


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
    uniform (depmixS4's ``random.start``). EM (Eqs. (4)–(9)) runs in hmmlearn with
    ``implementation="scaling"``, restarting from the same point with ``"log"`` if scaling
    fails; BLAS is held to one thread. A start is ``ok`` when the tolerance stopped it, its
    parameters are finite and its log-likelihood never fell by more than round-off;
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
    max_iter = _require_count("max_iter", max_iter, 1)
    tol = require_positive("tol", tol)
    var_floor = require_positive("var_floor", var_floor)
    if start not in START_METHODS:
        raise DtwinValueError(f"start must be one of {', '.join(START_METHODS)} (got {start!r})")
    if len(X) <= n_states:
        raise DtwinValueError(f"X must have more rows than n_states={n_states} (got {len(X)})")

    with threadpool_limits(limits=1):
        restarts, models = _fit_starts(
            X, n_states, seed, n_restarts, max_iter, tol, var_floor, start
        )
        if not models:
            raise HmmFitError(
                f"fit_hmm: all {n_restarts} starts failed or degenerated (K={n_states}); "
                f"statuses: {', '.join(restarts['status'])}"
            )
        restart_viterbi = np.full((n_restarts, len(X)), -1, dtype=int)
        for restart, fitted in models.items():
            restart_viterbi[restart - 1] = fitted.decode(X, algorithm="viterbi")[1]
        usable = restarts[restarts["restart"].isin(models)]
        best = int(usable.loc[usable["log_likelihood"].idxmax(), "restart"])
        model = models[best]
        best_row = restarts.loc[restarts["restart"] == best].iloc[0]
        log_likelihood = float(model.score(X))
        smoothed = model.predict_proba(X)
        viterbi = model.decode(X, algorithm="viterbi")[1]
        variances = _variances(model)
        filtered, _ = _forward_filter(X, model.startprob_, model.transmat_, model.means_, variances)
    n_params = n_hmm_params(n_states, X.shape[1])
    logger.info(
        "fit_hmm K=%d: best logL=%.4f (restart %d of %d; %d usable)",
        n_states,
        log_likelihood,
        best,
        n_restarts,
        len(models),
    )
    return HmmFit(
        startprob=_freeze(model.startprob_),
        transmat=_freeze(model.transmat_),
        means=_freeze(model.means_),
        sds=_freeze(np.sqrt(variances)),
        log_likelihood=log_likelihood,
        n_params=n_params,
        bic=-2.0 * log_likelihood + n_params * math.log(len(X)),
        n_iter=int(best_row["n_iter"]),
        converged=bool(best_row["converged"]),
        restarts=restarts,
        best_restart=best,
        smoothed=_freeze(smoothed),
        filtered=_freeze(filtered),
        viterbi=_freeze(viterbi.astype(int)),
        restart_viterbi=_freeze(restart_viterbi),
    )


# --- filtering ------------------------------------------------------------------------------


def _log_emission(X: np.ndarray, means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """``log N(x_t | μ_k, diag σ_k²)``, shape (T, K), as two matrix products.

    ``−½[Σ_d x²/σ² − 2 x·(μ/σ²) + Σ_d μ²/σ² + Σ_d log(2πσ²)]``, evaluated in place on two
    T×K arrays; the one T×D temporary (``X²``) is freed before the second product.
    ``2·(X·M)`` is bit-identical to ``(2X)·M`` (doubling is exact in floating point outside
    the subnormal range), so the values are those of the plain expression.
    """
    precision = 1.0 / variances
    quadratic = (X**2) @ precision.T
    cross = X @ (means * precision).T
    cross *= 2.0
    quadratic -= cross
    del cross
    quadratic += (means**2 * precision).sum(axis=1) + np.log(2.0 * np.pi * variances).sum(axis=1)
    quadratic *= -0.5
    return quadratic


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
    log_b = _log_emission(X, means, variances)
    peak = log_b.max(axis=1)
    emission = np.exp(log_b - peak[:, None])
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
    entries = np.empty((n_blocks, n_states))
    alpha = start
    for index in range(n_blocks):
        entries[index] = alpha
        alpha = prefix[index, -1] @ alpha
        alpha = alpha / alpha.sum()
    alphas = np.einsum("bjik,bk->bji", prefix, entries).reshape(-1, n_states)[:n_steps]
    return alphas / alphas.sum(axis=1, keepdims=True)


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
    usable = ~restarts["status"].isin(["failed", "degenerate"])
    values = restarts["log_likelihood"].where(usable)
    n_random = len(restarts) if n_random is None else int(n_random)
    half = max(1, n_random // 2)
    in_half = np.arange(len(restarts)) < half
    in_half[n_random:] = True
    return {
        "K": int(n_states),
        "log_likelihood": float(values.max()),
        "n_params": int(n_params),
        "bic": float(bic),
        "converged": bool(converged),
        "n_usable": int(usable.sum()),
        "log_likelihood_half": float(values[in_half].max()),
        "n_starts": n_random,
        "n_split_starts": len(restarts) - n_random,
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
    em = {key: fit_options[key] for key in ("max_iter", "tol", "var_floor") if key in fit_options}
    return split_fits(X, *grow_from, seed=[*entropy, k, 2], **em)


def _combined_row(
    fit: HmmFit,
    splits: pd.DataFrame | None,
    grown: tuple[np.ndarray, np.ndarray] | None,
    n_samples: int,
) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """Return the BIC row of a K's random and split starts, and the best emissions."""
    n_random = len(fit.restarts)
    restarts, best = fit.restarts, (np.array(fit.means), np.array(fit.sds) ** 2)
    log_likelihood, converged = fit.log_likelihood, fit.converged
    if splits is not None:
        splits = splits.assign(restart=splits["restart"] + n_random)
        restarts = pd.concat([restarts, splits], ignore_index=True)
        usable = splits[~splits["status"].isin(["failed", "degenerate"])]
        if grown is not None and usable["log_likelihood"].max() > log_likelihood:
            top = usable.loc[usable["log_likelihood"].idxmax()]
            log_likelihood, converged, best = (
                float(top["log_likelihood"]),
                bool(top["converged"]),
                grown,
            )
    bic = -2.0 * log_likelihood + fit.n_params * math.log(n_samples)
    row = bic_row(fit.n_states, restarts, fit.n_params, bic, converged, n_random=n_random)
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

    With ``max_restarts``, the random starts are doubled (the seeds are prefix-stable, so the
    first ones are the same fits) while the second half still gains :data:`STABLE_GAIN` or
    more log-likelihood and the doubled count stays within ``max_restarts``.
    """
    splits, grown = _grown_splits(X, k, entropy, grow_from, fit_options)
    n = n_restarts
    while True:
        fit = fit_hmm(X, k, n_restarts=n, seed=[*entropy, k], **fit_options)
        row, best = _combined_row(fit, splits, grown, len(X))
        gain = row["log_likelihood"] - row["log_likelihood_half"]
        if max_restarts is None or gain < STABLE_GAIN or 2 * n > max_restarts:
            return row, best
        logger.info("bic_by_k K=%d: %d starts gain %.3f over %d; doubling", k, n, gain, n // 2)
        n *= 2


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
    for k in [*ks, *range(max(ks) + 1, k_last + 1)]:
        if k > max(ks) and bic_minimum_bracketed([r["bic"] for r in rows], stop_after_rises):
            break
        if k in given:
            row = dict(given[k])
            best = _given_params(row)
            row.setdefault("n_split_starts", 0)
        else:
            grow_from = best if split_starts else None
            row, best = _sweep_row(X, k, n_restarts, entropy, grow_from, fit_options, max_restarts)
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
