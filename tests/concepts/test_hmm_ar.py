"""The AR(1)-emission HMM (dtwin.hmm_ar): likelihood by hand, recovery, BIC count, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from dtwin._validation import DtwinValueError
from dtwin.hmm_ar import (
    ar_bic_by_k,
    fit_ar_hmm,
    n_ar_hmm_params,
    sample_ar_hmm,
    score_ar_hmm,
)

#: A 3-state, 2-feature AR-HMM: states differ in level, dynamics and noise.
TRUE = {
    "startprob": [1 / 3, 1 / 3, 1 / 3],
    "transmat": [[0.98, 0.01, 0.01], [0.01, 0.98, 0.01], [0.01, 0.01, 0.98]],
    "intercepts": [[0.0, 1.0], [1.0, -1.0], [-1.0, 0.0]],
    "coefs": [[0.9, 0.5], [0.2, -0.3], [0.6, 0.95]],
    "sds": [[0.3, 0.3], [0.5, 0.2], [0.2, 0.4]],
}


def _hand_log_likelihood(X, fit) -> float:
    """log p(x_1 … x_T−1 | x_0): the forward recursion written out with scalar densities."""
    n_states, n_features = fit.coefs.shape

    def density(t, k):
        value = 1.0
        for d in range(n_features):
            mean = fit.intercepts[k, d] + fit.coefs[k, d] * X[t - 1, d]
            sd = fit.sds[k, d]
            value *= math.exp(-0.5 * ((X[t, d] - mean) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
        return value

    alpha = [fit.startprob[k] * density(1, k) for k in range(n_states)]
    for t in range(2, len(X)):
        alpha = [
            sum(alpha[i] * fit.transmat[i, j] for i in range(n_states)) * density(t, j)
            for j in range(n_states)
        ]
    return math.log(sum(alpha))


def test_log_likelihood_equals_a_forward_recursion_by_hand():
    X, _ = sample_ar_hmm(**TRUE, n_steps=12, rng=np.random.default_rng(5))
    fit = fit_ar_hmm(X, 2, n_restarts=2, seed=3, max_iter=5)
    hand = _hand_log_likelihood(X, fit)
    assert fit.log_likelihood == pytest.approx(hand, rel=1e-9, abs=1e-9)
    assert score_ar_hmm(fit, X) == pytest.approx(hand, rel=1e-9, abs=1e-9)
    assert fit.bic == pytest.approx(-2 * hand + n_ar_hmm_params(2, 2) * math.log(11))


def test_parameter_count_has_three_emission_values_per_state_and_feature():
    # π: K−1, A: K(K−1), then intercept, AR coefficient and variance per state and feature.
    assert n_ar_hmm_params(3, 2) == 2 + 6 + 18
    assert n_ar_hmm_params(4, 10) - n_ar_hmm_params(4, 9) == 3 * 4


def test_em_recovers_the_coefficients_and_states_of_a_three_state_ar_hmm():
    X, states = sample_ar_hmm(**TRUE, n_steps=6000, rng=np.random.default_rng(12))
    fit = fit_ar_hmm(X, 3, n_restarts=6, seed=7)  # 2 of the first 6 starts find it
    overlap = np.zeros((3, 3))
    np.add.at(overlap, (fit.viterbi, states), 1)
    rows, columns = linear_sum_assignment(-overlap)
    accuracy = overlap[rows, columns].sum() / len(states)
    assert accuracy >= 0.95
    order = rows[np.argsort(columns)]  # fitted state of each true state
    np.testing.assert_allclose(fit.coefs[order], TRUE["coefs"], atol=0.05)
    np.testing.assert_allclose(fit.sds[order], TRUE["sds"], atol=0.05)
    assert fit.converged


def test_bic_sweep_stops_past_the_true_number_of_states():
    two_states = {
        "startprob": [0.5, 0.5],
        "transmat": [[0.98, 0.02], [0.02, 0.98]],
        "intercepts": [[0.0], [1.0]],
        "coefs": [[0.95], [0.0]],
        "sds": [[0.1], [0.3]],
    }
    X, _ = sample_ar_hmm(**two_states, n_steps=800, rng=np.random.default_rng(2))
    sweep = ar_bic_by_k(X, [1, 2], n_restarts=2, seed=1, k_max=6, max_iter=60, tol=1e-6)
    table = sweep.table
    assert int(table.loc[table["bic"].idxmin(), "K"]) == 2
    assert table["K"].tolist() == [1, 2, 3, 4]  # rose twice after K = 2, then stopped
    assert sorted(sweep.fits) == [1, 2, 3, 4]


def test_bad_input_gets_a_one_line_error():
    with pytest.raises(DtwinValueError, match="at least n_states"):
        fit_ar_hmm(np.zeros((3, 1)), 2)
    with pytest.raises(DtwinValueError, match="finite"):
        fit_ar_hmm(np.array([[0.0], [np.nan], [1.0], [2.0]]), 1)
