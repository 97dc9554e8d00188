"""R's column names and labels, mapped to ours: the one place they are written.

Each table of the authors' R code that dtwin reads (``config/reference/``) uses its own names;
these maps translate them to the paper's signal names (``u_act``, ``x``, ``y_A`` …) and to our
module names (``M0`` …). Loaders in :mod:`dtwin.reference.loaders` apply them.
"""

from __future__ import annotations

__all__ = [
    "R_PHYSICS_COLUMNS",
    "R_SURROGATE_COLUMNS",
    "R_THETA_MODULES",
    "R_SWEEP_COLUMNS",
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
