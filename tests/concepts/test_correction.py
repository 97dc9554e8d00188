"""Tests of dtwin.bias_correction: shaping bounds, the R crosschecks (§7A and §7C), causality."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.bias_correction import (
    CORRECTED_SIGNALS,
    correct_bias,
    correct_plant_bias_viterbi,
    exponential_moving_average,
    rate_limit,
    state_residual_means,
)
from dtwin.hmm import fit_hmm, zscore
from dtwin.twin.wiring import RESIDUALS
from tests.conftest import REFERENCE

TWIN = {"alpha": 0.6, "w1": 1.0, "w2": 0.2, "dt": 0.02}


@pytest.fixture(scope="module")
def r_signals(r_pipeline):
    surrogate = pd.DataFrame(
        {
            "u_act": r_pipeline["u_act_A"],
            "x": r_pipeline["xpos_A_fault"],
            "y_A": r_pipeline["yA_A_fault"],
            "y_B": r_pipeline["yB_A_fault"],
        }
    )
    physics = pd.DataFrame(
        {
            "u_act": r_pipeline["u_act_P"],
            "x": r_pipeline["x_pos_P"],
            "y_A": r_pipeline["yA_P"],
            "y_B": r_pipeline["yB_P"],
            "y_fused": r_pipeline["y_fused_P"],
            "z": r_pipeline["z_P"],
        }
    )
    gamma = r_pipeline[[f"gamma_S{k}" for k in range(1, 5)]].to_numpy()
    return surrogate, physics, gamma


# --- shaping --------------------------------------------------------------------------------


def test_ema_by_hand_and_within_running_bounds():
    step = np.r_[0.0, np.ones(9)]
    np.testing.assert_allclose(
        exponential_moving_average(step, 0.15), np.r_[0.0, 1 - 0.85 ** np.arange(1, 10)]
    )
    x = np.random.default_rng(0).normal(size=(500, 3))
    out = exponential_moving_average(x, 0.15)
    assert out.shape == x.shape
    np.testing.assert_array_equal(out[0], x[0])
    assert np.all(out <= np.maximum.accumulate(x, axis=0) + 1e-12)
    assert np.all(out >= np.minimum.accumulate(x, axis=0) - 1e-12)
    np.testing.assert_allclose(out[1:], 0.15 * x[1:] + 0.85 * out[:-1])


def test_rate_limiter_bounds_steps_and_passes_slow_signals():
    x = np.random.default_rng(1).normal(size=(400, 2))
    out = rate_limit(x, 0.05)
    np.testing.assert_array_equal(out[0], x[0])
    assert np.abs(np.diff(out, axis=0)).max() <= 0.05 * (1 + 1e-12)
    slow = np.sin(np.linspace(0, 3, 200))  # steps ≤ 0.0151
    np.testing.assert_array_equal(rate_limit(slow, 0.05), slow)
    ramp = rate_limit(np.r_[0.0, np.full(30, 1.0)], 0.05)
    np.testing.assert_allclose(ramp[:21], 0.05 * np.arange(21))
    assert ramp[-1] == pytest.approx(1.0)


def test_shaping_validates_arguments():
    with pytest.raises(DtwinValueError, match=r"ema_alpha must be in \[0, 1\] \(got 1.5\)"):
        exponential_moving_average(np.zeros(3), 1.5)
    with pytest.raises(DtwinValueError, match=r"rate_max must be >= 0 \(got -1.0\)"):
        rate_limit(np.zeros(3), -1.0)


# --- posterior-weighted correction, r_notes.md §7A ----------------------------------------


def test_correction_reproduces_r_targeted_intervention(r_pipeline, r_signals):
    surrogate, physics, gamma = r_signals
    result = correct_bias(surrogate, physics, gamma, **TWIN)
    np.testing.assert_allclose(
        result.residuals_before, r_pipeline[list(RESIDUALS)], rtol=0, atol=1e-9
    )
    reference = pd.read_csv(REFERENCE / "targeted_intervention_metrics_rerun.csv")
    assert list(result.metrics["channel"]) == list(reference["channel"])
    columns = {
        "rmse_before": "RMSE_Original",
        "rmse_after": "RMSE_Corrected",
        "mae_before": "MAE_Original",
        "mae_after": "MAE_Corrected",
        "drmse_pct": "dRMSE_pct",
        "dmae_pct": "dMAE_pct",
    }
    for ours, theirs in columns.items():
        np.testing.assert_allclose(result.metrics[ours], reference[theirs], rtol=1e-6, err_msg=ours)
    assert list(result.applied.columns) == list(CORRECTED_SIGNALS) == ["u_act", "x", "y_A", "y_B"]
    assert np.abs(np.diff(result.applied.to_numpy(), axis=0)).max() <= 0.05 * (1 + 1e-12)


def test_state_means_and_eq25_by_hand():
    e = np.array([[1.0, 10.0], [3.0, 30.0], [5.0, 50.0]])
    gamma = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0]])
    means = state_residual_means(e, gamma)
    np.testing.assert_allclose(
        means, [[(1 + 1.5) / 1.5, (10 + 15) / 1.5], [(1.5 + 5) / 1.5, 65 / 1.5]]
    )


def test_zero_gain_changes_nothing(r_signals):
    surrogate, physics, gamma = r_signals
    result = correct_bias(surrogate, physics, gamma, kappa=0.0, **TWIN)
    np.testing.assert_allclose(result.residuals_after, result.residuals_before, atol=1e-15)
    np.testing.assert_allclose(result.metrics["drmse_pct"], 0.0, atol=1e-9)


def test_filtered_correction_is_causal_given_state_means(r_signals):
    surrogate, physics, _ = r_signals
    fit_input = zscore(surrogate.to_numpy() - physics[list(surrogate.columns)].to_numpy())
    fit = fit_hmm(fit_input.values, 3, n_restarts=2, seed=0)
    means = np.random.default_rng(0).normal(scale=0.01, size=(3, 6))
    first = correct_bias(surrogate, physics, fit.filtered, state_means=means, **TWIN)
    t = 600
    changed_gamma = fit.filtered.copy()
    changed_gamma[t + 1 :] = np.roll(changed_gamma[t + 1 :], 1, axis=1)
    changed_surrogate = surrogate.copy()
    changed_surrogate.loc[t + 1 :, "x"] += 1.0
    second = correct_bias(changed_surrogate, physics, changed_gamma, state_means=means, **TWIN)
    np.testing.assert_array_equal(first.applied[: t + 1], second.applied[: t + 1])
    np.testing.assert_array_equal(first.corrected[: t + 1], second.corrected[: t + 1])
    assert not np.allclose(first.corrected[t + 1 :], second.corrected[t + 1 :])


def test_correction_validates_inputs(r_signals):
    surrogate, physics, gamma = r_signals
    with pytest.raises(DtwinValueError, match=r"posteriors rows must sum to 1 \(got 0.5"):
        correct_bias(surrogate, physics, 0.5 * gamma, **TWIN)
    with pytest.raises(DtwinValueError, match=r"posteriors must lie in \[0, 1\]"):
        correct_bias(surrogate, physics, 2 * gamma - 0.5, **TWIN)
    with pytest.raises(DtwinValueError, match="surrogate is missing column"):
        correct_bias(surrogate.drop(columns="y_B"), physics, gamma, **TWIN)
    with pytest.raises(DtwinValueError, match=r"posteriors must have 1000 rows \(got 10\)"):
        correct_bias(surrogate, physics, gamma[:10], **TWIN)


# --- sensitivity-sweep variant, r_notes.md §7C --------------------------------------------


def test_plant_variant_reproduces_r_sensitivity_row_on_the_same_local_optimum(r_pipeline):
    """RobustnessAnalysis.R at α = 0.6, unit noise multipliers is the nominal seed-11 run, so
    its residuals are in the CSV. R's single EM start found one local optimum; among a few of
    our starts, one reaches it and the §7C correction then reproduces R's row."""
    p = r_pipeline
    x_a = p["xpos_A_nofault"].to_numpy()
    y_fused = 0.6 * p["yA_A_nofault"] + 0.4 * p["yB_A_nofault"]
    z = x_a + 0.2 * np.r_[0.0, np.diff(x_a) / 0.02]
    residuals = np.column_stack(
        [
            p["u_act_A"] - p["u_act_P"],
            x_a - p["x_pos_P"],
            p["yA_A_nofault"] - p["yA_P"],
            p["yB_A_nofault"] - p["yB_P"],
            y_fused - p["y_fused_P"],
            z - p["z_P"],
        ]
    )
    sweep = pd.read_csv(REFERENCE / "sensitivity_36_rerun.csv")
    row = sweep.query("alpha_fuse == 0.6 and sa_mult == 1 and sb_mult == 1").iloc[0]
    X = zscore(residuals).values
    match = None
    for seed in range(30):
        fit = fit_hmm(X, 4, n_restarts=1, seed=seed)
        result = correct_plant_bias_viterbi(x_a, p["x_pos_P"], fit.smoothed, fit.viterbi)
        if abs(result.metrics["drmse_pct"][0] - row.dRMSE_e1_pct) < 5e-3:
            match = result
            break
    assert match is not None, "no start reached R's local optimum"
    metrics = match.metrics.iloc[0]
    assert metrics.rmse_before == pytest.approx(row.RMSE_e1_orig, rel=1e-9)
    assert metrics.rmse_after == pytest.approx(row.RMSE_e1_corr, rel=1e-4)
    assert metrics.dmae_pct == pytest.approx(row.dMAE_e1_pct, abs=5e-3)
    # R's aggregate L2: the mean over t of the 6-channel Euclidean norm, e1 replaced only
    corrected = residuals.copy()
    corrected[:, 1] = match.e1_after
    l2_before = np.linalg.norm(residuals, axis=1).mean()
    l2_after = np.linalg.norm(corrected, axis=1).mean()
    assert l2_before == pytest.approx(row.L2_orig, rel=1e-9)
    assert l2_after == pytest.approx(row.L2_corr, rel=1e-6)
    assert np.abs(np.diff(match.applied)).max() <= 5e-4 * (1 + 1e-12)


def test_a_continued_shaping_compiled_gives_the_bits_of_the_ema_and_the_rate_limiter():
    """shaped_bias continued from a previous chunk runs one compiled loop where numba is loaded:
    the EMA's lfilter arithmetic and the rate limiter's, bit for bit (signed zeros included)."""
    from dtwin import bias_correction
    from dtwin._jit import HAVE_NUMBA

    if HAVE_NUMBA:
        import numba  # noqa: F401 - loaded, as in the monitor
    rng = np.random.default_rng(8)
    bias = rng.normal(0, 1, (500, 3))
    bias[10:20] = 0.0
    bias[20:25] = -0.0
    first = bias_correction.shaped_bias(bias[:7], kappa=0.9, ema_alpha=0.3, rate_max=0.05)
    start = (first.smoothed[-1], first.applied[-1])
    shaped = bias_correction.shaped_bias(bias[7:], kappa=0.9, ema_alpha=0.3, rate_max=0.05,
                                         initial=start)  # fmt: skip
    assert bool(bias_correction._COMPILED_SHAPING) == HAVE_NUMBA  # compiled and used
    smoothed = bias_correction.exponential_moving_average(0.9 * bias[7:], 0.3, initial=start[0])
    applied = bias_correction.rate_limit(smoothed, 0.05, initial=start[1])
    assert shaped.smoothed.tobytes() == smoothed.tobytes()
    assert shaped.applied.tobytes() == applied.tobytes()
    with pytest.raises(ValueError, match="ema_alpha must be > 0"):
        bias_correction.shaped_bias(bias, kappa=1.0, ema_alpha=0.0, rate_max=0.1, initial=start)
