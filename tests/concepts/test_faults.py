"""Tests of dtwin.fault_injection and dtwin.regime_matching (schedule, injection, Hungarian)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from sklearn.metrics import accuracy_score, cohen_kappa_score, f1_score

from dtwin._validation import DtwinValueError
from dtwin.fault_injection import (
    FAULT_SCHEDULE,
    FEATURES,
    REGIMES,
    FaultMagnitudes,
    RegimeWindow,
    fault_schedule,
    inject_faults,
    regime_features,
    regime_labels,
)
from dtwin.regime_matching import UNMATCHED, classification_scores, hungarian_map, mapped_posteriors
from dtwin.twin.wiring import RESIDUALS
from tests.conftest import REFERENCE

TWIN = {"alpha": 0.6, "w1": 1.0, "w2": 0.2, "dt": 0.02}


@pytest.fixture(scope="module")
def r_nofault(r_pipeline) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "t": np.arange(len(r_pipeline)) * TWIN["dt"],
            "u_act": r_pipeline["u_act_A"],
            "x": r_pipeline["xpos_A_nofault"],
            "y_A": r_pipeline["yA_A_nofault"],
            "y_B": r_pipeline["yB_A_nofault"],
        }
    )


# --- schedule -------------------------------------------------------------------------------


def test_regime_labels_match_r_schedule(r_pipeline):
    labels = regime_labels(np.arange(len(r_pipeline)) * 0.02)
    np.testing.assert_array_equal(labels, r_pipeline["regime"].to_numpy())
    counts = pd.Series(labels).value_counts()
    assert counts.to_dict() == {
        "Drift": 275,
        "Nominal": 250,
        "SensorNoisy": 250,
        "DynamicsOff": 225,
    }


def test_schedule_validation():
    with pytest.raises(DtwinValueError, match="must not overlap"):
        fault_schedule([{"regime": "Nominal", "start": 0, "end": 5}, RegimeWindow("Drift", 4, 6)])
    with pytest.raises(DtwinValueError, match=r"regime must be one of .* \(got 'Broken'\)"):
        fault_schedule([{"regime": "Broken", "start": 0, "end": 5}])
    with pytest.raises(DtwinValueError, match="must cover every sample"):
        regime_labels(np.array([0.0, 25.0]), FAULT_SCHEDULE)
    with pytest.raises(DtwinValueError, match="drift_origin must be one of"):
        FaultMagnitudes(drift_origin="local")


# --- injection ------------------------------------------------------------------------------


def test_injection_reproduces_r_where_deterministic(r_pipeline, r_nofault):
    faulted = inject_faults(r_nofault, np.random.default_rng(0), **TWIN)
    regime = r_pipeline["regime"].to_numpy()
    noisy = regime == "SensorNoisy"
    # DynamicsOff and Drift are deterministic: x scaled, y_A stepped + ramped. The CSV holds
    # 12 significant digits, hence the tolerances (the KPI's velocity divides by dt).
    np.testing.assert_allclose(faulted["x"], r_pipeline["xpos_A_fault"], rtol=0, atol=1e-11)
    np.testing.assert_allclose(
        faulted["y_A"][~noisy], r_pipeline["yA_A_fault"][~noisy], rtol=0, atol=1e-11
    )
    np.testing.assert_allclose(
        faulted["y_B"][~noisy], r_pipeline["yB_A_fault"][~noisy], rtol=0, atol=1e-11
    )
    # KPI from the faulted x with backward-difference velocity, everywhere
    np.testing.assert_allclose(faulted["z"], r_pipeline["z_A_fault"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        faulted["y_fused"][~noisy], r_pipeline["y_fused_A_fault"][~noisy], rtol=0, atol=1e-11
    )
    dynamics = regime == "DynamicsOff"
    np.testing.assert_allclose(
        faulted["x"][dynamics], 0.8 * r_nofault["x"][dynamics], rtol=1e-14, atol=0
    )
    drift = np.flatnonzero(regime == "Drift")
    step = faulted["y_A"].to_numpy()[drift] - r_nofault["y_A"].to_numpy()[drift]
    assert step[0] == pytest.approx(0.0007 * 725)  # the step of the global-index drift
    np.testing.assert_array_equal(faulted["regime"], regime)


def test_sensor_noise_is_interleaved_a_then_b(r_nofault):
    faulted = inject_faults(r_nofault, np.random.default_rng(5), **TWIN)
    noisy = faulted["regime"].to_numpy() == "SensorNoisy"
    draws = np.random.default_rng(5).standard_normal((noisy.sum(), 2))
    np.testing.assert_allclose(
        faulted["y_A"][noisy] - r_nofault["y_A"][noisy], 0.06 * draws[:, 0], atol=1e-14
    )
    np.testing.assert_allclose(
        faulted["y_B"][noisy] - r_nofault["y_B"][noisy], 0.05 * draws[:, 1], atol=1e-14
    )


def test_drift_from_regime_start_is_a_ramp(r_nofault):
    magnitudes = FaultMagnitudes(drift_origin="regime_start", drift_per_sample=0.001)
    faulted = inject_faults(r_nofault, np.random.default_rng(0), magnitudes=magnitudes, **TWIN)
    drift = np.flatnonzero(faulted["regime"].to_numpy() == "Drift")
    added = faulted["y_A"].to_numpy()[drift] - r_nofault["y_A"].to_numpy()[drift]
    np.testing.assert_allclose(added, 0.001 * np.arange(drift.size), atol=1e-12)


# --- features -------------------------------------------------------------------------------


def test_regime_features_by_hand():
    residuals = pd.DataFrame([[1.0, -2.0, 0.0, 0.0, 3.0, 0.0], [0.0, 1.0, 0.0, 0.0, -1.0, 0.0]])
    residuals.columns = list(RESIDUALS)
    features = regime_features(residuals)
    assert tuple(features.columns) == FEATURES
    np.testing.assert_allclose(features["e_abs_sum"], [6.0, 2.0])
    np.testing.assert_allclose(features["e_rms"], [np.sqrt(14 / 6), np.sqrt(2 / 6)])
    np.testing.assert_allclose(features["e1_diff"], [0.0, 3.0])
    np.testing.assert_allclose(features["e3_diff"], [0.0, -4.0])


# --- Hungarian ------------------------------------------------------------------------------


def test_hungarian_reproduces_r_confusion_and_scores(r_pipeline):
    mapping = hungarian_map(r_pipeline["viterbi_state"], r_pipeline["regime"])
    assert mapping.mapping == {1: "Drift", 2: "Nominal", 3: "SensorNoisy", 4: "DynamicsOff"}
    np.testing.assert_array_equal(mapping.predicted, r_pipeline["viterbi_regime"].to_numpy())
    scores = classification_scores(mapping.predicted, r_pipeline["regime"])
    reference = pd.read_csv(REFERENCE / "hungarian_confusion_K4_diag.csv", index_col=0)
    reference.columns = [c.removeprefix("Actual_") for c in reference.columns]
    np.testing.assert_array_equal(scores.confusion.to_numpy(), reference.loc[list(REGIMES)])
    assert list(scores.confusion.columns) == list(reference.columns) == list(REGIMES)
    assert scores.accuracy == pytest.approx(0.85, abs=5e-5)
    assert scores.macro_f1 == pytest.approx(0.8489, abs=5e-5)
    assert scores.kappa == pytest.approx(0.7997, abs=5e-5)
    per_class = pd.read_csv(REFERENCE / "per_class_metrics_K4.csv")
    np.testing.assert_allclose(
        scores.per_class[["precision", "recall", "f1"]],
        per_class[["precision", "recall", "f1"]],
        atol=5e-4,
    )


def test_hungarian_recovers_a_known_permutation():
    rng = np.random.default_rng(1)
    regimes = np.repeat(["r0", "r1", "r2", "r3"], 30)
    permutation = {"r0": 2, "r1": 0, "r2": 3, "r3": 1}
    states = np.array([permutation[r] for r in regimes])
    flip = rng.random(states.size) < 0.1
    states[flip] = rng.integers(0, 4, flip.sum())
    mapping = hungarian_map(states, regimes)
    assert mapping.mapping == {state: regime for regime, state in permutation.items()}
    assert (mapping.predicted == regimes).mean() >= 0.85


def test_hungarian_handles_missing_states_and_k_not_equal_to_regimes():
    regimes = np.array(["a"] * 4 + ["b"] * 4)
    # K = 4 > 2 regimes, state 3 never occurs: two states stay unmatched
    mapping = hungarian_map([0, 0, 0, 1, 2, 2, 2, 2], regimes, all_states=[0, 1, 2, 3])
    assert mapping.mapping[0] == "a" and mapping.mapping[2] == "b"
    assert mapping.mapping[1] == mapping.mapping[3] == UNMATCHED
    assert mapping.contingency.loc[3].sum() == 0
    scores = classification_scores(mapping.predicted, regimes, labels=["a", "b"])
    assert list(scores.confusion.index) == ["a", "b", UNMATCHED]
    assert scores.accuracy == pytest.approx(7 / 8)
    # K = 2 < 3 regimes: one regime is never predicted
    few = hungarian_map([0, 0, 1, 1, 1, 1], ["a", "a", "b", "b", "c", "c"])
    assert sorted(few.mapping.values()) in (["a", "b"], ["a", "c"])
    assert set(few.predicted) <= {"a", "b", "c"}


def test_mapped_posteriors_sum_state_columns_per_regime(r_pipeline):
    mapping = hungarian_map(r_pipeline["viterbi_state"], r_pipeline["regime"])
    gamma = r_pipeline[[f"gamma_S{k}" for k in range(1, 5)]].to_numpy()
    regime_gamma = mapped_posteriors(gamma, mapping)
    np.testing.assert_allclose(regime_gamma.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(regime_gamma["Drift"], gamma[:, 0] / gamma.sum(axis=1))


def test_classification_scores_agree_with_sklearn():
    rng = np.random.default_rng(2)
    labels = list(REGIMES)
    actual = rng.choice(labels, 300)
    predicted = np.where(rng.random(300) < 0.7, actual, rng.choice(labels, 300))
    scores = classification_scores(predicted, actual)
    assert scores.accuracy == pytest.approx(accuracy_score(actual, predicted))
    assert scores.macro_f1 == pytest.approx(f1_score(actual, predicted, average="macro"))
    assert scores.kappa == pytest.approx(cohen_kappa_score(actual, predicted))
    with pytest.raises(DtwinValueError, match="actual holds labels not in labels"):
        classification_scores(["Nominal"], ["Elsewhere"])
