"""The regime model of a twin's residuals: the paper's HMM, its nominal regimes and ``unknown``.

Specification: docs/monitor.md §Regimes. The residual channels of the causal twin
(:mod:`dtwin.monitor.causal_twin`) are z-scored and a K-state Gaussian HMM is fitted to them
(paper §4.2, :func:`dtwin.hmm.fit_hmm`, the multi-start EM of the DAG's regime stage, its starts
on at most :data:`MAX_SWEEP_SAMPLES` rows and the best one run on over every row), K chosen by
the BIC with its minimum bracketed (§5, :func:`dtwin.hmm.bic_by_k`) unless given.
A regime is **nominal** when it holds at least :data:`NOMINAL_SHARE` of the nominal stretch
(smoothed occupancy; the regime holding most of it always is). A model fitted on a clean
recording may hold nominal regimes only, so the filter has one more state, ``unknown``: a broad
Gaussian (:data:`UNKNOWN_SD` z-units per channel about the nominal regimes' mean) entered with
probability :data:`UNKNOWN_HAZARD` per sample from any regime and left with probability
``1 − UNKNOWN_STAY`` towards the nominal regimes. Its posterior is a Bayesian change test:
a residual that no fitted regime explains moves the filter into it within a few samples.

:class:`RegimeModel` is the fitted model as the monitor needs it (``regimes.json``'s
``model``): z-scoring, the K regimes, the unknown state, the correction's state means and
shaping. Arrays are time-first.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.bias_correction import state_residual_means
from dtwin.config_sections import EmSettings, HmmSettings
from dtwin.hmm import HmmFit, ZScored, bic_by_k, fit_hmm, zscore
from dtwin.monitor._stream_kernels import filter_rows, standardise_rows
from dtwin.monitor.novelty import NoveltyTest, fit_novelty
from dtwin.state_tables import state_labels

__all__ = [
    "UNKNOWN",
    "UNKNOWN_SD",
    "UNKNOWN_HAZARD",
    "UNKNOWN_STAY",
    "NOMINAL_SHARE",
    "MAX_SWEEP_SAMPLES",
    "REGIME_EM",
    "RegimeSettings",
    "FilterArrays",
    "RegimeModel",
    "RegimeFit",
    "fit_regime_model",
    "sweep_rows",
    "simulate_regimes",
    "poisson_upper",
]

#: Label of the regime no fitted regime explains.
UNKNOWN = "unknown"
#: Standard deviation of the unknown regime's emission, z-units of each channel.
UNKNOWN_SD = 4.0
#: Probability per sample of entering the unknown regime from any fitted regime.
UNKNOWN_HAZARD = 1e-9
#: Probability per sample of staying in the unknown regime.
UNKNOWN_STAY = 0.99
#: Smallest share of the nominal stretch (smoothed occupancy) a nominal regime holds.
NOMINAL_SHARE = 0.02
#: Most samples the BIC sweep over K and the final fit's starts use (evenly spaced contiguous
#: blocks beyond it).
MAX_SWEEP_SAMPLES = 20_000
#: Contiguous blocks of the sweep's sample when it is capped.
SWEEP_BLOCKS = 8
#: EM options of ``dtwin regimes``: k-means++ starts (a Dirichlet start's states begin alike
#: and EM can stop at that symmetric point on two well separated residual levels), a relative
#: tolerance of 1e-6 and at most 200 iterations per start.
REGIME_EM = EmSettings(max_iter=200, tol=1e-6, start="kmeans++")


@dataclass(frozen=True)
class RegimeSettings:
    """How ``dtwin regimes`` fits the regime model (the command line's options).

    Attributes
    ----------
    n_states : int or None
        K; None: chosen by the BIC over ``1 … k_max``.
    k_max : int
        Largest K of the BIC sweep.
    n_restarts : int
        EM starts per K, the best kept.
    seed : int
        Entropy of every random draw (EM starts, the false-alarm simulation).
    em : EmSettings
        EM options (``max_iter``, ``tol``, ``var_floor``, ``start``; :data:`REGIME_EM`).
    kappa, ema_alpha : float
        The correction's gain and EMA weight (paper §4.3).
    rate_max : float
        The correction's largest step per sample, in residual standard deviations.
    """

    n_states: int | None = None
    k_max: int = 8
    n_restarts: int = 5
    seed: int = 0
    em: EmSettings = field(default_factory=lambda: REGIME_EM)
    kappa: float = 0.8
    ema_alpha: float = 0.15
    rate_max: float = 0.5


class FilterArrays(NamedTuple):
    """The K + 1 states of the filter (the fitted regimes, then ``unknown``), z-units."""

    means: np.ndarray
    precision: np.ndarray
    log_norm: np.ndarray
    transmat: np.ndarray
    start: np.ndarray


def _array(raw: Mapping, key: str, shape: tuple[int, ...]) -> np.ndarray:
    value = np.asarray(raw[key], dtype=float)
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise DtwinValueError(f"regimes file: model.{key} must be finite of shape {shape}")
    return value


@dataclass(frozen=True)
class RegimeModel:
    """The fitted regime model (module docstring); arrays in z-units unless said.

    Attributes
    ----------
    channels : tuple of str
        Residual channels ``<unit>:<signal>``.
    center, scale : ndarray, shape (C,)
        Each channel's mean and sample standard deviation (its units): ``z = (e − center)/scale``.
    startprob, occupancy : ndarray, shape (K,)
        The fit's initial distribution and each regime's share of the fitted samples.
    transmat : ndarray, shape (K, K)
    means, sds : ndarray, shape (K, C)
    nominal : tuple of bool, length K
    state_means : ndarray, shape (K, C)
        Each regime's posterior-weighted mean residual, channel units (the correction's μ).
    unknown_sd, hazard, stay : float
        The unknown regime (:data:`UNKNOWN_SD`, :data:`UNKNOWN_HAZARD`, :data:`UNKNOWN_STAY`).
    kappa, ema_alpha, rate_max : float
        The correction's shaping (:class:`RegimeSettings`).
    novelty : NoveltyTest or None
        The novelty test on the innovations (:mod:`dtwin.monitor.novelty`); None: none.
    """

    channels: tuple[str, ...]
    center: np.ndarray
    scale: np.ndarray
    startprob: np.ndarray
    occupancy: np.ndarray
    transmat: np.ndarray
    means: np.ndarray
    sds: np.ndarray
    nominal: tuple[bool, ...]
    state_means: np.ndarray
    unknown_sd: float = UNKNOWN_SD
    hazard: float = UNKNOWN_HAZARD
    stay: float = UNKNOWN_STAY
    kappa: float = 0.8
    ema_alpha: float = 0.15
    rate_max: float = 0.5
    novelty: NoveltyTest | None = None

    @property
    def n_states(self) -> int:
        """K, the fitted regimes (without ``unknown``)."""
        return len(self.startprob)

    @property
    def labels(self) -> tuple[str, ...]:
        """``S1 … SK`` then :data:`UNKNOWN`: the filter's states."""
        return (*state_labels(self.n_states), UNKNOWN)

    @property
    def nominal_mask(self) -> np.ndarray:
        """Bool, shape (K + 1,): the nominal regimes (``unknown`` never is)."""
        return np.array([*self.nominal, False])

    def filter_arrays(self) -> FilterArrays:
        """Return the K + 1 filter states: the fitted regimes, then ``unknown``."""
        k, c = self.means.shape
        weights = self.occupancy * np.asarray(self.nominal, dtype=float)
        weights = weights / weights.sum()
        means = np.vstack([self.means, weights @ self.means])
        variances = np.vstack([self.sds**2, np.full(c, self.unknown_sd**2)])
        transmat = np.zeros((k + 1, k + 1))
        transmat[:k, :k] = (1.0 - self.hazard) * self.transmat
        transmat[:k, k] = self.hazard
        transmat[k, :k] = (1.0 - self.stay) * weights
        transmat[k, k] = self.stay
        start = np.append((1.0 - self.hazard) * self.occupancy, self.hazard)
        log_norm = -0.5 * np.log(2.0 * np.pi * variances).sum(axis=1)
        return FilterArrays(means, 1.0 / variances, log_norm, transmat, start)

    def to_mapping(self) -> dict[str, Any]:
        """Return the model as plain data (``regimes.json``'s ``model``)."""
        out = {"channels": list(self.channels), "labels": list(self.labels)}
        for key in ("center", "scale", "startprob", "occupancy", "transmat", "means", "sds"):
            out[key] = getattr(self, key).tolist()
        out["nominal"] = list(self.nominal)
        out["state_means"] = self.state_means.tolist()
        for key in ("unknown_sd", "hazard", "stay", "kappa", "ema_alpha", "rate_max"):
            out[key] = float(getattr(self, key))
        out["novelty"] = None if self.novelty is None else self.novelty.to_mapping()
        return out

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any]) -> RegimeModel:
        """Return the model of ``regimes.json``'s ``model`` (shapes and values checked)."""
        try:
            channels = tuple(str(c) for c in raw["channels"])
            k, c = len(raw["startprob"]), len(channels)
            arrays = {"center": (c,), "scale": (c,), "startprob": (k,), "occupancy": (k,),
                      "transmat": (k, k), "means": (k, c), "sds": (k, c),
                      "state_means": (k, c)}  # fmt: skip
            values = {key: _array(raw, key, shape) for key, shape in arrays.items()}
            scalars = ("unknown_sd", "hazard", "stay", "kappa", "ema_alpha", "rate_max")
            numbers = {key: float(raw[key]) for key in scalars}
            nominal = tuple(bool(v) for v in raw["nominal"])
        except (KeyError, TypeError, ValueError) as error:
            raise DtwinValueError(f"regimes file: model is malformed ({error})") from error
        if len(nominal) != k or not any(nominal) or np.any(values["sds"] <= 0):
            raise DtwinValueError("regimes file: model.nominal or model.sds is not valid")
        novelty = raw.get("novelty")
        if novelty is not None:
            novelty = NoveltyTest.from_mapping(novelty, c)
        return cls(channels=channels, nominal=nominal, novelty=novelty, **values, **numbers)

    def standardised(self, z: np.ndarray) -> np.ndarray:
        """Return z-scored rows of a sequence standardised by the nominal regimes' prediction.

        The filter is run over ``z`` (shape (n, C)) from its start, and each row standardised
        by the nominal regimes' one-step predictive mean and sd
        (:func:`dtwin.monitor._stream_kernels.standardise_rows`); shape (n, C).
        """
        arrays = self.filter_arrays()
        z = np.ascontiguousarray(z, dtype=float)
        posteriors = filter_rows(z, arrays.means, arrays.precision, arrays.log_norm,
                                 arrays.transmat, arrays.start.copy(), True)  # fmt: skip
        return standardise_rows(z, posteriors, arrays.start, True, arrays.transmat, self.means,
                                self.sds**2, np.asarray(self.nominal))  # fmt: skip


@dataclass(frozen=True)
class RegimeFit:
    """A fitted regime model with what it was fitted from.

    Attributes
    ----------
    model : RegimeModel
    scaled : ZScored
        The z-scored residuals of the fitted samples.
    fit : HmmFit
        The K-state fit (smoothed posteriors over the fitted samples).
    bic : DataFrame or None
        The BIC sweep (:func:`dtwin.hmm.bic_by_k`'s columns), None when K was given.
    sweep_samples : int
        Samples the sweep fitted.
    """

    model: RegimeModel
    scaled: ZScored
    fit: HmmFit
    bic: pd.DataFrame | None
    sweep_samples: int


def sweep_rows(n: int, cap: int = MAX_SWEEP_SAMPLES, blocks: int = SWEEP_BLOCKS) -> np.ndarray:
    """Rows of the BIC sweep: all ``n`` rows, or ``blocks`` contiguous blocks of ``cap`` in all.

    Examples
    --------
    >>> sweep_rows(10, cap=4, blocks=2).tolist()
    [0, 1, 8, 9]
    """
    if n <= cap:
        return np.arange(n)
    length = cap // blocks
    firsts = np.round(np.linspace(0, n - length, blocks)).astype(int)
    return np.concatenate([np.arange(a, a + length) for a in firsts])


def _chosen_k(z: np.ndarray, settings: RegimeSettings) -> tuple[int, pd.DataFrame | None, int]:
    """K (given, or at the BIC's minimum over a sweep on at most MAX_SWEEP_SAMPLES rows)."""
    if settings.n_states is not None:
        return settings.n_states, None, 0
    rows = sweep_rows(len(z))
    ks = [k for k in (1, 2, 3) if k <= settings.k_max]
    table = bic_by_k(
        z[rows], ks, n_restarts=settings.n_restarts, seed=settings.seed,
        k_max=settings.k_max, **settings.em.options(),
    )  # fmt: skip
    return int(table.loc[table["bic"].idxmin(), "K"]), table, len(rows)


def _fitted_hmm(z: np.ndarray, k: int, settings: RegimeSettings) -> HmmFit:
    """Return the K-state HMM of the z-scored rows ``z`` (T, C).

    The multi-start EM (:func:`dtwin.hmm.fit_hmm`) runs on the sweep's rows
    (:func:`sweep_rows`: every row up to :data:`MAX_SWEEP_SAMPLES`); on a longer recording its
    best start is then run on to convergence over every row (one more EM run, started from its
    emissions). The starts only have to find the optimum's basin, which a sample of the
    recording shows; at 100,000 rows this takes a fifth of the time of every start on every row.
    """
    hmm = HmmSettings(n_states=k, n_restarts=settings.n_restarts, em=settings.em)
    rows = sweep_rows(len(z))
    best = fit_hmm(z[rows], k, seed=[settings.seed, k], **hmm.fit_options())
    if len(rows) == len(z):
        return best
    return fit_hmm(z, k, seed=settings.seed, start_from=best, **settings.em.options())


def _nominal(fit: HmmFit, nominal_rows: np.ndarray) -> tuple[bool, ...]:
    """Return the regimes holding NOMINAL_SHARE of the nominal stretch (the largest always)."""
    share = fit.smoothed[nominal_rows].mean(axis=0)
    chosen = share >= NOMINAL_SHARE
    chosen[int(np.argmax(share))] = True
    return tuple(bool(v) for v in chosen)


def fit_regime_model(
    residuals: pd.DataFrame, nominal_rows: Any, settings: RegimeSettings | None = None
) -> RegimeFit:
    """Fit the regime model to residual channels (module docstring).

    Parameters
    ----------
    residuals : DataFrame, shape (T, C)
        Finite residuals (channel units), columns the channels.
    nominal_rows : array of bool, shape (T,)
        The nominal stretch among the rows (at least one row).
    settings : RegimeSettings, optional

    Returns
    -------
    RegimeFit
    """
    settings = settings or RegimeSettings()
    nominal_rows = np.asarray(nominal_rows, dtype=bool)
    if len(nominal_rows) != len(residuals) or not nominal_rows.any():
        raise DtwinValueError("the nominal stretch holds no sample after the settling period")
    if len(residuals) < 2 * settings.k_max + 10:
        raise DtwinValueError(
            f"too few samples after the settling period to fit regimes ({len(residuals)})"
        )
    scale = residuals.std(axis=0, ddof=1).to_numpy()
    if not np.all(scale > 0):
        flat = [c for c, s in zip(residuals.columns, scale, strict=True) if not s > 0]
        raise DtwinValueError(f"residual channel(s) {', '.join(flat)} do not vary: no regimes")
    scaled = zscore(residuals)
    k, bic, n_sweep = _chosen_k(scaled.values, settings)
    fit = _fitted_hmm(scaled.values, k, settings)
    model = RegimeModel(
        channels=tuple(residuals.columns),
        center=np.asarray(scaled.mean, dtype=float),
        scale=np.asarray(scaled.sd, dtype=float),
        startprob=fit.startprob,
        occupancy=fit.smoothed.mean(axis=0),
        transmat=fit.transmat,
        means=fit.means,
        sds=fit.sds,
        nominal=_nominal(fit, nominal_rows),
        state_means=state_residual_means(residuals.to_numpy(), fit.smoothed),
        kappa=settings.kappa,
        ema_alpha=settings.ema_alpha,
        rate_max=settings.rate_max,
    )
    x = model.standardised((residuals.to_numpy() - model.center) / model.scale)
    x[~nominal_rows] = np.nan  # the whitening is fitted on the nominal stretch only
    model = replace(model, novelty=fit_novelty(x))
    return RegimeFit(model, scaled, fit, bic, n_sweep)


def simulate_regimes(model: RegimeModel, n_samples: int, seed: Sequence[int]) -> np.ndarray:
    """Draw ``n_samples`` z-scored residual rows from the K fitted regimes (no ``unknown``).

    Returns
    -------
    ndarray, shape (n_samples, C)
    """
    rng = np.random.default_rng(np.random.SeedSequence(list(seed)))
    last = model.n_states - 1
    rows = np.cumsum(model.transmat, axis=1).tolist()
    draws = rng.random(n_samples).tolist()
    first = np.cumsum(model.occupancy)
    state = min(int(np.searchsorted(first, draws[0] * first[-1], side="right")), last)
    states = [state]
    for draw in draws[1:]:  # a Markov chain: each state from the one before
        row = rows[state]
        state = min(bisect.bisect_right(row, draw * row[-1]), last)
        states.append(state)
    index = np.array(states)
    noise = rng.standard_normal((n_samples, model.means.shape[1]))
    return model.means[index] + model.sds[index] * noise


def poisson_upper(count: int, exposure: float, level: float = 0.95) -> float:
    """One-sided upper bound of a Poisson rate (events per unit of ``exposure``).

    Examples
    --------
    >>> round(poisson_upper(0, 1.0), 3)
    2.996
    """
    from scipy.stats import chi2

    if exposure <= 0:
        return math.inf
    return float(chi2.ppf(level, 2 * (count + 1)) / 2.0 / exposure)
