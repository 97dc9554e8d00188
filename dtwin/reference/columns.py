"""R's column names and labels, mapped to ours: the one place they are written.

Each table of the authors' R code that dtwin reads (``config/reference/``) uses its own names;
these maps translate them to the paper's signal names (``u_act``, ``x``, ``y_A`` …) and to our
module names (``M0`` …). Loaders in :mod:`dtwin.reference.loaders` apply them.
"""

from __future__ import annotations

__all__ = [
    "R_PHYSICS_COLUMNS",
    "R_SURROGATE_COLUMNS",
    "R_FAULTED_SURROGATE_COLUMNS",
    "R_N_STATES",
    "R_GAMMA_COLUMNS",
    "R_VITERBI_COLUMN",
    "R_THETA_MODULES",
    "R_SWEEP_COLUMNS",
    "R_CORRECTION_METRICS",
    "R_CONFUSION_PREFIX",
    "R_CLASSIFICATION_METRICS",
    "R_RESTART_AGREEMENT_COLUMN",
    "R_BIC_NOMINAL_COLUMNS",
    "R_BIC_FEATURE_COLUMNS",
    "R_MCDA_VERSION",
    "R_MCDA_TIMELINE_COLUMNS",
    "R_MCDA_COUNT_COLUMNS",
]

#: Our signal name → column of R's physics signals in the seed-11 pipeline CSV.
R_PHYSICS_COLUMNS: dict[str, str] = {
    "t": "t",
    "u_cmd": "u_cmd",
    "u_act": "u_act_P",
    "x": "x_pos_P",
    "v": "x_vel_P",
    "y_A": "yA_P",
    "y_B": "yB_P",
    "y_fused": "y_fused_P",
    "z": "z_P",
}

#: Our surrogate signal → R's unfaulted surrogate column (rollouts seeded from physics).
R_SURROGATE_COLUMNS: dict[str, str] = {
    "u_act": "u_act_A",
    "x": "xpos_A_nofault",
    "y_A": "yA_A_nofault",
    "y_B": "yB_A_nofault",
}

#: Our surrogate signal → R's faulted surrogate column (the fault scenario's streams).
R_FAULTED_SURROGATE_COLUMNS: dict[str, str] = {
    "u_act": "u_act_A",
    "x": "xpos_A_fault",
    "y_A": "yA_A_fault",
    "y_B": "yB_A_fault",
}

#: Number of states of R's fault-scenario HMM (``depmixS4``, K = 4).
R_N_STATES = 4

#: R's smoothed state posteriors of the fault-scenario HMM, ``gamma_S1 … gamma_S4``.
R_GAMMA_COLUMNS: tuple[str, ...] = tuple(f"gamma_S{k}" for k in range(1, R_N_STATES + 1))

#: R's Viterbi state (1 … 4) of the fault-scenario HMM.
R_VITERBI_COLUMN = "viterbi_state"

#: R's module label in ``arx_theta_seed11_rerun.csv`` → our module name.
R_THETA_MODULES: dict[str, str] = {
    "M0_cmd": "M0",
    "M1_plant": "M1",
    "M2a_sensA": "M2a",
    "M2b_sensB": "M2b",
}

#: R's sweep table column → ours (``config/reference/sensitivity_36_rerun.csv``).
R_SWEEP_COLUMNS: dict[str, str] = {
    "alpha_fuse": "alpha",
    "sa_mult": "m_A",
    "sb_mult": "m_B",
    "RMSE_e1_orig": "rmse_e1_before",
    "RMSE_e1_corr": "rmse_e1_after",
    "MAE_e1_orig": "mae_e1_before",
    "MAE_e1_corr": "mae_e1_after",
    "L2_orig": "l2_before",
    "L2_corr": "l2_after",
    "dRMSE_e1_pct": "drmse_e1_pct",
    "dMAE_e1_pct": "dmae_e1_pct",
    "dL2_pct": "dl2_pct",
}

#: Our correction metric → column of R's ``targeted_intervention_metrics_rerun.csv``.
R_CORRECTION_METRICS: dict[str, str] = {
    "rmse_before": "RMSE_Original",
    "rmse_after": "RMSE_Corrected",
    "mae_before": "MAE_Original",
    "mae_after": "MAE_Corrected",
    "drmse_pct": "dRMSE_pct",
    "dmae_pct": "dMAE_pct",
}

#: Prefix of the actual-regime columns of ``hungarian_confusion_K4_diag.csv``.
R_CONFUSION_PREFIX = "Actual_"

#: Our score → R's ``metric`` in ``classification_summary_K4.csv``.
R_CLASSIFICATION_METRICS: dict[str, str] = {
    "accuracy": "accuracy",
    "macro_f1": "macro_f1",
    "kappa": "cohen_kappa",
}

#: Column of ``multistart_restarts_K4.csv``: Viterbi agreement (%) of each start with the best.
R_RESTART_AGREEMENT_COLUMN = "viterbi_agreement_pct_loop2_vs_best"

#: Ours → R's column of ``bic_vs_K_6ch_nofault_singlefit_rerun.csv`` (r_notes.md §6 (a)).
R_BIC_NOMINAL_COLUMNS: dict[str, str] = {"K": "K", "bic": "BIC"}

#: Ours → R's column of ``bic_vs_K_10feat_faulted_multistart5.csv`` (r_notes.md §6 (b)).
R_BIC_FEATURE_COLUMNS: dict[str, str] = {
    "K": "K",
    "bic": "BIC_diag_published",
    "log_likelihood": "best_logLik_diag_published",
}

#: The RMCDA release whose timeline and counts we compare with (``legacy_r`` mode).
R_MCDA_VERSION = "0.3.1"

#: Our timeline column → R's column of ``mcda_actions_timeline_rerun.csv`` (RMCDA 0.3.1).
R_MCDA_TIMELINE_COLUMNS: dict[str, str] = {
    "best": f"action_raw_rmcda{R_MCDA_VERSION}",
    "action": f"action_hyst_rmcda{R_MCDA_VERSION}",
}

#: Columns of ``mcda_action_counts_rerun.csv`` (one row per version, stage, regime, action).
R_MCDA_COUNT_COLUMNS: tuple[str, ...] = ("RMCDA_version", "stage", "regime", "action", "count")
