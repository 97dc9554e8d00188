"""Claims across random draws: seeds, the aggregate and its Wilson intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.claim_criteria import dynamics_off_window
from dtwin.figures._draw_bic import judge_draw_bic, k_star_distributions, k_star_table
from dtwin.figures.fig12_claims_across_draws import BicDraws, claims_across_draws, collect_draws
from dtwin.proportions import wilson_interval
from dtwin.stages.draws import REGIME_SECTIONS, draw_seeds, run_draw, run_draw_bic


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


def _numbers(draw: int) -> dict:
    """A draw's headline numbers (made up; the e1 gain and the window's mean x grow with it)."""
    return {
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


def test_fig12_artifact_is_valid_and_orders_claims_by_figure():
    from dtwin.figures.fig12_claims_across_draws import fig12_claims_across_draws

    def record(draw):
        claims = {"fig10_x:b": True, "fig02_x:a": draw % 2 == 0}
        numbers = _numbers(draw)
        return {"draw": draw, "seeds": {"simulation": draw}, "claims": claims, "numbers": numbers}

    artifact, table, _ = fig12_claims_across_draws(
        [{"draws": [record(d) for d in range(4)]}], 4, 0.95, {"dynamics_off_mean_x": 0.2}
    )
    assert [c.passed for c in artifact.checks] == [True]
    assert list(artifact.metrics["claims"]) == ["fig02_x:a", "fig10_x:b"]
    assert artifact.metrics["claims"]["fig02_x:a"]["k"] == 2
    assert artifact.metrics["e1_explanation"]["spearman_abs_mean_x_vs_drmse_e1"] == 1.0
    assert len(table) == 4


def _bic_record(draw: int, bics: dict[str, list[float]], gain: float = 0.0) -> dict:
    """A draw's BIC sweep over K = 2 ... len + 1; K = 4 is the dedicated ("given") fit."""
    rows = []
    for name, values in bics.items():
        for k, bic in enumerate(values, start=2):
            rows.append(
                {
                    "dataset": name,
                    "K": k,
                    "bic": bic,
                    "log_likelihood": -bic / 2,
                    "log_likelihood_half": -bic / 2 - (gain if k == 9 else 0.0),
                    "n_starts": 10 if k == 4 else 4,
                    "source": "given" if k == 4 else "sweep",
                }
            )
    return {"draw": draw, "seeds": {}, "bic": rows}


#: Hand-made BIC curves from K = 2: minimum at K = 8 (to K = 12), at K = 10 (to 11: not bracketed).
AT_8 = [90, 70, 50, 40, 30, 25, 20, 22, 24, 26, 28]
AT_10 = [90, 70, 50, 40, 30, 25, 22, 21, 20, 21]


def test_a_draws_k_star_is_judged_with_fig09s_criteria():
    judged = judge_draw_bic(
        _bic_record(0, {"nominal_residuals": AT_8, "fault_features": AT_10}, gain=3.0)
    )
    assert judged["claims"] == {
        "fig09_bic:bic_minimum_at_k8_nominal_residuals": True,
        "fig09_bic:bic_minimum_at_k8_fault_features": False,
    }
    nominal, fault = judged["k_star"]["nominal_residuals"], judged["k_star"]["fault_features"]
    assert (nominal["k_star"], nominal["bracketed"], nominal["margin_k8"]) == (8, True, 0)
    assert (fault["k_star"], fault["k_last"], fault["bracketed"]) == (10, 11, False)
    # the second half of the starts gained 3 at K = 9 <= K* + 2: not stable
    assert (nominal["max_gain"], nominal["at_k"], nominal["stable"]) == (3.0, 9, False)
    assert fault["margin_k8"] == pytest.approx(2.0) and fault["n_starts"] == 4
    assert nominal["k4_given"] and fault["k4_given"]
    # a K whose starts were doubled: n_starts stays the sweep's base, max_starts says how far
    record = _bic_record(0, {"fault_features": AT_8}, gain=0.0)
    record["bic"][3]["n_starts"] = 16
    doubled = judge_draw_bic(record)["k_star"]["fault_features"]
    assert (doubled["n_starts"], doubled["max_starts"]) == (4, 16)


def test_k_star_distribution_counts_draws_and_the_margin_over_start_noise():
    judged = [
        judge_draw_bic(_bic_record(d, {"fault_features": curve}, gain=0.5))
        for d, curve in enumerate([AT_10, AT_10, AT_8])
    ]
    table = k_star_table(judged)
    dist = k_star_distributions(table, {"fault_features": 11}, 20)["fault_features"]
    assert dist["counts"] == {"8": 1, "10": 2} and dist["n"] == 3 and dist["draw0"] == 10
    assert (dist["k_at_paper"], dist["main_run"], dist["stable"]) == (1, 11, 3)
    # margins 2, 2, 0 against twice the gain (1): K = 8 excluded by more than start noise twice
    assert dist["k8_beyond_start_noise"] == 2


def test_fig12_adds_fig09s_claims_across_draws_with_k_star():
    from dtwin.figures.fig12_claims_across_draws import fig12_claims_across_draws

    chunks = [{"draws": [_record(d, d % 2 == 0) for d in range(2)]}]
    for record in chunks[0]["draws"]:
        record["numbers"] = _numbers(record["draw"])
    bic_chunks = [
        {"draws": [_bic_record(d, {"nominal_residuals": AT_10}) for d in (1, 0)]},
    ]
    main = pd.DataFrame({"dataset": "nominal_residuals", "K": [9, 10, 11], "bic": [3, 1, 2]})
    bic = BicDraws(bic_chunks, 2, main, 20)
    artifact, _, k_star = fig12_claims_across_draws(chunks, 2, 0.95, {}, bic)
    entry = artifact.metrics["claims"]["fig09_bic:bic_minimum_at_k8_nominal_residuals"]
    assert (entry["k"], entry["n"], entry["draw0_is_main_run"]) == (0, 2, False)
    assert entry["detail"].startswith("K* in 2 draws: 10 (2)")
    assert artifact.metrics["k_star"]["nominal_residuals"]["main_run"] == 10
    assert list(k_star["draw"]) == [0, 1]
    assert all(c.passed for c in artifact.checks)
    with pytest.raises(DtwinValueError, match=r"bic_draws: .*missing \[2\].*rerun bic_draws"):
        fig12_claims_across_draws(chunks, 2, 0.95, {}, BicDraws(bic_chunks, 3, main, 20))


def test_a_draws_bic_sweep_uses_its_dedicated_fits_at_k4(config):
    """K* across draws reads the draw up to its fault HMM: no correction or mcda section."""
    sections = {key: config[key] for key in REGIME_SECTIONS}
    sections["simulation"] = {**config["simulation"], "T": 6.0}
    sections["hmm"] = {**config["hmm"], "n_restarts": 2}
    bic = {"ks": [3, 4], "k_max": 5, "stop_after_rises": 2, "n_restarts": 2}
    record = run_draw_bic(1, sections, bic)
    table = pd.DataFrame(record["bic"])
    assert record["draw"] == 1 and record["seeds"]["hmm"] == draw_seeds(1, 11, 11, 123).hmm
    given = table[table["source"] == "given"]
    assert sorted(given["dataset"]) == ["fault_features", "nominal_residuals"]
    assert set(given["K"]) == {config["hmm"]["n_states"]}
    assert set(table.loc[table["source"] == "sweep", "n_starts"]) == {2}
