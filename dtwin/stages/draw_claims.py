"""The paper's single-draw claims judged on one random draw, with the figures' own criteria.

Each claim of Figs. 2–8 and 10 is judged here on the tables of one draw
(:class:`dtwin.stages.draws.DrawTables`) with the criterion the figure that states it calls:
:mod:`dtwin.claim_criteria` (Figs. 2–6, 10) and :mod:`dtwin.fault_claim_criteria` (Figs. 7, 8).
No figure module is imported, so a label edit in a figure reruns no draw. Draw 0 is the main
run, so its verdicts must equal the figures' (a validity check of Fig. 12 compares them).
Claim keys are ``"<artifact>:<check id>"``, as in ``paper_figures/claims.json``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.claim_criteria import (
    MCDA_CLAIMS,
    action_share,
    all_structured,
    dynamics_off_window,
    lowered_in_m1_m2b_m3_m4,
    not_white,
    regimes_are_persistent,
    residual_spread,
    rmse_like_r,
    strongly_autocorrelated,
    tightened,
)
from dtwin.fault_claim_criteria import fault_claims, feature_claims, feature_stats
from dtwin.fault_injection import regime_features
from dtwin.hmm_basics import zscore
from dtwin.residual_stats import acf_table, ljung_box_table
from dtwin.twin.wiring import RESIDUALS

__all__ = ["judge_draw"]


def _twin_claims(
    tables: Any, acf: Mapping[str, Any], r_rmse: Mapping[str, float]
) -> tuple[dict[str, bool], dict[str, Any]]:
    """Figs. 2–4: ARX agreement, residual structure, persistence of the nominal regimes."""
    residuals = tables.residuals
    n_train = int(tables.theta["n_train"].iloc[0])
    rmse = {e: float(np.sqrt(np.mean(residuals[e].to_numpy()[n_train:] ** 2))) for e in RESIDUALS}
    lag1 = acf_table(residuals, RESIDUALS, 1)
    max_p = (
        ljung_box_table(residuals, RESIDUALS, acf["ljungbox_lags"])
        .groupby("channel")["lb_pvalue"]
        .max()
        .to_dict()
    )
    alpha, strong = acf["significance"], acf["strong_lag1"]
    self_prob = np.diag(np.asarray(tables.nominal_model["transmat"]))
    dt = float(residuals["t"].iloc[1] - residuals["t"].iloc[0])
    claims = {
        "fig02_arx_vs_physics:general_agreement": rmse_like_r(rmse, r_rmse),
        "fig03_residual_acf:all_residuals_structured": all_structured(max_p, alpha),
        "fig04_hmm_posteriors:regimes_are_persistent": regimes_are_persistent(self_prob, dt),
    }
    for e in ("e1", "e4"):
        claims[f"fig03_residual_acf:{e}_strongly_autocorrelated"] = strongly_autocorrelated(
            lag1[e].iloc[1], strong
        )
        claims[f"fig03_residual_acf:{e}_not_white"] = not_white(max_p[e], alpha)
    numbers = {
        "rmse_ratio_e1": rmse["e1"] / r_rmse["e1"],
        "lag1_e1": float(lag1["e1"].iloc[1]),
        "lag1_e4": float(lag1["e4"].iloc[1]),
        "min_self_transition": float(self_prob.min()),
    }
    return claims, numbers


def _fault_claims(
    tables: Any, r_scores: Mapping[str, float]
) -> tuple[dict[str, bool], dict[str, Any]]:
    """Figs. 7, 8: regime scores, confusions, onsets; the feature observations."""
    origin = tables.fault_summary["drift_origin"]
    scenario = tables.fault_summary["origins"][origin]
    checks = fault_claims(tables.fault_posteriors, scenario, r_scores, origin)
    regimes = tables.fault_residuals["regime"].to_numpy(dtype=str)
    features = zscore(regime_features(tables.fault_residuals)).to_frame()
    checks += feature_claims(feature_stats(features, regimes))
    artifacts = ["fig07_fault_posteriors"] * 3 + ["fig08_feature_separability"] * 3
    claims = {f"{a}:{c.id}": bool(c.passed) for a, c in zip(artifacts, checks, strict=True)}
    numbers = {key: float(scenario[key]) for key in ("accuracy", "macro_f1", "kappa")}
    numbers["nominal_sensor_share"] = float(scenario["nominal_sensor_share"])
    return claims, numbers


def _correction_claims(tables: Any) -> tuple[dict[str, bool], dict[str, Any]]:
    """Figs. 5, 6: which residuals the correction lowers and tightens."""
    metrics = tables.correction_metrics
    smoothed = metrics[metrics["variant"] == "smoothed"].set_index("channel")["drmse_pct"]
    spread = residual_spread(tables.correction_residuals)
    claims = {
        "fig05_correction_timeseries:lowered_in_m1_m2b_m3_m4": lowered_in_m1_m2b_m3_m4(smoothed),
        "fig06_correction_distributions:tighter_in_every_module_but_m0": all(
            tightened(spread[e]) for e in RESIDUALS if e != "e0"
        ),
        "fig06_correction_distributions:not_tighter_in_m0": not tightened(spread["e0"]),
    }
    window = dynamics_off_window(
        tables.physics["x"].to_numpy(),
        tables.fault_residuals["e1"].to_numpy(),
        tables.fault_residuals["regime"].to_numpy(dtype=str),
    )
    numbers = {"drmse_pct": {e: float(smoothed[e]) for e in RESIDUALS}, "dynamics_off": window}
    return claims, numbers


def _mcda_claims(tables: Any) -> tuple[dict[str, bool], dict[str, Any]]:
    """Fig. 10: the regime's most frequent action, and the action shares."""
    timeline = tables.mcda_timeline
    counts = pd.crosstab(timeline["regime"], timeline["action"])
    claims, shares = {}, {}
    for regime, action in MCDA_CLAIMS:
        share, is_mode = action_share(counts, regime, action)
        claims[f"fig10_mcda_actions:{regime}_mostly_{action}"] = bool(is_mode)
        shares[f"{regime}:{action}"] = share
    overall = timeline["action"].value_counts(normalize=True).sort_index()
    return claims, {"action_shares": shares, "overall_action_shares": overall.to_dict()}


def judge_draw(
    tables: Any,
    acf: Mapping[str, Any],
    r_scores: Mapping[str, float],
    r_rmse: Mapping[str, float],
) -> dict[str, Any]:
    """Judge every single-draw claim of Figs. 2–8 and 10 on one draw (Fig. 9's: Fig. 12's rule).

    Parameters
    ----------
    tables : DrawTables
        :func:`dtwin.stages.draws.run_draw`'s result (read through its attributes).
    acf : mapping
        The ``acf`` config section (``ljungbox_lags``, ``significance``, ``strong_lag1``).
    r_scores : mapping
        R's ``accuracy``, ``macro_f1``, ``kappa`` (Fig. 7's claim compares with them).
    r_rmse : mapping
        R's held-out RMSE per residual (``r_numbers.yaml`` ``nominal_rmse_test_half``; Fig. 2).

    Returns
    -------
    dict
        ``draw``, ``seeds`` (``simulation``, ``faults``, ``hmm``), ``claims`` (claim key →
        held or not) and ``numbers`` (the headline numbers: scores, dRMSE % per residual,
        lag-1 ACF of e1/e4, e1's held-out RMSE over R's, the DynamicsOff window of
        :func:`dynamics_off_window`, action shares).
    """
    claims: dict[str, bool] = {}
    numbers: dict[str, Any] = {}
    for part in (
        _twin_claims(tables, acf, r_rmse),
        _fault_claims(tables, r_scores),
        _correction_claims(tables),
        _mcda_claims(tables),
    ):
        claims.update(part[0])
        numbers.update(part[1])
    seeds = tables.seeds
    return {
        "draw": seeds.draw,
        "seeds": {"simulation": seeds.simulation, "faults": seeds.faults, "hmm": seeds.hmm},
        "claims": claims,
        "numbers": numbers,
    }
