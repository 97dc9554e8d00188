"""hmmlearn as the reference EM engine (paper §2.1, §5).

The regime HMMs run EM in :mod:`dtwin._em_kernels` (scaled recursions, and log-space ones
where those underflow); this module keeps hmmlearn 0.3.3 as the reference the tests compare
the kernels with (config ``hmm.engine: hmmlearn`` runs every fit here, or numba is missing),
for :func:`dtwin.hmm.to_hmmlearn` and for scoring an AR(1)-HMM whose scaled forward pass
underflows. It is imported only then, so a compiled fit loads neither hmmlearn nor
scikit-learn.

The Gaussian model (:class:`_MatmulGaussianHMM`) and the AR(1) model (:class:`_ArGaussianHMM`)
extend hmmlearn through its documented hooks: the emission methods its own model classes
define and the convergence monitor ``monitor_`` (here with depmixS4's relative stopping rule
and, for the Gaussian model, the variance floor after each M-step).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from hmmlearn import _hmmc
from hmmlearn.base import BaseHMM, ConvergenceMonitor
from hmmlearn.hmm import GaussianHMM
from hmmlearn.utils import normalize

from dtwin._em_data import GAUSSIAN, EmData, EmError, EmRun
from dtwin._emissions import _ar_log_emission, _ar_mstep, _log_emission, _moments

#: Letter of the AR emission parameters (c, φ, σ²) in hmmlearn's ``params`` string.
_EMISSION = "e"

__all__ = ["diag_variances", "fitted_model", "new_gaussian_model", "run_em", "score", "viterbi"]


# --- Gaussian emissions ---------------------------------------------------------------------


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
    These are the places dtwin goes below hmmlearn's public methods; ``tests/concepts/test_hmm.py``
    checks both against hmmlearn's own density and E-step (the latter bit for bit) on every
    run, so a release that changes the hooks fails loudly (hmmlearn is pinned
    ``>=0.3.3,<0.4``).
    """

    def _compute_log_likelihood(self, X: np.ndarray) -> np.ndarray:
        variances = np.maximum(diag_variances(self), np.finfo(float).tiny)
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


def new_gaussian_model(n_states: int, implementation: str, n_iter: int = 1) -> GaussianHMM:
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


def set_gaussian_params(
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


def diag_variances(model: GaussianHMM) -> np.ndarray:
    """Return the (K, D) variances of a diagonal model (its public ``covars_`` is (K, D, D))."""
    return np.diagonal(model.covars_, axis1=1, axis2=2).copy()


class _RelativeMonitor(ConvergenceMonitor):
    """depmixS4's stopping rule ``(LL − LL_old)/|LL_old| < tol``; records the history."""

    def __init__(self, tol: float, n_iter: int):
        super().__init__(tol, n_iter, verbose=False)
        self.log_likelihoods: list[float] = []
        self.stopped_by_tol = False
        self.non_finite = False

    def report(self, log_prob: float) -> None:
        super().report(log_prob)
        self.log_likelihoods.append(float(log_prob))
        if not np.isfinite(log_prob):
            self.non_finite = True

    @property
    def converged(self) -> bool:
        history = self.log_likelihoods
        if self.non_finite or self.iter >= self.n_iter:
            return True
        if len(history) >= 2 and (history[-1] - history[-2]) < self.tol * abs(history[-2]):
            self.stopped_by_tol = True
            return True
        return False


class _DepmixMonitor(_RelativeMonitor):
    """hmmlearn convergence monitor with depmixS4's rule and a variance floor.

    hmmlearn documents subclassing :class:`~hmmlearn.base.ConvergenceMonitor` to change the
    stopping rule. ``report`` runs once per EM iteration, right after the M-step: it records
    the log-likelihood of the parameters that entered the iteration and floors the new
    variances (the exact M-step under ``σ² ≥ var_floor``, so EM stays monotone). ``converged``
    stops on ``(LL − LL_old)/|LL_old| < tol``, at the iteration cap, or on non-finite values.
    """

    def __init__(self, model: GaussianHMM, tol: float, n_iter: int, var_floor: float):
        super().__init__(tol, n_iter)
        self.model = model
        self.var_floor = var_floor

    def report(self, log_prob: float) -> None:
        super().report(log_prob)
        model = self.model
        variances = diag_variances(model)
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


def _gaussian_em(
    X: np.ndarray, emission: np.ndarray, implementation: str, options: Mapping[str, Any]
) -> EmRun:
    """Run EM in one hmmlearn ``fit`` from the given emission start, π and A uniform."""
    n_states = emission.shape[1]
    model = new_gaussian_model(n_states, implementation, n_iter=options["max_iter"])
    uniform = np.full(n_states, 1.0 / n_states)
    set_gaussian_params(model, uniform, np.tile(uniform, (n_states, 1)), *emission)
    monitor = _DepmixMonitor(model, options["tol"], options["max_iter"], options["var_floor"])
    model.monitor_ = monitor
    model.fit(X)
    if monitor.non_finite:
        raise EmError(f"non-finite log-likelihood or parameters ({implementation})")
    final, posteriors = model.score_samples(X)
    if not np.isfinite(final):
        raise EmError(f"non-finite final log-likelihood ({implementation})")
    return EmRun(
        model.startprob_,
        model.transmat_,
        np.stack([model.means_, diag_variances(model)]),
        np.array([*monitor.log_likelihoods, float(final)]),
        monitor.stopped_by_tol,
        posteriors,
        implementation,
    )


# --- AR(1) emissions ------------------------------------------------------------------------


class _ArGaussianHMM(BaseHMM):
    """hmmlearn HMM with a diagonal Gaussian AR(1) emission per state.

    Fitted on :func:`_design` rows; attributes ``intercepts_``, ``coefs_``, ``variances_``
    (K, D). ``params`` letters: ``s`` (π), ``t`` (A), ``e`` (the emission).
    """

    def __init__(
        self,
        n_components: int = 1,
        var_floor: float = 1e-6,
        algorithm: str = "viterbi",
        random_state: Any = None,
        n_iter: int = 10,
        tol: float = 0.0,
        verbose: bool = False,
        params: str = "ste",
        init_params: str = "",
        implementation: str = "scaling",
    ):
        super().__init__(
            n_components=n_components,
            startprob_prior=1.0,
            transmat_prior=1.0,
            algorithm=algorithm,
            random_state=random_state,
            n_iter=n_iter,
            tol=tol,
            verbose=verbose,
            params=params,
            init_params=init_params,
            implementation=implementation,
        )
        self.var_floor = var_floor

    def _get_n_fit_scalars_per_param(self) -> dict[str, int]:
        k, d = self.n_components, self.n_features // 5
        return {"s": k - 1, "t": k * (k - 1), _EMISSION: 3 * k * d}

    def _compute_log_likelihood(self, X: np.ndarray) -> np.ndarray:
        return _ar_log_emission(X, self.intercepts_, self.coefs_, self.variances_)

    def _initialize_sufficient_statistics(self) -> dict[str, Any]:
        stats = super()._initialize_sufficient_statistics()
        stats["moments"] = None
        return stats

    def _accumulate_sufficient_statistics(
        self, stats, X, lattice, posteriors, fwdlattice, bwdlattice
    ) -> None:
        super()._accumulate_sufficient_statistics(
            stats, X, lattice, posteriors, fwdlattice, bwdlattice
        )
        if _EMISSION in self.params:
            moments = _moments(posteriors, X)
            if stats["moments"] is not None:
                moments = {key: stats["moments"][key] + value for key, value in moments.items()}
            stats["moments"] = moments

    def _do_mstep(self, stats: dict[str, Any]) -> None:
        super()._do_mstep(stats)
        if _EMISSION in self.params and stats["moments"] is not None:
            self.intercepts_, self.coefs_, self.variances_ = _ar_mstep(
                stats["moments"], self.var_floor
            )


def new_ar_model(
    startprob: np.ndarray,
    transmat: np.ndarray,
    emission: tuple[np.ndarray, np.ndarray, np.ndarray],
    implementation: str,
    max_iter: int = 1,
    var_floor: float = 1e-6,
) -> _ArGaussianHMM:
    model = _ArGaussianHMM(
        n_components=len(startprob),
        var_floor=var_floor,
        n_iter=max_iter,
        implementation=implementation,
    )
    model.n_features = 5 * emission[0].shape[1]
    model.startprob_ = np.array(startprob, dtype=float)
    model.transmat_ = np.array(transmat, dtype=float)
    model.intercepts_, model.coefs_, model.variances_ = (np.array(a, dtype=float) for a in emission)
    return model


def _ar_em(
    design: np.ndarray, emission: np.ndarray, implementation: str, options: Mapping[str, Any]
) -> EmRun:
    """One hmmlearn ``fit`` of the AR(1)-HMM from the given emission start (π and A uniform)."""
    n_states = emission.shape[1]
    uniform = np.full(n_states, 1.0 / n_states)
    model = new_ar_model(
        uniform,
        np.tile(uniform, (n_states, 1)),
        tuple(emission),
        implementation,
        options["max_iter"],
        options["var_floor"],
    )
    monitor = _RelativeMonitor(options["tol"], options["max_iter"])
    model.monitor_ = monitor
    with np.errstate(under="ignore"):
        model.fit(design)
        final, posteriors = model.score_samples(design)
    parameters = (model.intercepts_, model.coefs_, model.variances_, model.transmat_)
    if (
        monitor.non_finite
        or not np.isfinite(final)
        or not all(np.isfinite(p).all() for p in parameters)
    ):
        raise FloatingPointError(f"non-finite log-likelihood or parameters ({implementation})")
    return EmRun(
        model.startprob_,
        model.transmat_,
        np.stack([model.intercepts_, model.coefs_, model.variances_]),
        np.array([*monitor.log_likelihoods, float(final)]),
        monitor.stopped_by_tol,
        posteriors,
        implementation,
    )


# --- the engine -----------------------------------------------------------------------------


def run_em(
    data: EmData, emission: np.ndarray, implementation: str, options: Mapping[str, Any]
) -> EmRun:
    """EM from one emission start in hmmlearn (``scaling`` or ``log``); raises on failure."""
    run = _gaussian_em if data.kind == GAUSSIAN else _ar_em
    return run(data.reference, emission, implementation, options)


def fitted_model(data: EmData, run: EmRun) -> BaseHMM:
    """Return the hmmlearn model holding ``run``'s parameters (in its implementation)."""
    if data.kind == GAUSSIAN:
        model = new_gaussian_model(len(run.startprob), run.implementation)
        model.n_features = run.emission.shape[2]
        return set_gaussian_params(model, run.startprob, run.transmat, *run.emission)
    return new_ar_model(run.startprob, run.transmat, tuple(run.emission), run.implementation)


def viterbi(data: EmData, run: EmRun) -> np.ndarray:
    """Hmmlearn's Viterbi path of the training rows under ``run``'s parameters."""
    with np.errstate(under="ignore"):
        return fitted_model(data, run).decode(data.reference, algorithm="viterbi")[1]


def score(data: EmData, startprob, transmat, emission, implementation: str = "log") -> float:
    """Hmmlearn's log p(rows) under the given parameters."""
    run = EmRun(startprob, transmat, emission, np.empty(0), False, np.empty((0, 0)), implementation)
    with np.errstate(under="ignore"):
        return float(fitted_model(data, run).score(data.reference))
