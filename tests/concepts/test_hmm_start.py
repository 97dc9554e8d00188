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


def test_a_fit_on_a_sample_continues_on_every_row_from_its_own_start():
    """start_from: one EM run from a fit's emissions, at least as good as that fit on all rows."""
    rng = np.random.default_rng(3)
    X = np.concatenate([rng.normal(-2, 1, (400, 2)), rng.normal(2, 1, (400, 2))])
    sample = fit_hmm(X[::4], 2, n_restarts=3, seed=2)
    fit = fit_hmm(X, 2, seed=5, start_from=sample)
    assert len(fit.restarts) == 1 and fit.restarts["seed"].tolist() == [5]
    assert np.abs(fit.means - sample.means).max() < 0.3  # the same basin
    again = fit_hmm(X, 2, seed=5, start_from=sample)
    assert again.log_likelihood == fit.log_likelihood
    # the sample's parameters scored on every row: one EM run from them can only climb
    scored = fit_hmm(X, 2, seed=5, start_from=sample, max_iter=1)
    assert fit.log_likelihood >= scored.log_likelihood
    with pytest.raises(DtwinValueError, match="start_from must have 3 states of 2 features"):
        fit_hmm(X, 3, seed=5, start_from=sample)
    with pytest.raises(TypeError, match="seed must be an int with start_from"):
        fit_hmm(X, 2, seed=[5, 1], start_from=sample)
