"""MCDA/TOPSIS action selection (paper §5, Table 1; r_notes.md §8)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from pymcdm import normalizations
from pymcdm.methods import TOPSIS

from dtwin._validation import DtwinValueError
from dtwin.mcda import ACTIONS, NO_ACTION, McdaSettings, run_mcda, select_actions, topsis
from dtwin.reference.loaders import load_r_fault_scenario
from tests.conftest import REFERENCE

WEIGHTS = {
    "KPI_gain": 0.35,
    "Module_gain": 0.25,
    "Drift_gain": 0.15,
    "Stability": 0.10,
    "Cost": 0.15,
}
REGIMES = ("Nominal", "SensorNoisy", "DynamicsOff", "Drift")


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_topsis_matches_pymcdm_on_random_matrices(seed):
    rng = np.random.default_rng(seed)
    matrix = rng.uniform(-2, 3, size=(rng.integers(2, 8), rng.integers(2, 7)))
    weights = rng.uniform(0.05, 1, size=matrix.shape[1])
    weights /= weights.sum()
    ours, degenerate = topsis(matrix, weights)
    reference = TOPSIS(normalization_function=normalizations.vector_normalization)(
        matrix, weights, np.ones(matrix.shape[1], dtype=int)
    )
    np.testing.assert_allclose(ours, reference, atol=1e-12)
    assert not degenerate


def test_weights_act_on_criteria_not_alternatives():
    matrix = np.array([[1.0, 0.0], [0.0, 1.0]])
    favour_first_criterion, _ = topsis(matrix, [0.9, 0.1])
    favour_second_criterion, _ = topsis(matrix, [0.1, 0.9])
    assert np.argmax(favour_first_criterion) == 0
    assert np.argmax(favour_second_criterion) == 1


def test_all_zero_column_is_degenerate_but_still_ranks():
    matrix = np.array([[0.0, 1.0, -0.1], [0.0, 3.0, -0.2], [0.0, 2.0, -0.3]])
    closeness, degenerate = topsis(matrix, [0.4, 0.4, 0.2])
    assert degenerate and np.all(np.isfinite(closeness))
    # the zero column carries no information: same ranking as without it
    without, _ = topsis(matrix[:, 1:], [0.4, 0.2])
    np.testing.assert_allclose(closeness, without)


def test_bad_weights_are_rejected():
    with pytest.raises(DtwinValueError, match="weights"):
        topsis(np.ones((3, 2)), [1.0])


def test_noaction_is_reachable_after_an_action():
    scores = np.tile([0.2, 0.9, 0.1], (60, 1))
    gate = np.zeros(60, dtype=bool)
    gate[40:] = True
    fixed = select_actions(scores, gate, dwell=5, margin=0.02)
    legacy = select_actions(scores, gate, dwell=5, margin=0.02, legacy_r=True)
    assert fixed[0] == 1 and fixed[-1] == 3  # index n_actions = NoAction
    assert np.all(legacy == 1)  # the authors' code can never return to NoAction


def test_dwell_and_margin_are_obeyed():
    rng = np.random.default_rng(4)
    scores = rng.uniform(size=(300, 4))
    chosen = select_actions(scores, np.zeros(300, dtype=bool), dwell=25, margin=0.02)
    switches = np.flatnonzero(np.diff(chosen)) + 1
    assert np.all(np.diff(switches) > 25)
    for step in switches:
        assert scores[step, chosen[step]] - scores[step, chosen[step - 1]] > 0.02


def _r_inputs():
    return load_r_fault_scenario(REFERENCE / "faulted_pipeline_seed11_rerun.csv")


def test_legacy_mode_reproduces_r_031_timeline_exactly():
    r, probs = _r_inputs()
    timeline = pd.read_csv(REFERENCE / "mcda_actions_timeline_rerun.csv")
    result = run_mcda(r, probs, 0.02, McdaSettings(weights=WEIGHTS, legacy_r=True))
    assert result.thresholds["kpi"] == pytest.approx(0.5259335, abs=1e-7)
    assert result.thresholds["agg"] == pytest.approx(0.9088305, abs=1e-7)
    assert (result.timeline["best"] == timeline["action_raw_rmcda0.3.1"]).all()
    assert (result.timeline["action"] == timeline["action_hyst_rmcda0.3.1"]).all()
    scored = timeline["score_rmcda0.3.1"].notna()
    np.testing.assert_allclose(
        result.timeline.loc[scored, "best_score"],
        timeline.loc[scored, "score_rmcda0.3.1"],
        atol=1e-9,
    )


def test_fixed_mode_on_r_inputs_counts_degenerate_steps_and_returns_to_noaction():
    r, probs = _r_inputs()
    result = run_mcda(r, probs, 0.02, McdaSettings(weights=WEIGHTS))
    timeline = result.timeline
    assert result.n_degenerate == int(timeline["degenerate"].sum()) > 0
    assert (timeline["confidence"] >= 0).all()
    first_action = np.flatnonzero(timeline["action"] != NO_ACTION)[0]
    assert (timeline["action"].iloc[first_action:] == NO_ACTION).any()
    assert set(timeline["action"]) <= {a.name for a in ACTIONS} | {NO_ACTION}
