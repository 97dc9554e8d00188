"""The novelty test: CUSUMs on the residuals' innovations under the fitted nominal model.

Specification: docs/monitor.md §Novelty. The regime filter's ``unknown`` state only catches a
residual that no fitted regime explains sample by sample; a small lasting change (a fraction of
a residual standard deviation, a burst that returns at every input step) never does. This test
accumulates the evidence instead:

1. **centred on the fitted model**: each z-scored residual row is standardised by the one-step
   predictive mean and standard deviation of the nominal regimes (their predicted probabilities
   from the filter's previous row, renormalised: ``x_t = (z_t − m_t) / s_t``), so an excursion
   the nominal regimes hold is no change;
2. **whitened**: each channel's ``x`` follows an AR(p) fitted by least squares on the nominal
   stretch (p ≤ :data:`MAX_LAG` by the BIC); its standardised innovation
   ``ε_t = (x_t − c − Σ a_i x_{t−i}) / σ`` is white N(0, 1) under the model;
3. **tested**: per channel three CUSUMs of log-likelihood ratios (Page's), a mean shift of
   ±:data:`SHIFT` innovation standard deviations (``±δ ε − δ²/2``) and a variance ratio
   :data:`VARIANCE_RATIO` (``−½ ln r + ½ (1 − 1/r) ε²``), each ``S_t = min(max(0, S_{t−1} +
   ℓ_t), 2h)``. The test **alarms** while a statistic is at or above ``h = ln(m · ARL)`` nats
   (``m`` = 3 × channels, ``ARL`` = :data:`ARL_SAMPLES`): by Lorden's bound a CUSUM of a
   log-likelihood ratio crosses ``h`` on data that follow the model once per ``e^h`` samples at
   most, so the whole test at most once per ``ARL`` samples (``3600 / (ARL · dt)`` per hour).
   The cap at ``2h`` brings the test back below ``h`` within about ``h / 0.3`` samples once the
   residuals are nominal again.

A row with a missing value (or with one among its AR lags) leaves the statistics as they were.
The loops are compiled (:func:`dtwin.monitor._stream_kernels.standardise_rows`,
:func:`~dtwin.monitor._stream_kernels.cusum_rows`); this module fits the whitening and holds
the test's constants. Arrays are time-first.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtwin._validation import DtwinValueError

__all__ = [
    "MAX_LAG",
    "SHIFT",
    "VARIANCE_RATIO",
    "ARL_SAMPLES",
    "N_TESTS",
    "NoveltyTest",
    "fit_novelty",
]

#: Largest AR order of the whitening.
MAX_LAG = 5
#: Mean shift each mean CUSUM is designed for, innovation standard deviations.
SHIFT = 1.0
#: Variance ratio the variance CUSUM is designed for (the innovation's sd doubled).
VARIANCE_RATIO = 4.0
#: Samples between false alarms of the whole test on data that follow the model (at least).
ARL_SAMPLES = 1e6
#: CUSUMs per channel: mean up, mean down, variance up.
N_TESTS = 3


@dataclass(frozen=True)
class NoveltyTest:
    """The fitted novelty test (module docstring).

    Attributes
    ----------
    coef : ndarray, shape (C, MAX_LAG + 1)
        Per channel the AR intercept ``c`` then ``a_1 … a_MAX_LAG`` (zeros beyond its order).
    sigma : ndarray, shape (C,)
        Per channel the innovation's standard deviation (units of ``x``).
    order : tuple of int, length C
        Each channel's AR order p (by the BIC).
    shift, ratio, arl : float
        :data:`SHIFT`, :data:`VARIANCE_RATIO`, :data:`ARL_SAMPLES`.
    """

    coef: np.ndarray
    sigma: np.ndarray
    order: tuple[int, ...]
    shift: float = SHIFT
    ratio: float = VARIANCE_RATIO
    arl: float = ARL_SAMPLES

    @property
    def lags(self) -> int:
        """The largest AR order over the channels (the rows of history the test keeps)."""
        return max(self.order)

    @property
    def threshold(self) -> float:
        """``h = ln(3 C · ARL)``, nats."""
        return math.log(N_TESTS * len(self.sigma) * self.arl)

    def per_hour(self, dt: float) -> float:
        """Return the false alarms per hour at most on data that follow the model (``dt`` s)."""
        return 3600.0 / (self.arl * dt)

    def to_mapping(self) -> dict[str, Any]:
        """Return the test as plain data (``regimes.json``'s ``model.novelty``)."""
        return {"coef": self.coef.tolist(), "sigma": self.sigma.tolist(),
                "order": list(self.order), "shift": self.shift, "ratio": self.ratio,
                "arl": self.arl, "threshold_nats": self.threshold}  # fmt: skip

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any], n_channels: int) -> NoveltyTest:
        """Return the test of ``regimes.json``'s ``model.novelty`` (shapes and values checked)."""
        try:
            coef = np.asarray(raw["coef"], dtype=float)
            sigma = np.asarray(raw["sigma"], dtype=float)
            order = tuple(int(v) for v in raw["order"])
            numbers = {key: float(raw[key]) for key in ("shift", "ratio", "arl")}
        except (KeyError, TypeError, ValueError) as error:
            raise DtwinValueError(f"regimes file: model.novelty is malformed ({error})") from error
        valid = (
            coef.shape == (n_channels, MAX_LAG + 1)
            and sigma.shape == (n_channels,)
            and len(order) == n_channels
            and all(0 <= p <= MAX_LAG for p in order)
            and np.all(np.isfinite(coef))
            and np.all(sigma > 0)
            and numbers["shift"] > 0
            and numbers["ratio"] > 1
            and numbers["arl"] > 1
        )
        if not valid:
            raise DtwinValueError("regimes file: model.novelty is not valid")
        return cls(coef, sigma, order, **numbers)


def _ar_fit(x: np.ndarray, p: int) -> tuple[np.ndarray, float, int]:
    """Least-squares AR(p) with intercept on the rows of ``x`` whose lags are known."""
    n = len(x)
    lags = [x[MAX_LAG - i : n - i] for i in range(1, p + 1)]
    lagged = np.column_stack([np.ones(n - MAX_LAG), *lags])
    y = x[MAX_LAG:]
    rows = np.isfinite(y) & np.all(np.isfinite(lagged), axis=1)
    coef, *_ = np.linalg.lstsq(lagged[rows], y[rows], rcond=None)
    innovation = y[rows] - lagged[rows] @ coef
    return coef, float(np.sqrt(np.mean(innovation**2))), int(rows.sum())


def fit_novelty(x: np.ndarray) -> NoveltyTest:
    """Fit the whitening of each channel of standardised residual rows (module docstring).

    Parameters
    ----------
    x : ndarray, shape (T, C)
        Standardised rows of the nominal stretch (:meth:`dtwin.monitor.regime_model.
        RegimeModel.standardised`); NaN rows (outside the stretch) are left out with the rows
        that lag on them.

    Returns
    -------
    NoveltyTest

    Raises
    ------
    DtwinValueError
        If fewer than ``10 · (MAX_LAG + 1)`` rows have known lags.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.standard_normal(5000)
    >>> x = np.empty(5000); x[0] = e[0]
    >>> for t in range(1, 5000): x[t] = 0.6 * x[t - 1] + e[t]
    >>> test = fit_novelty(x[:, None])
    >>> test.order, round(float(test.coef[0, 1]), 2), round(float(test.sigma[0]), 2)
    ((1,), 0.6, 1.0)
    """
    x = np.asarray(x, dtype=float)
    coefs, sigmas, orders = np.zeros((x.shape[1], MAX_LAG + 1)), np.ones(x.shape[1]), []
    for c in range(x.shape[1]):
        best = None
        for p in range(MAX_LAG + 1):
            coef, sigma, n = _ar_fit(x[:, c], p)
            if n < 10 * (MAX_LAG + 1):
                raise DtwinValueError(
                    f"the nominal stretch holds {n} residual rows with known lags: too few "
                    "for the novelty test"
                )
            bic = n * math.log(max(sigma, 1e-300) ** 2) + (p + 1) * math.log(n)
            if best is None or bic < best[0]:
                best = (bic, coef, sigma, p)
        _, coef, sigma, p = best
        coefs[c, : p + 1] = coef
        sigmas[c] = sigma if sigma > 0 else 1.0
        orders.append(p)
    return NoveltyTest(coefs, sigmas, tuple(orders))
