"""Tests of dtwin.reference: R's column maps, the loaders and every crosscheck against R."""

from __future__ import annotations

import ast
from pathlib import Path

import pandas as pd
import pytest

from dtwin.artifacts import Check, load_yaml
from dtwin.reference.bic_crosscheck import crosscheck_bic_formula
from dtwin.reference.correction_crosscheck import crosscheck_correction
from dtwin.reference.crosscheck_result import CrosscheckResult, read_crosscheck, write_crosscheck
from dtwin.reference.em_crosscheck import crosscheck_r_loglik
from dtwin.reference.hungarian_crosscheck import crosscheck_hungarian
from dtwin.reference.loaders import (
    load_r_bic,
    load_r_classification,
    load_r_confusion,
    load_r_correction_metrics,
    load_r_mcda_counts,
    load_r_mcda_timeline,
)
from dtwin.reference.mcda_crosscheck import crosscheck_mcda_legacy
from tests.conftest import REFERENCE

REPO = Path(__file__).resolve().parents[2]
PIPELINE = REFERENCE / "faulted_pipeline_seed11_rerun.csv"

#: R column names that may be written only in dtwin/reference/columns.py.
R_ONLY_NAMES = (
    "x_pos_P",
    "yA_P",
    "u_act_A",
    "xpos_A_fault",
    "alpha_fuse",
    "RMSE_e1_orig",
    "RMSE_Original",
    "viterbi_state",
    "cohen_kappa",
    "Actual_",
    "RMCDA_version",
    "rmcda0.3.1",
    "BIC_diag_published",
    "best_logLik_diag_published",
    "viterbi_agreement_pct_loop2_vs_best",
)


def _code_strings(path: Path) -> list[str]:
    """String constants of a module that are not docstrings."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.FunctionDef | ast.ClassDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return [
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
    ]


def test_r_column_names_live_only_in_columns_py():
    offenders = {
        f"{path.relative_to(REPO)}: {name}"
        for path in (REPO / "dtwin").rglob("*.py")
        if path.name != "columns.py"
        for text in _code_strings(path)
        for name in R_ONLY_NAMES
        if name in text
    }
    assert not offenders


def test_crosscheck_result_round_trips_through_json(tmp_path):
    result = CrosscheckResult(
        [
            Check(
                id="x",
                kind="crosscheck",
                statement="s",
                expected={"a": 0.1},
                observed=[1e-17, 2.5],
                passed=True,
            )
        ],
        {"deviation": {"M0": 0.30000000000000004}},
    )
    write_crosscheck(result, tmp_path / "crosscheck.json")
    assert read_crosscheck(tmp_path / "crosscheck.json") == result


def test_hungarian_crosscheck_reproduces_r(r_pipeline):
    checks, metrics = crosscheck_hungarian(
        r_pipeline,
        load_r_confusion(REFERENCE / "hungarian_confusion_K4_diag.csv"),
        load_r_classification(REFERENCE / "classification_summary_K4.csv"),
    )
    assert [c.passed for c in checks] == [True, True]
    assert metrics["r_mapping"] == {
        "S1": "Drift",
        "S2": "Nominal",
        "S3": "SensorNoisy",
        "S4": "DynamicsOff",
    }


def test_loglik_crosscheck_on_r_features(r_pipeline, config):
    (check,), metrics = crosscheck_r_loglik(r_pipeline, config["hmm"], -2115.852)
    assert check.passed, check.observed
    assert metrics["n_starts_reaching_r"] >= 1


def test_correction_crosscheck_reproduces_r_table(config):
    twin = {key: config["twin"][key] for key in ("dt", "fusion", "kpi")}
    r_metrics = load_r_correction_metrics(REFERENCE / "targeted_intervention_metrics_rerun.csv")
    (check,), deviations = crosscheck_correction(PIPELINE, r_metrics, twin, config["correction"])
    assert check.passed, deviations


def test_mcda_legacy_crosscheck_reproduces_r_timeline(config):
    timeline = load_r_mcda_timeline(REFERENCE / "mcda_actions_timeline_rerun.csv")
    (check,), agreement = crosscheck_mcda_legacy(
        PIPELINE, timeline, config["mcda"], config["twin"]["dt"]
    )
    assert check.passed
    assert agreement == {"raw_agreement": 1.0, "final_agreement": 1.0}


def test_bic_formula_crosscheck_and_r_tables():
    r_tables = load_r_bic(
        REFERENCE / "bic_vs_K_6ch_nofault_singlefit_rerun.csv",
        REFERENCE / "bic_vs_K_10feat_faulted_multistart5.csv",
    )
    assert list(r_tables["fault_features"].columns) == ["K", "bic", "log_likelihood"]
    numbers = load_yaml(REFERENCE / "r_numbers.yaml")
    (check,), deviations = crosscheck_bic_formula(r_tables, numbers["bic_nominal_log_likelihood"])
    assert check.passed, deviations


def test_mcda_counts_are_per_regime_and_action():
    counts = load_r_mcda_counts(REFERENCE / "mcda_action_counts_rerun.csv")
    assert "ALL" not in counts.index
    assert counts.to_numpy().dtype.kind == "i"
    assert (counts.to_numpy() >= 0).all()


def test_a_missing_r_column_is_named(tmp_path):
    path = tmp_path / "metrics.csv"
    pd.DataFrame({"channel": ["e0"], "RMSE_Original": [1.0]}).to_csv(path, index=False)
    with pytest.raises(ValueError, match="RMSE_Corrected"):
        load_r_correction_metrics(path)
