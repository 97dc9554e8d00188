"""The EM random starts of fit_hmm: k-means++ beside depmixS4's Dirichlet."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin._validation import DtwinValueError
from dtwin.hmm import START_METHODS, fit_hmm


def test_kmeanspp_start_puts_the_states_apart():
    rng = np.random.default_rng(4)
    X = np.concatenate([rng.normal(c, 0.1, (100, 2)) for c in (-3.0, 0.0, 3.0)])
    spread = {}
    for name, start in START_METHODS.items():
        means, variances, occupancy = start(X, 3, np.random.default_rng(0), 1e-3)
        assert means.shape == variances.shape == (3, 2) and occupancy.sum() == pytest.approx(300)
        spread[name] = float(np.ptp(means[:, 0]))
    # Dirichlet(0.01) weights are a near-random assignment: every state starts near the mean.
    assert spread["dirichlet"] < 1.0 < 5.0 < spread["kmeans++"]


def test_both_starts_fit_and_an_unknown_start_is_one_clear_error():
    rng = np.random.default_rng(1)
    X = np.concatenate([rng.normal(-2, 1, (100, 2)), rng.normal(2, 1, (100, 2))])
    fits = {name: fit_hmm(X, 2, n_restarts=2, seed=1, start=name) for name in START_METHODS}
    for fit in fits.values():
        assert sorted(np.round(fit.means[:, 0]).tolist()) == [-2.0, 2.0]
    with pytest.raises(DtwinValueError, match="start must be one of dirichlet, kmeans"):
        fit_hmm(X, 2, start="random")
