"""Claims across random draws (issue 12): seeds, the aggregate and its Wilson intervals."""

from __future__ import annotations

import numpy as np
import pytest

from dtwin._validation import DtwinValueError
from dtwin.claims import wilson_interval
from dtwin.figures.fig12_claims_across_draws import (
    claims_across_draws,
    collect_draws,
    dynamics_off_window,
)
from dtwin.stages.draws import draw_seeds, run_draw


def _record(draw: int, holds: bool) -> dict:
    return {"draw": draw, "seeds": {}, "claims": {"figA:c": holds, "figB:d": True}, "numbers": {}}


def test_draw_zero_uses_the_configured_seeds_and_others_differ():
    assert draw_seeds(0, 11, 12, 123) == draw_seeds(0, 11, 12, 123)
    zero, one, two = (draw_seeds(d, 11, 12, 123) for d in range(3))
    assert (zero.simulation, zero.faults, zero.hmm) == (11, 12, 123)
    assert len({zero.simulation, one.simulation, two.simulation}) == 3
    with pytest.raises(DtwinValueError, match="draw must be an integer"):
        draw_seeds(-1, 11, 11, 123)


def test_aggregate_counts_draws_with_a_wilson_interval():
    chunks = [
        {"draws": [_record(2, False), _record(3, True)]},
        {"draws": [_record(0, True), _record(1, True)]},
    ]
    records = collect_draws(chunks, 4)
    assert [r["draw"] for r in records] == [0, 1, 2, 3]
    table = claims_across_draws(records, 0.95).set_index("claim")
    assert table.loc["figA:c", "k"] == 3 and table.loc["figA:c", "n"] == 4
    assert (table.loc["figA:c", "low"], table.loc["figA:c", "high"]) == wilson_interval(3, 4)
    assert table.loc["figA:c", "draw0"]


def test_aggregate_fails_with_a_clear_message_when_a_draw_is_missing():
    chunks = [{"draws": [_record(0, True), _record(2, True)]}]
    with pytest.raises(DtwinValueError, match=r"missing \[1\].*rerun claims_draws"):
        collect_draws(chunks, 3)
    with pytest.raises(DtwinValueError, match=r"repeated \[0\]"):
        collect_draws([{"draws": [_record(0, True), _record(0, True)]}], 1)


def test_dynamics_off_window_is_the_mean_a_constant_correction_can_remove():
    regimes = np.array(["Nominal"] * 3 + ["DynamicsOff"] * 4)
    x = np.array([9.0, 9.0, 9.0, 1.0, 2.0, 3.0, 2.0])
    e1 = -0.2 * x
    window = dynamics_off_window(x, e1, regimes)
    assert window["mean_x"] == pytest.approx(2.0) and window["mean_e1"] == pytest.approx(-0.4)
    assert window["e1_mean_share"] == pytest.approx(0.16 / np.mean((0.2 * x[3:]) ** 2))
    assert np.isnan(dynamics_off_window(x, e1, np.array(["Nominal"] * 7))["mean_x"])


@pytest.mark.slow
def test_draw_zero_reproduces_the_stage_tables(config):
    """Draw 0 is the main run: the same fault scores as the stage run on the configured seeds."""
    sections = {
        key: config[key]
        for key in ("simulation", "command", "twin", "arx", "faults", "hmm", "correction", "mcda")
    }
    sections["simulation"] = {**config["simulation"], "T": 20.0}
    tables = run_draw(0, sections)
    summary = tables.fault_summary["origins"][config["faults"]["drift_origin"]]
    assert list(tables.fault_summary["origins"]) == [config["faults"]["drift_origin"]]
    assert 0.5 < summary["accuracy"] <= 1.0
    assert tables.seeds.simulation == config["simulation"]["seed"]
    assert len(tables.mcda_timeline) == len(tables.physics)


def test_fig12_artifact_is_valid_and_orders_claims_by_figure():
    from dtwin.figures.fig12_claims_across_draws import fig12_claims_across_draws

    def record(draw):
        numbers = {
            "accuracy": 0.8,
            "macro_f1": 0.8,
            "kappa": 0.7,
            "nominal_sensor_share": 0.9,
            "lag1_e1": 0.99,
            "lag1_e4": 0.99,
            "min_self_transition": 0.97,
            "rmse_ratio_e1": 1.0,
            "drmse_pct": {e: float(draw) for e in ("e0", "e1", "e2a", "e2b", "e3", "e4")},
            "dynamics_off": {"mean_x": 0.1 * draw, "mean_e1": 0.0, "e1_mean_share": 0.1},
            "action_shares": {"DynamicsOff:ReidentifyPlant": 0.7, "Drift:BiasCorrect": 1.0},
        }
        claims = {"fig10_x:b": True, "fig02_x:a": draw % 2 == 0}
        return {"draw": draw, "seeds": {"simulation": draw}, "claims": claims, "numbers": numbers}

    artifact, table = fig12_claims_across_draws(
        [{"draws": [record(d) for d in range(4)]}], 4, 0.95, {"dynamics_off_mean_x": 0.2}
    )
    assert [c.passed for c in artifact.checks] == [True]
    assert list(artifact.metrics["claims"]) == ["fig02_x:a", "fig10_x:b"]
    assert artifact.metrics["claims"]["fig02_x:a"]["k"] == 2
    assert artifact.metrics["e1_explanation"]["spearman_abs_mean_x_vs_drmse_e1"] == 1.0
    assert len(table) == 4
