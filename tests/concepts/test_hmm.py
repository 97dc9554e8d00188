"""Tests of dtwin.hmm: z-scoring, EM fits, posteriors, Viterbi, BIC, and the R crosscheck."""

from __future__ import annotations

import dataclasses
import itertools
import logging

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from dtwin._validation import DtwinValueError
from dtwin.fault_injection import regime_features
from dtwin.figures.fig09_bic import STABLE_LOGLIK
from dtwin.hmm import (
    STABLE_GAIN,
    HmmFitError,
    bic_by_k,
    bic_minimum_bracketed,
    filtered_posteriors,
    fit_hmm,
    n_hmm_params,
    split_fits,
    to_hmmlearn,
    zscore,
)
from dtwin.regime_matching import classification_scores, hungarian_map

R_BEST_LOGLIK = -2115.852  # depmixS4, best of 10 starts (r_notes.md §5, §11)


@pytest.fixture(scope="module")
def r_features(r_pipeline) -> np.ndarray:
    return zscore(regime_features(r_pipeline)).values


def three_state_data(n_per: int = 60, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    centres = [(-3.0, 0.0), (0.0, 3.0), (3.0, -3.0)]
    blocks = [rng.normal(c, 0.7, size=(n_per, 2)) for c in centres]
    return np.concatenate(blocks + blocks[:1])


# --- zscore ---------------------------------------------------------------------------------


def test_zscore_uses_sample_sd_like_r_scale():
    rng = np.random.default_rng(3)
    raw = pd.DataFrame(rng.normal(2.0, 5.0, size=(50, 3)), columns=["a", "b", "c"])
    z = zscore(raw)
    np.testing.assert_allclose(z.values, ((raw - raw.mean()) / raw.std(ddof=1)).to_numpy())
    np.testing.assert_allclose(z.values.std(axis=0, ddof=1), 1.0)
    assert z.columns == ("a", "b", "c")
    np.testing.assert_allclose(z.transform(raw.to_numpy()), z.values)


def test_zscore_rejects_zero_variance_column_by_name():
    table = pd.DataFrame({"e0": [1.0, 2.0, 3.0], "e1": [0.5, 0.5, 0.5]})
    with pytest.raises(DtwinValueError, match=r"column 'e1' \(index 1\) must have non-zero var"):
        zscore(table)


def test_zscore_rejects_nan_column_by_index():
    array = np.column_stack([np.arange(4.0), np.full(4, np.nan)])
    with pytest.raises(DtwinValueError, match=r"column 1 must be finite \(got 4 NaN/inf"):
        zscore(array)


# --- posteriors and decoding ----------------------------------------------------------------


def test_posteriors_are_probabilities():
    fit = fit_hmm(three_state_data(), 3, n_restarts=3, seed=1)
    for gamma in (fit.smoothed, fit.filtered):
        assert gamma.shape == (240, 3)
        assert gamma.min() >= 0.0 and gamma.max() <= 1.0
        np.testing.assert_allclose(gamma.sum(axis=1), 1.0, atol=1e-12)
    # the last filtered posterior conditions on everything, like the smoothed one
    np.testing.assert_allclose(fit.filtered[-1], fit.smoothed[-1], atol=1e-10)


def _brute_force(X, fit):
    """Enumerate every state path of a short sequence: joint log-probabilities (paths, T)."""
    n_steps, n_states = len(X), fit.n_states
    log_b = np.stack(
        [norm.logpdf(X, fit.means[k], fit.sds[k]).sum(axis=1) for k in range(n_states)], axis=1
    )
    paths = np.array(list(itertools.product(range(n_states), repeat=n_steps)))
    with np.errstate(divide="ignore"):
        log_pi, log_a = np.log(fit.startprob), np.log(fit.transmat)
    prefix = np.empty(paths.shape)  # log p(s_1..t, e_1..t) along each path
    prefix[:, 0] = log_pi[paths[:, 0]] + log_b[0, paths[:, 0]]
    for t in range(1, n_steps):
        prefix[:, t] = prefix[:, t - 1] + log_a[paths[:, t - 1], paths[:, t]]
        prefix[:, t] += log_b[t, paths[:, t]]
    return paths, prefix


def test_viterbi_filtered_smoothed_and_loglik_match_brute_force_enumeration():
    rng = np.random.default_rng(7)
    X = np.concatenate([rng.normal(m, 0.8, size=(3, 1)) for m in (-2.0, 0.0, 2.0)])
    fit = fit_hmm(X, 3, n_restarts=4, seed=2)
    paths, prefix = _brute_force(X, fit)
    joint = prefix[:, -1]
    # Viterbi = arg-max path; log-likelihood = log Σ over paths
    np.testing.assert_array_equal(fit.viterbi, paths[np.argmax(joint)])
    total = np.logaddexp.reduce(joint)
    assert fit.log_likelihood == pytest.approx(total, abs=1e-9)
    weights = np.exp(joint - total)
    smoothed = np.stack([np.bincount(paths[:, t], weights, 3) for t in range(len(X))])
    np.testing.assert_allclose(fit.smoothed, smoothed, atol=1e-9)
    # filtered: P(S_t | e_1..t) from the path prefixes (paths repeat prefixes evenly)
    for t in range(len(X)):
        w = np.exp(prefix[:, t] - np.logaddexp.reduce(prefix[:, t]))
        np.testing.assert_allclose(fit.filtered[t], np.bincount(paths[:, t], w, 3), atol=1e-9)


def test_viterbi_of_a_known_hmm_by_hand():
    # A sticky 3-state chain, means -2, 0, 2, unit sds. At t = 3 the sample 1.2 is closer to
    # state 2's mean (emission log-ratio +0.4 for state 2), but the detour 1 → 2 → 1 costs
    # log(0.8² / 0.15²) = 3.35 against staying in state 1, so the best path stays in 1.
    X = np.array([[-2.0], [-2.0], [0.0], [1.2], [0.0], [2.0]])
    template = fit_hmm(X, 3, n_restarts=1, seed=0)
    known = dataclasses.replace(
        template,
        startprob=np.array([0.8, 0.1, 0.1]),
        transmat=np.array([[0.8, 0.15, 0.05], [0.05, 0.8, 0.15], [0.05, 0.15, 0.8]]),
        means=np.array([[-2.0], [0.0], [2.0]]),
        sds=np.array([[1.0], [1.0], [1.0]]),
    )
    paths, prefix = _brute_force(X, known)
    expected = paths[np.argmax(prefix[:, -1])]
    _, decoded = to_hmmlearn(known).decode(X, algorithm="viterbi")
    np.testing.assert_array_equal(decoded, expected)
    np.testing.assert_array_equal(expected, [0, 0, 1, 1, 1, 2])


def test_filtered_posterior_is_causal():
    X = three_state_data()
    fit = fit_hmm(X, 3, n_restarts=2, seed=4)
    t = 100
    changed = X.copy()
    changed[t + 1 :] = np.random.default_rng(9).normal(size=changed[t + 1 :].shape) * 5
    before = filtered_posteriors(fit, X)
    after = filtered_posteriors(fit, changed)
    np.testing.assert_array_equal(before[: t + 1], after[: t + 1])
    assert not np.allclose(before[t + 1 :], after[t + 1 :])
    np.testing.assert_allclose(before, fit.filtered)


def test_same_seed_gives_identical_fits_and_other_seeds_other_starts():
    X = three_state_data(seed=5)
    first = fit_hmm(X, 3, n_restarts=3, seed=123)
    second = fit_hmm(X, 3, n_restarts=3, seed=123)
    pd.testing.assert_frame_equal(first.restarts, second.restarts)
    for field in ("startprob", "transmat", "means", "sds", "smoothed", "filtered", "viterbi"):
        np.testing.assert_array_equal(getattr(first, field), getattr(second, field))
    other = fit_hmm(X, 3, n_restarts=3, seed=124)
    assert set(other.restarts["seed"]).isdisjoint(first.restarts["seed"])


def test_restart_table_and_honest_convergence():
    X = three_state_data(seed=6)
    fit = fit_hmm(X, 3, n_restarts=4, seed=0)
    assert list(fit.restarts.columns[:6]) == [
        "restart",
        "seed",
        "log_likelihood",
        "n_iter",
        "converged",
        "status",
    ]
    assert fit.log_likelihood == pytest.approx(fit.restarts["log_likelihood"].max())
    capped = fit_hmm(X, 3, n_restarts=2, seed=0, max_iter=2)
    assert not capped.converged
    assert set(capped.restarts["status"]) == {"max_iter"}
    assert (capped.restarts["n_iter"] == 2).all()


def test_every_start_keeps_its_viterbi_path():
    X = three_state_data(seed=6)
    fit = fit_hmm(X, 3, n_restarts=4, seed=0)
    assert fit.restart_viterbi.shape == (4, len(X))
    np.testing.assert_array_equal(fit.restart_viterbi[fit.best_restart - 1], fit.viterbi)
    usable = ~fit.restarts["status"].isin(["failed", "degenerate"]).to_numpy()
    assert (fit.restart_viterbi[usable] >= 0).all()
    assert (fit.restart_viterbi[~usable] == -1).all()
    # a start that degenerated keeps a row of -1
    rng = np.random.default_rng(0)
    tiny = fit_hmm(rng.normal(size=(12, 1)), 4, n_restarts=6, seed=1)
    failed = tiny.restarts["status"].isin(["failed", "degenerate"]).to_numpy()
    assert failed.any()
    assert (tiny.restart_viterbi[failed] == -1).all()


def test_bic_sweep_accepts_a_seed_sequence():
    X = three_state_data(seed=7)
    table = bic_by_k(X, [2, 3], n_restarts=2, seed=[5, 1])
    again = bic_by_k(X, [3], n_restarts=2, seed=[5, 1])
    assert table.loc[table["K"] == 3, "bic"].item() == again["bic"].item()


def test_variance_floor_holds_for_a_one_sample_state():
    rng = np.random.default_rng(0)
    X = np.concatenate([rng.normal(size=(40, 1)), [[50.0]], rng.normal(size=(40, 1))])
    fit = fit_hmm(X, 3, n_restarts=3, seed=0, var_floor=1e-3)
    assert fit.sds.min() ** 2 >= 1e-3 * (1 - 1e-12)
    assert np.isfinite(fit.log_likelihood)


def test_all_degenerate_starts_raise():
    X = np.random.default_rng(0).normal(size=(6, 1))
    with pytest.raises(HmmFitError, match="all 4 starts failed or degenerated"):
        fit_hmm(X, 5, n_restarts=4, seed=0)


def test_fit_hmm_validates_arguments():
    X = three_state_data()
    with pytest.raises(DtwinValueError, match="X must be finite"):
        fit_hmm(np.where(np.arange(X.size).reshape(X.shape) == 3, np.nan, X), 2)
    with pytest.raises(DtwinValueError, match=r"n_states must be >= 1 \(got 0\)"):
        fit_hmm(X, 0)
    with pytest.raises(DtwinValueError, match="var_floor must be > 0"):
        fit_hmm(X, 2, var_floor=0.0)


# --- BIC ------------------------------------------------------------------------------------


def test_bic_uses_depmix_parameter_count_and_matches_hmmlearn():
    X = three_state_data()
    fit = fit_hmm(X, 3, n_restarts=2, seed=0)
    assert fit.n_params == (3 - 1) + 3 * 2 + 2 * 2 * 3 == n_hmm_params(3, 2)
    assert fit.bic == pytest.approx(-2 * fit.log_likelihood + fit.n_params * np.log(len(X)))
    assert fit.bic == pytest.approx(to_hmmlearn(fit).bic(X))


def test_bic_sweep_selects_the_true_number_of_states(caplog):
    X = three_state_data(n_per=80)
    with caplog.at_level(logging.INFO, logger="dtwin.hmm"):
        table = bic_by_k(X, [1, 2, 3, 4], n_restarts=3, seed=0)
    assert list(table.columns[:4]) == ["K", "log_likelihood", "n_params", "bic"]
    assert table.loc[table["bic"].idxmin(), "K"] == 3
    assert sum("bic_by_k K=" in message for message in caplog.messages) == 4


@pytest.mark.parametrize(
    ("curve", "stop"),
    [
        ([10, 8, 7, 9, 11], True),  # two rises in a row after the minimum at index 2
        ([10, 8, 7, 9, 8], False),  # a rise then a fall: not yet bracketed
        ([10, 8, 7, 9], False),  # one rise only
        ([10, 12, 14], True),  # rising from the start
        ([5, 4, 3, 2, 1], False),  # still falling
    ],
)
def test_bic_bracket_stops_where_it_should_on_a_hand_made_curve(curve, stop):
    assert bic_minimum_bracketed(curve, rises=2) is stop


def test_bic_sweep_extends_k_until_the_minimum_is_bracketed():
    X = three_state_data(n_per=80)
    table = bic_by_k(X, [1, 2], n_restarts=4, seed=0, k_max=8, stop_after_rises=2)
    # K = 3 is the minimum; K = 4 and 5 rise, so K = 6 is never fitted
    assert table["K"].tolist() == [1, 2, 3, 4, 5]
    assert table.loc[table["bic"].idxmin(), "K"] == 3
    assert (table["log_likelihood"] >= table["log_likelihood_half"]).all()
    assert (table["n_starts"] == 4).all() and set(table["source"]) == {"sweep"}


def test_split_fits_grow_the_missing_state():
    X = three_state_data(n_per=80)
    two = fit_hmm(X, 2, n_restarts=3, seed=0)
    table, best = split_fits(X, two.means, two.sds**2, seed=1, first_restart=4)
    assert table["restart"].tolist() == [4, 5] and (table["seed"] == -1).all()
    assert table["message"].str.startswith("split of state").all()
    means, variances = best
    # the three blocks' centres: x = -3, 0, 3 (one of the two states held two blocks)
    np.testing.assert_allclose(np.sort(means[:, 0]), [-3.0, 0.0, 3.0], atol=0.2)
    assert table["log_likelihood"].max() == pytest.approx(
        fit_hmm(X, 3, n_restarts=3, seed=0).log_likelihood, abs=1e-3
    )
    assert variances.shape == (3, 2)


def test_bic_sweep_with_split_starts_never_loses_to_random_starts():
    rng = np.random.default_rng(4)
    # a smooth signal: many tilings fit about equally well, as the residuals of the paper
    X = np.cumsum(rng.normal(size=(400, 2)), axis=0)
    X = (X - X.mean(axis=0)) / X.std(axis=0)
    plain = bic_by_k(X, [2, 3, 4, 5], n_restarts=2, seed=3)
    grown = bic_by_k(X, [2, 3, 4, 5], n_restarts=2, seed=3, split_starts=True)
    assert grown["n_split_starts"].tolist() == [0, 2, 3, 4]
    assert (grown["n_starts"] == 2).all()
    # the random starts are the same, so the best of all starts is at least theirs
    assert (grown["log_likelihood"] >= plain["log_likelihood"] - 1e-9).all()
    assert (grown["log_likelihood_half"] >= plain["log_likelihood_half"] - 1e-9).all()
    assert (grown["bic"] <= plain["bic"] + 1e-6).all()


def test_bic_sweep_doubles_the_starts_of_a_k_until_its_best_is_stable():
    rng = np.random.default_rng(4)
    # a smooth signal: random starts land in many optima, as on the paper's residuals
    X = np.cumsum(rng.normal(size=(400, 2)), axis=0)
    X = (X - X.mean(axis=0)) / X.std(axis=0)
    plain = bic_by_k(X, [2, 3, 4, 5], n_restarts=2, seed=3)
    doubled = bic_by_k(X, [2, 3, 4, 5], n_restarts=2, seed=3, max_restarts=16)
    plain_gain = plain["log_likelihood"] - plain["log_likelihood_half"]
    gain = doubled["log_likelihood"] - doubled["log_likelihood_half"]
    assert (plain_gain >= STABLE_GAIN).any()  # the data need the doubling
    assert set(doubled["n_starts"]) <= {2, 4, 8, 16} and doubled["n_starts"].max() > 2
    # every K stops as soon as its second half gains nothing, or at the cap
    assert ((gain < STABLE_GAIN) | (doubled["n_starts"] == 16)).all()
    assert (doubled.loc[plain_gain < STABLE_GAIN, "n_starts"] == 2).all()
    # the first starts are the same fits (prefix-stable seeds), so nothing is lost
    assert (doubled["log_likelihood"] >= plain["log_likelihood"] - 1e-9).all()


def test_the_sweeps_stability_bar_is_the_figures():
    assert STABLE_GAIN == STABLE_LOGLIK


def test_bic_sweep_grows_from_a_given_fit_without_tabulating_its_parameters():
    X = three_state_data(n_per=80)
    two = fit_hmm(X, 2, n_restarts=3, seed=0)
    given = {
        2: {
            **bic_by_k(X, [2], n_restarts=1, seed=9).iloc[0].to_dict(),
            "means_z": two.means.tolist(),
            "sds_z": two.sds.tolist(),
        }
    }
    table = bic_by_k(X, [2, 3], n_restarts=1, seed=0, given=given, split_starts=True)
    assert "means_z" not in table and "sds_z" not in table
    assert table["n_split_starts"].tolist() == [0, 2]
    assert table.loc[1, "log_likelihood"] == pytest.approx(
        fit_hmm(X, 3, n_restarts=3, seed=0).log_likelihood, abs=1e-3
    )


# --- crosscheck against depmixS4 ------------------------------------------------------------


def test_best_of_ten_reaches_depmix_loglik_and_regime_accuracy(r_pipeline, r_features):
    # its time (target < 0.5 s on two cores) is a benchmark: `make bench` (benchmarks/run.py)
    fit = fit_hmm(r_features, 4, n_restarts=10, seed=11)
    assert fit.log_likelihood >= R_BEST_LOGLIK - 1e-2
    assert fit.bic == pytest.approx(4887.941, abs=0.05)
    assert fit.converged
    mapping = hungarian_map(fit.viterbi, r_pipeline["regime"])
    scores = classification_scores(mapping.predicted, r_pipeline["regime"])
    assert scores.accuracy == pytest.approx(0.85, abs=1e-3)


def test_scaling_underflow_falls_back_to_log_implementation():
    # 200 dimensions and one far-out row: every state's emission density of that row
    # underflows exp(), so hmmlearn's scaling forward pass fails and the start reruns in log.
    rng = np.random.default_rng(0)
    X = rng.normal(size=(100, 200))
    X[50] = 5.0
    fit = fit_hmm(X, 2, n_restarts=2, seed=0)
    assert set(fit.restarts["implementation"]) == {"log"}
    assert fit.restarts["message"].str.contains("scaling: .*underflow").all()
    assert set(fit.restarts["status"]) == {"ok"}
    np.testing.assert_allclose(fit.smoothed.sum(axis=1), 1.0)
    np.testing.assert_allclose(fit.filtered.sum(axis=1), 1.0)


@pytest.mark.parametrize(
    ("n_steps", "left_to_right"), [(1, False), (2, False), (997, False), (3000, True)]
)
def test_vectorised_forward_filter_equals_the_exact_loop(n_steps, left_to_right):
    from dtwin.hmm import _forward_filter, _forward_filter_loop

    rng = np.random.default_rng(n_steps)
    transmat = rng.dirichlet(np.ones(4), size=4)
    if left_to_right:  # zeros in the transition matrix
        transmat = np.triu(transmat)
        transmat /= transmat.sum(axis=1, keepdims=True)
    args = (
        rng.normal(size=(n_steps, 3)) * 2.0,
        rng.dirichlet(np.ones(4)),
        transmat,
        rng.normal(size=(4, 3)),
        rng.uniform(0.3, 2.0, size=(4, 3)),
    )
    fast, fast_ll = _forward_filter(*args)
    exact, exact_ll = _forward_filter_loop(*args)
    np.testing.assert_allclose(fast, exact, atol=1e-10)
    assert fast_ll == pytest.approx(exact_ll, rel=1e-12)


def test_matmul_emission_hook_equals_hmmlearns_density():
    """The one override below hmmlearn's public API gives hmmlearn's own numbers."""
    from hmmlearn.stats import log_multivariate_normal_density

    from dtwin._em_reference import new_gaussian_model

    rng = np.random.default_rng(3)
    X = rng.normal(size=(500, 6)) * 3
    model = new_gaussian_model(3, "scaling")
    model.n_features = 6
    model.startprob_ = np.full(3, 1 / 3)
    model.transmat_ = np.full((3, 3), 1 / 3)
    model.means_ = rng.normal(size=(3, 6))
    model.covars_ = rng.uniform(0.05, 4.0, size=(3, 6))
    ours = model._compute_log_likelihood(X)
    variances = np.diagonal(model.covars_, axis1=1, axis2=2)
    reference = log_multivariate_normal_density(X, model.means_, variances, "diag")
    np.testing.assert_allclose(ours, reference, rtol=1e-10)


@pytest.mark.parametrize("n_steps", [1, 2, 700])
def test_lean_estep_gives_hmmlearns_statistics_bit_for_bit(n_steps):
    """The lean scaling E-step returns exactly hmmlearn's own E-step (same model, same X)."""
    from hmmlearn.hmm import GaussianHMM

    from dtwin._em_reference import new_gaussian_model

    rng = np.random.default_rng(n_steps)
    X = rng.normal(size=(n_steps, 5)) * 2
    model = new_gaussian_model(3, "scaling")
    model.n_features = 5
    model.startprob_ = rng.dirichlet(np.ones(3))
    model.transmat_ = rng.dirichlet(np.ones(3), size=3)
    model.means_ = rng.normal(size=(3, 5))
    model.covars_ = rng.uniform(0.2, 3.0, size=(3, 5))
    ours, ours_logprob = model._do_estep(X, np.array([n_steps]))
    theirs, theirs_logprob = super(type(model), model)._do_estep(X, np.array([n_steps]))
    assert type(model)._do_estep is not GaussianHMM._do_estep
    assert ours_logprob == theirs_logprob
    assert ours.keys() == theirs.keys()
    for name, value in theirs.items():
        assert np.array_equal(ours[name], value), name
        assert np.asarray(ours[name]).tobytes() == np.asarray(value).tobytes(), name
