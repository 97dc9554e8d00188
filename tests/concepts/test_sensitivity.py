"""Tests of dtwin.sensitivity_sweep: grid, seeds, one configuration, R's inputs, aggregation."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinTypeError, DtwinValueError
from dtwin.figures._fig11_claims import sweep_claim_numbers
from dtwin.params import twin_params_from_mapping
from dtwin.reference.loaders import load_r_physics, load_r_sweep
from dtwin.sensitivity_sweep import (
    SWEEP_COLUMNS,
    SweepPoint,
    alpha_trends,
    bimodality_coefficient,
    replicate_seed,
    scale_twin,
    summarize_sweep,
    sweep_grid,
    sweep_table,
)
from dtwin.stages.sensitivity import sweep_point, sweep_point_on_r_signals
from tests.conftest import REFERENCE


@pytest.fixture(scope="module")
def sections(config) -> dict:
    """Config sections of one sweep job, on an 8 s horizon with 2 EM starts (fast)."""
    sensitivity = {
        **config["sensitivity"],
        "hmm": {**config["sensitivity"]["hmm"], "n_restarts": 2},
    }
    return {
        "simulation": {**config["simulation"], "T": 8.0},
        "command": config["command"],
        "twin": config["twin"],
        "arx": config["arx"],
        "sensitivity": sensitivity,
    }


@pytest.fixture(scope="module")
def r_sweep() -> pd.DataFrame:
    return load_r_sweep(REFERENCE / "sensitivity_36_rerun.csv")


# --- grid and seeds -------------------------------------------------------------------------


def test_grid_expands_every_configuration_and_replicate_in_r_order(config):
    s = config["sensitivity"]
    grid = sweep_grid(s["alphas"], s["sensor_A_mults"], s["sensor_B_mults"], 1)
    assert len(grid) == 36 and len(set(grid)) == 36
    assert grid[:5] == [
        SweepPoint(0.2, 0.5, 0.5, 0),
        SweepPoint(0.4, 0.5, 0.5, 0),
        SweepPoint(0.6, 0.5, 0.5, 0),
        SweepPoint(0.8, 0.5, 0.5, 0),
        SweepPoint(0.2, 1.0, 0.5, 0),
    ]
    big = sweep_grid(np.linspace(0, 1, 10), np.linspace(0.5, 2, 10), np.linspace(0.5, 2, 10), 20)
    assert len(big) == 20_000
    assert {p.replicate for p in big} == set(range(20))


@pytest.mark.parametrize(
    ("args", "error", "message"),
    [
        (([0.2, 1.3], [1], [1]), DtwinValueError, r"sensitivity.alphas\[1\] must be in \[0, 1\]"),
        (([0.2, 0.2], [1], [1]), DtwinValueError, "sensitivity.alphas must not repeat"),
        (([0.2], [], [1]), DtwinValueError, "sensor_A_mults must list at least one"),
        (([0.2], [1], [-1]), DtwinValueError, r"sensor_B_mults\[0\] must be >= 0"),
        (([0.2], [1], [1], 0), DtwinValueError, "n_replicates must be >= 1"),
        (([0.2], [1], [1], 1.5), DtwinTypeError, "n_replicates must be an integer"),
        ((0.2, [1], [1]), DtwinTypeError, "alphas must be a list"),
    ],
)
def test_grid_names_the_offending_key(args, error, message):
    with pytest.raises(error, match=message):
        sweep_grid(*args)


def test_replicate_seeds_are_deterministic_and_replicate_0_is_the_base_seed():
    assert replicate_seed(11, 0) == 11
    seeds = [replicate_seed(11, r) for r in range(1, 50)]
    assert seeds == [replicate_seed(11, r) for r in range(1, 50)]
    assert len(set(seeds)) == len(seeds) and 11 not in seeds
    assert replicate_seed(12, 1) != replicate_seed(11, 1)
    with pytest.raises(DtwinValueError, match="replicate must be an integer >= 0"):
        replicate_seed(11, -1)


def test_scale_twin_changes_only_fusion_and_sensor_noise(config):
    twin = config["twin"]
    scaled = scale_twin(twin, 0.2, 0.5, 1.5)
    assert scaled.fusion.alpha == 0.2
    assert scaled.noise.sensor_A == 0.5 * twin["noise"]["sensor_A"]
    assert scaled.noise.sensor_B == 1.5 * twin["noise"]["sensor_B"]
    parsed = twin_params_from_mapping(twin)
    assert scaled.plant == parsed.plant and scaled.noise.plant == parsed.noise.plant
    assert scale_twin(parsed, 0.2, 0.5, 1.5) == scaled
    assert twin["fusion"]["alpha"] == 0.6 and parsed.fusion.alpha == 0.6  # inputs unchanged


# --- one configuration end to end -------------------------------------------------------------


def test_one_configuration_is_finite_and_reproducible(sections):
    point = SweepPoint(0.4, 1.5, 0.5, 0)
    first = sweep_point(point, **sections)
    second = sweep_point(point, **sections)
    assert first == second
    assert first.n_steps == 400 and first.physics_seed == 11 and first.hmm_seed == 11
    rows = first.rows()
    assert [row["method"] for row in rows] == ["code", "paper"]
    assert all(list(row) == sorted(row, key=SWEEP_COLUMNS.index) for row in rows)
    for row in rows:
        values = [row[c] for c in SWEEP_COLUMNS[7:] if c != "converged"]
        assert all(math.isfinite(v) for v in values)
        assert row["rmse_e1_before"] > 0 and row["l2_before"] > 0
        expected = 100 * (row["rmse_e1_before"] - row["rmse_e1_after"]) / row["rmse_e1_before"]
        assert row["drmse_e1_pct"] == pytest.approx(expected)


def test_e1_is_shared_by_configurations_and_replicates_differ(sections):
    a = sweep_point(SweepPoint(0.2, 0.5, 1.5, 0), **sections).rows()[0]
    b = sweep_point(SweepPoint(0.8, 1.5, 0.5, 0), **sections).rows()[0]
    c = sweep_point(SweepPoint(0.2, 0.5, 1.5, 1), **sections).rows()[0]
    assert a["rmse_e1_before"] == b["rmse_e1_before"]
    assert a["l2_before"] != b["l2_before"]
    assert c["physics_seed"] == replicate_seed(11, 1) and c["rmse_e1_before"] != a["rmse_e1_before"]


def test_r_signals_rebuild_r_sweep_inputs_exactly(sections, r_sweep):
    """R's configurations, rebuilt from R's seed-11 signals, give R's pre-correction numbers."""
    r_physics, _ = load_r_physics(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
    point = SweepPoint(0.2, 1.5, 0.5, 0)
    run = sweep_point_on_r_signals(point, r_physics, **_r_sections(sections))
    row = run.rows()[0]
    r_row = r_sweep.query("alpha == 0.2 and m_A == 1.5 and m_B == 0.5").iloc[0]
    assert run.n_steps == 1000 and run.physics_seed is None
    for key in ("rmse_e1_before", "mae_e1_before", "l2_before"):
        assert row[key] == pytest.approx(r_row[key], rel=1e-7), key


def _r_sections(sections: dict) -> dict:
    return {k: sections[k] for k in ("twin", "arx", "sensitivity")}


# --- aggregation ------------------------------------------------------------------------------


def _fake_rows(grid, value=lambda p: 10 * p.alpha + p.replicate):
    rows = []
    for p in grid:
        for source in ("ours", "r_signals"):
            for method in ("code", "paper"):
                row = dict.fromkeys(SWEEP_COLUMNS, 1.0)
                row.update(p._asdict(), source=source, method=method, converged=True)
                row["drmse_e1_pct"] = value(p)
                rows.append(row)
    return rows


def test_aggregate_names_the_missing_configuration():
    grid = sweep_grid([0.2, 0.8], [1.0], [0.5], 2)
    rows = [r for r in _fake_rows(grid) if not (r["alpha"] == 0.8 and r["replicate"] == 1)]
    with pytest.raises(
        DtwinValueError,
        match=r"missing 1 of 4 configurations: "
        r"alpha=0\.8, m_A=1, m_B=0\.5, replicate 1",
    ):
        sweep_table(rows, grid)
    with pytest.raises(
        DtwinValueError, match=r"outside the grid: alpha=0\.2, m_A=1, m_B=0\.5, replicate 1"
    ):
        sweep_table(_fake_rows(grid), grid[:2])


def test_summary_mean_interval_and_alpha_slopes():
    grid = sweep_grid([0.2, 0.8], [1.0], [0.5], 5)
    table = sweep_table(_fake_rows(grid), grid)
    summary = summarize_sweep(table, interval=0.5)
    row = summary.query("source == 'ours' and method == 'code' and alpha == 0.2").iloc[0]
    values = 2.0 + np.arange(5)
    assert row["n_replicates"] == 5
    assert row["drmse_e1_mean"] == pytest.approx(values.mean())
    assert row["drmse_e1_sd"] == pytest.approx(values.std(ddof=1))
    assert (row["drmse_e1_lo"], row["drmse_e1_hi"]) == pytest.approx((3.0, 5.0))
    slopes = alpha_trends(table)
    assert len(slopes) == 2 * 2 * 5
    np.testing.assert_allclose(slopes["slope_pct_per_unit_alpha"], 10.0)


def test_claim_numbers_reproduce_references_summary_of_r(r_sweep):
    """r_notes.md §9: R's 36 values: min 23.28, max 41.85, mean 29.54, median 24.95."""
    numbers = sweep_claim_numbers(
        r_sweep[["alpha", "m_A", "m_B"]].assign(value=r_sweep["drmse_e1_pct"])
    )
    assert [round(numbers[k], 2) for k in ("min", "max", "mean", "median")] == [
        23.28,
        41.85,
        29.54,
        24.95,
    ]
    assert numbers["argmax"] == {
        "alpha": 0.8,
        "m_A": 1.5,
        "m_B": 0.5,
        "value": pytest.approx(41.85, abs=0.01),
    }
    assert numbers["n_low_mode"] == 26
    assert numbers["bimodality_coefficient"] > 5 / 9


def test_bimodality_coefficient_separates_one_and_two_modes():
    rng = np.random.default_rng(0)
    assert bimodality_coefficient(rng.normal(size=500)) < 5 / 9
    two = np.concatenate([rng.normal(24, 1, 250), rng.normal(40, 1, 250)])
    assert bimodality_coefficient(two) > 5 / 9
    assert math.isnan(bimodality_coefficient([1.0, 2.0, 3.0]))


def test_a_failed_alpha_trend_claim_names_the_optimiser_with_the_slopes_of_each_source():
    from dtwin.artifacts import Check
    from dtwin.figures.fig11_sensitivity import _with_notes

    def row(slope: float) -> dict:
        return {"median_slope": slope, "mean_slope": slope, "frac_positive": float(slope > 0)}

    observed = {
        "ours": {"m_A=0.5": row(0.42), "m_A=1": row(-0.39)},
        "r_rerun": {"m_A=0.5": row(2.6), "m_A=1": row(13.05)},
        "passed_by_source": {"ours": False, "r_rerun": True},
    }
    check = Check(
        id="alpha_trend_sensor_B_degraded",
        kind="claim",
        statement="paper §5: improvements increased with α",
        expected="median slope > 0 in every Sensor A row",
        observed=observed,
        passed=False,
    )
    (noted,) = _with_notes([check], "ours 36.1–37.2 % in 36 of 36", 10, "kmeans++")
    assert noted.note.startswith("optimiser: ours 36.1–37.2 % in 36 of 36")
    assert "ours +0.42/-0.39; R's re-run +2.60/+13.05" in noted.note
    assert "Holds: ours no, R's re-run yes" in noted.note
    assert "Dirichlet start" in noted.note


def _two_replicate_table():
    """The paper's 36 configurations twice: replicate 0 rises with α (27–33 %), replicate 1
    falls with α and goes negative (3 … −3 %)."""
    grid = sweep_grid([0.2, 0.4, 0.6, 0.8], [0.5, 1.0, 1.5], [0.5, 1.0, 1.5], 2)

    def value(p):
        return 25.0 + 10.0 * p.alpha if p.replicate == 0 else 5.0 - 10.0 * p.alpha

    return sweep_table(_fake_rows(grid, value), grid)


def test_claims_are_judged_on_each_replicate_alone():
    from dtwin.claims import REPLICATES_METRIC, summarise_claims
    from dtwin.figures import _fig11_claims

    table = _two_replicate_table()
    axes = {"m_A": [0.5, 1.0, 1.5], "m_B": [0.5, 1.0, 1.5]}
    block = _fig11_claims.claims_across_replicates(table, "code", [0.2, 0.4, 0.6, 0.8], axes)
    assert block["n_replicates"] == 2 and block["replicate0_is_figure"] is False
    verdicts = block["verdicts"]
    # replicate 0: every value in 27-33 %, slope +10 %/unit α; replicate 1: below 0 %, slope -10
    assert verdicts["all_positive"] == [True, False]
    assert verdicts["range_23_40"] == [True, False]
    assert verdicts["alpha_trend_sensor_B_degraded"] == [True, False]
    # the claims rule reads the block under the same key: k = 1 of 2 with Wilson's interval
    assert _fig11_claims.REPLICATES_METRIC == REPLICATES_METRIC
    payload = {
        "artifact": "fig11_sensitivity",
        "checks": [
            {
                "id": "all_positive",
                "kind": "claim",
                "statement": "paper §5: positive everywhere",
                "passed": True,
            }
        ],
        "metrics": {REPLICATES_METRIC: block},
    }
    row = summarise_claims([payload]).rows[0]
    assert (row["draws"]["k"], row["draws"]["n"], row["draws"]["unit"]) == (1, 2, "replicates")
    assert row["draws"]["low"] == pytest.approx(0.0945, abs=1e-4)


def test_one_replicates_verdicts_are_the_figures():
    """With one replicate the figure's claims (on summarize_sweep's means) are replicate 0's."""
    from dtwin.figures._fig11_claims import claims_across_replicates, sweep_claims

    full = _two_replicate_table()
    table = full[full["replicate"] == 1].assign(replicate=0).reset_index(drop=True)
    alphas, axes = [0.2, 0.4, 0.6, 0.8], {"m_A": [0.5, 1.0, 1.5], "m_B": [0.5, 1.0, 1.5]}
    summary = summarize_sweep(table).query("source == 'ours' and method == 'code'")
    means = summary[["alpha", "m_A", "m_B"]].assign(value=summary["drmse_e1_mean"])
    slopes = alpha_trends(table).query("source == 'ours' and method == 'code'")
    figure = {
        c.id: c.passed
        for c in sweep_claims({"ours": sweep_claim_numbers(means, slopes)}, alphas, axes)
    }
    block = claims_across_replicates(table, "code", alphas, axes)
    assert block["replicate0_is_figure"] is True
    assert {k: v[0] for k, v in block["verdicts"].items()} == figure
    assert figure["all_positive"] is False  # the check compares verdicts that can differ
    with pytest.raises(DtwinValueError, match="no run of our own with correction 'other'"):
        claims_across_replicates(table, "other", alphas, axes)
