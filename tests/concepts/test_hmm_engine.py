"""The compiled EM engine against hmmlearn (the reference): same iterations, same numbers.

Acceptance fixture: on R's seed-11 fault features (T = 2000, D = 10), random and
split starts at K = 2 … 12 give the same iteration counts and statuses in both engines, the
log-likelihood within 1e-9 (relative) at every iteration and the parameters within 1e-8.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from dtwin import _em_kernels as kernels
from dtwin._multistart import EmData, decode, fit_one_start
from dtwin.fault_injection import regime_features
from dtwin.hmm import (
    _em_data,
    _random_start,
    _split_start,
    fit_hmm,
    split_fits,
    zscore,
)
from dtwin.hmm_ar import _design, _random_emission, fit_ar_hmm, sample_ar_hmm, score_ar_hmm
from tests.conftest import REPO

OPTIONS = {"max_iter": 500, "tol": 1e-8, "var_floor": 1e-3}


@pytest.fixture(scope="module")
def features(r_pipeline) -> np.ndarray:
    return zscore(regime_features(r_pipeline)).values


def _both(data: EmData, initial: tuple[np.ndarray, np.ndarray], options=OPTIONS):
    return [fit_one_start(data, 0, initial, engine, options) for engine in ("compiled", "hmmlearn")]


def _assert_same_run(compiled, reference):
    (row, run), (ref_row, ref_run) = compiled, reference
    assert (row["status"], row["n_iter"], row["implementation"]) == (
        ref_row["status"],
        ref_row["n_iter"],
        ref_row["implementation"],
    )
    if ref_run is None:
        assert run is None
        return
    np.testing.assert_allclose(run.history, ref_run.history, rtol=1e-9, atol=0)
    for ours, theirs in [
        (run.startprob, ref_run.startprob),
        (run.transmat, ref_run.transmat),
        (run.emission, ref_run.emission),
        (run.posteriors, ref_run.posteriors),
    ]:
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-8)


def _gaussian_initial(X, k, seed):
    means, variances, occupancy = _random_start(X, k, np.random.default_rng(seed), 1e-3)
    return np.stack([means, variances]), occupancy


@pytest.mark.parametrize("k", range(2, 13))
def test_random_and_split_starts_match_hmmlearn(features, k):
    data = _em_data(features)
    compiled, reference = _both(data, _gaussian_initial(features, k, 100 + k))
    _assert_same_run(compiled, reference)
    if reference[1] is not None:
        np.testing.assert_array_equal(
            decode(data, compiled[1], "compiled"), decode(data, reference[1], "hmmlearn")
        )
    if k == 2:
        return
    # a split start grows the (K − 1)-state random start's fit
    grow = _both(data, _gaussian_initial(features, k - 1, 200 + k))[1][1]
    assert grow is not None
    split = np.stack(_split_start(*grow.emission, k // 2, np.random.default_rng(k)))
    _assert_same_run(*_both(data, (split, np.full(k, np.inf))))


def test_ar_starts_match_hmmlearn():
    truth = {
        "startprob": [0.5, 0.5],
        "transmat": [[0.97, 0.03], [0.05, 0.95]],
        "intercepts": [[0.0, 1.0], [1.0, -1.0]],
        "coefs": [[0.9, 0.5], [0.2, -0.3]],
        "sds": [[0.3, 0.3], [0.5, 0.2]],
    }
    X, _ = sample_ar_hmm(**truth, n_steps=600, rng=np.random.default_rng(2))
    design = _design(X)
    data = EmData(kernels.AR1, design, design)
    for k in (2, 3, 4):
        initial = _random_emission(design, k, np.random.default_rng(k), 1e-6)
        _assert_same_run(*_both(data, initial, {**OPTIONS, "var_floor": 1e-6}))


def test_whole_fits_agree_and_capped_starts_stop_alike(features):
    fits = [fit_hmm(features, 5, n_restarts=3, seed=4, engine=e) for e in ("compiled", "hmmlearn")]
    compiled, reference = fits
    np.testing.assert_array_equal(compiled.restart_viterbi, reference.restart_viterbi)
    assert compiled.restarts["status"].tolist() == reference.restarts["status"].tolist()
    assert compiled.log_likelihood == pytest.approx(reference.log_likelihood, rel=1e-12)
    np.testing.assert_allclose(compiled.smoothed, reference.smoothed, atol=1e-8)
    np.testing.assert_allclose(compiled.filtered, reference.filtered, atol=1e-8)
    capped = [
        fit_hmm(features, 3, n_restarts=2, seed=1, max_iter=3, engine=e)
        for e in ("compiled", "hmmlearn")
    ]
    assert [list(c.restarts["status"]) for c in capped] == [["max_iter"] * 2] * 2
    splits = [
        split_fits(features, compiled.means, compiled.sds**2, seed=3, engine=e)[0]
        for e in ("compiled", "hmmlearn")
    ]
    assert splits[0]["n_iter"].tolist() == splits[1]["n_iter"].tolist()
    ar = [
        fit_ar_hmm(features[:400, :3], 2, n_restarts=2, seed=0, engine=e)
        for e in ("compiled", "hmmlearn")
    ]
    np.testing.assert_array_equal(ar[0].viterbi, ar[1].viterbi)
    assert ar[0].log_likelihood == pytest.approx(ar[1].log_likelihood, rel=1e-10)


def test_compiled_viterbi_breaks_ties_as_hmmlearn():
    # two identical states: every step ties; hmmlearn keeps the first state at the end and the
    # later state going back
    X = np.random.default_rng(0).normal(size=(30, 2))
    emission = np.stack([np.zeros((2, 2)), np.ones((2, 2))])
    startprob, transmat = np.full(2, 0.5), np.full((2, 2), 0.5)
    path = kernels.viterbi(kernels.GAUSSIAN, np.hstack([X, X * X]), emission, startprob, transmat)
    from dtwin._em_reference import new_gaussian_model, set_gaussian_params

    model = set_gaussian_params(new_gaussian_model(2, "scaling"), startprob, transmat, *emission)
    model.n_features = 2
    np.testing.assert_array_equal(path, model.decode(X, algorithm="viterbi")[1])


def test_kernel_sums_are_numpys():
    rng = np.random.default_rng(1)
    for n in range(1, 129):
        a = rng.normal(size=(2, n))
        assert kernels._numpy_sum(a[1].copy()) == a[1].sum()
        assert kernels._row_sum(a, 0, 0, n) == a.sum(axis=1)[0]


def test_fit_hmm_rejects_an_unknown_engine(features):
    with pytest.raises(ValueError, match=r"engine must be one of compiled, hmmlearn \(got 'R'\)"):
        fit_hmm(features, 2, engine="R")


def test_every_call_site_uses_the_one_warmed_signature(features):
    """dtwin passes each kernel one argument type, the one warm_up compiles into the cache."""
    fit_hmm(features[:300], 3, n_restarts=2, seed=0)
    split_fits(features[:300], np.zeros((2, 10)), np.ones((2, 10)), seed=0)
    fit = fit_ar_hmm(features[:300, :2], 2, n_restarts=2, seed=0)
    score_ar_hmm(fit, features[:300, :2])
    kernels.warm_up()
    for kernel in (kernels.em, kernels.viterbi, kernels.score):
        assert len(kernel.signatures) == 1, kernel


def test_a_fresh_process_loads_the_kernels_from_the_cache():
    """After one warm-up (``make venv``), a new process compiles nothing."""
    code = (
        "from dtwin import _em_kernels as k; k.warm_up(); "
        "print(sum(sum(f.stats.cache_misses.values()) for f in (k.em, k.viterbi, k.score)))"
    )
    for _ in range(2):  # a second run only if the first filled the cache (no make venv)
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
        )
        if out.stdout.strip() == "0":
            break
    assert out.stdout.strip() == "0"


def test_emission_kinds_agree_and_importing_the_hmm_loads_no_engine():
    import dtwin._multistart as multistart

    assert (multistart.GAUSSIAN, multistart.AR1) == (kernels.GAUSSIAN, kernels.AR1)
    code = (
        "import sys, dtwin.hmm, dtwin.hmm_ar\nprint(sorted({'numba', 'hmmlearn'} & {*sys.modules}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert out.stdout.strip() == "[]"


def test_vectorised_exp_is_within_one_ulp_of_libm():
    """The kernels' exp against math.exp: 1 ulp at most; overflow, subnormals and NaN kept."""
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-750.0, 712.0, 200_000), rng.uniform(-2.0, 2.0, 200_000)])
    special = [np.nan, np.inf, -np.inf, 0.0, -0.0, 709.78, 709.79, -708.39, -745.13, -745.14]
    x = np.concatenate([x, special]).reshape(-1, 1)
    ours = x.copy()
    kernels._exp_all(ours)
    largest = math.log(np.finfo(float).max)  # math.exp raises beyond
    libm = np.array([math.inf if v > largest else math.exp(v) for v in x[:, 0]]).reshape(-1, 1)
    assert np.array_equal(np.isnan(ours), np.isnan(libm))
    assert np.array_equal(np.isinf(ours), np.isinf(libm))
    finite = np.isfinite(libm)
    ulp = np.spacing(np.maximum(libm[finite], 5e-324))
    assert np.max(np.abs(ours[finite] - libm[finite]) / ulp) <= 1.0


def test_only_the_best_start_keeps_its_posteriors(features):
    """fit_starts drops every other start's posteriors (memory) and keeps the fit's best."""
    from dtwin._multistart import fit_starts, restart_seeds

    def initial(rng):
        return _gaussian_initial(features, 3, int(rng.integers(1 << 30)))

    restarts, runs = fit_starts(
        _em_data(features), restart_seeds(5, 6), initial, "compiled", OPTIONS
    )
    usable = restarts[restarts["restart"].isin(runs)]
    best = int(usable.loc[usable["log_likelihood"].idxmax(), "restart"])
    assert len(runs) > 1
    assert [number for number, run in runs.items() if run.posteriors is not None] == [best]
    np.testing.assert_allclose(runs[best].posteriors.sum(axis=1), 1.0)


#: A start on R's seed-11 fault features (K = 2, its random-start seed in the BIC sweep of
#: rule bic_r_signals) whose scaled forward pass underflows at R's outlier sample t = 725.
UNDERFLOWING_START = (2, 4080602305)


def test_a_start_whose_scaled_pass_underflows_reruns_in_compiled_log_space(features):
    """The compiled engine reruns it in its own log space, as hmmlearn's log implementation."""
    initial = _gaussian_initial(features, *UNDERFLOWING_START)
    compiled, reference = _both(_em_data(features), initial)
    for row, _ in (compiled, reference):
        assert row["implementation"] == "log"
        assert row["message"].startswith("scaling: forward pass failed with underflow")
    _assert_same_run(compiled, reference)
    code = (
        "import sys, numpy as np, pandas as pd\n"
        "from dtwin.fault_injection import regime_features\n"
        "from dtwin.hmm import _em_data, _random_start, zscore\n"
        "from dtwin._multistart import fit_one_start\n"
        "X = zscore(regime_features(pd.read_csv("
        "'config/reference/faulted_pipeline_seed11_rerun.csv'))).values\n"
        f"m, v, occ = _random_start(X, {UNDERFLOWING_START[0]}, "
        f"np.random.default_rng({UNDERFLOWING_START[1]}), 1e-3)\n"
        f"row, _ = fit_one_start(_em_data(X), 0, (np.stack([m, v]), occ), 'compiled', {OPTIONS})\n"
        "print(row['implementation'], sorted({'hmmlearn', 'sklearn'} & {*sys.modules}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert out.stdout.strip() == "log []"


def _hmmlearn_log_estep(startprob, transmat, log_frameprob):
    from hmmlearn import _hmmc

    log_prob, fwd = _hmmc.forward_log(startprob, transmat, log_frameprob)
    bwd = _hmmc.backward_log(startprob, transmat, log_frameprob)
    with np.errstate(under="ignore", divide="ignore"):
        xi = np.exp(_hmmc.compute_log_xi_sum(fwd, transmat, bwd, log_frameprob))
        log_gamma = fwd + bwd
        gamma = np.exp(log_gamma - np.logaddexp.reduce(log_gamma, axis=1, keepdims=True))
    return log_prob, gamma, xi


def test_log_space_estep_is_hmmlearns():
    """log p(X), γ and Σ ξ of the compiled log-space E-step against hmmlearn's ``_hmmc``, with
    a forbidden transition (log A = −∞) and a sample whose every density underflows."""
    rng = np.random.default_rng(3)
    X = rng.normal(size=(400, 3))
    X[150] = 60.0  # every state's density below 1e-300: the scaled pass fails here
    emission = np.stack([rng.normal(size=(4, 3)), rng.uniform(0.5, 2.0, size=(4, 3))])
    startprob = np.array([0.4, 0.3, 0.2, 0.1])
    transmat = rng.dirichlet(np.ones(4), size=4)
    transmat[1, 3] = 0.0
    transmat[1] /= transmat[1].sum()
    data = np.hstack([X, X * X])
    buffers, xi = kernels._lattices(len(X), 4), np.empty((4, 4))
    assert math.isnan(kernels._estep(0, data, emission, startprob, transmat, buffers, xi))
    log_prob = kernels._estep_log(0, data, emission, startprob, transmat, buffers, xi)
    log_frameprob = np.empty((len(X), 4))
    kernels._log_frameprob(0, data, emission, log_frameprob)
    ref_log_prob, ref_gamma, ref_xi = _hmmlearn_log_estep(startprob, transmat, log_frameprob)
    assert log_prob == pytest.approx(ref_log_prob, rel=1e-12)
    np.testing.assert_allclose(buffers[kernels._GAMMA], ref_gamma, rtol=0, atol=1e-12)
    np.testing.assert_allclose(xi, ref_xi, rtol=1e-10, atol=0)
    assert xi[1, 3] == 0.0
    score = kernels.score(0, data, emission, startprob, transmat)
    assert score == pytest.approx(ref_log_prob, rel=1e-12)


def test_subnormals_flush_to_zero_inside_the_block_only():
    """Inside subnormals_flushed a product below the smallest normal float is 0 (x86-64)."""
    tiny, factor = 1e-300, np.float64(1e-10)  # their product, 1e-310, is subnormal
    assert tiny * factor == pytest.approx(1e-310, rel=1e-6)
    with kernels.subnormals_flushed():
        inside = (tiny * factor, float(np.multiply(np.array([tiny]), factor)[0]))
        assert tiny * 1e10 == 1e-290  # normal results are untouched
    assert tiny * factor == pytest.approx(1e-310, rel=1e-6)
    with pytest.raises(RuntimeError), kernels.subnormals_flushed():
        raise RuntimeError
    assert tiny * factor > 0.0  # restored on an exception too
    expected = (0.0, 0.0) if kernels._HAS_MXCSR else (tiny * factor,) * 2
    assert inside == expected


def test_a_sweep_limits_blas_once_and_numbas_blas_from_the_first_start(features, monkeypatch):
    """bic_by_k enters threadpool_limits once (a scan of the loaded libraries each time), and
    scipy's OpenBLAS, which the kernels call, is loaded before the limit, so it is held too."""
    import dtwin._multistart as multistart
    from dtwin.hmm import bic_by_k

    entered, real = [], multistart.threadpool_limits

    def counting(**kwargs):
        entered.append(kwargs)
        return real(**kwargs)

    monkeypatch.setattr(multistart, "threadpool_limits", counting)
    bic_by_k(features[:300], [2, 3], n_restarts=2, seed=0, split_starts=True, max_restarts=4)
    assert entered == [{"limits": 1}]
    with multistart.one_blas_thread():
        assert "scipy.linalg.cython_blas" in sys.modules
        from threadpoolctl import threadpool_info

        blas = [lib for lib in threadpool_info() if lib["user_api"] == "blas"]
        assert len(blas) >= 2 and all(lib["num_threads"] == 1 for lib in blas)
