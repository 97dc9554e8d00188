"""Crosschecks against the authors' R code on exactly the same signals (REFERENCE.md §2, §13).

numpy cannot replay R's random stream, so the seed-11 signals R produced are read from
``config/reference/faulted_pipeline_seed11_rerun.csv`` and our ARX fit and rollout are run on
them: the coefficients must match R's (``arx_theta_seed11_rerun.csv``) and the rollouts R's
unfaulted surrogate signals.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.artifacts import Check
from dtwin.arx import ArxFit, ArxOrders
from dtwin.params import TwinParams
from dtwin.surrogate import fit_surrogates, run_surrogate_chain
from dtwin.wiring import RESIDUALS

__all__ = [
    "R_PHYSICS_COLUMNS",
    "R_SURROGATE_COLUMNS",
    "R_THETA_MODULES",
    "load_r_physics",
    "load_r_theta",
    "crosscheck_arx",
    "load_r_fault_scenario",
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


def _read_csv(path: str | os.PathLike, required: list[str]) -> pd.DataFrame:
    table = pd.read_csv(path)
    missing = [column for column in required if column not in table.columns]
    if missing:
        raise DtwinValueError(f"{path} is missing column(s): {', '.join(missing)}")
    return table


def load_r_physics(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return R's physics signals and unfaulted surrogate signals in our column names.

    Returns
    -------
    (physics, surrogate) : tuple of DataFrame
        ``physics`` has columns ``t`` and the pipeline signals; ``surrogate`` has ``t`` and
        ``u_act, x, y_A, y_B`` (R's ARX rollouts, before any fault).
    """
    raw = _read_csv(path, [*R_PHYSICS_COLUMNS.values(), *R_SURROGATE_COLUMNS.values()])
    physics = pd.DataFrame({ours: raw[theirs] for ours, theirs in R_PHYSICS_COLUMNS.items()})
    surrogate = pd.DataFrame({"t": raw["t"]})
    for ours, theirs in R_SURROGATE_COLUMNS.items():
        surrogate[ours] = raw[theirs]
    return physics, surrogate


def load_r_theta(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Return R's fitted ARX coefficients per module (our module names), ``[a…, b…]``."""
    raw = _read_csv(path, ["module", "theta"])
    return {
        R_THETA_MODULES[label]: np.array([float(v) for v in str(text).split(";")])
        for label, text in zip(raw["module"], raw["theta"], strict=True)
    }


def crosscheck_arx(
    r_pipeline_path: str | os.PathLike,
    r_theta_path: str | os.PathLike,
    orders: Mapping[str, ArxOrders],
    train_frac: float,
    twin: TwinParams,
    theta_rtol: float = 1e-6,
    rollout_atol: float = 1e-9,
) -> tuple[list[Check], dict[str, dict[str, float]]]:
    """Fit our ARX models on R's physics signals and compare with R.

    Returns
    -------
    (checks, metrics)
        Two ``crosscheck`` checks (coefficients within ``theta_rtol`` relative, rollouts
        within ``rollout_atol`` absolute) and the per-module deviations behind them.
    """
    physics, r_surrogate = load_r_physics(r_pipeline_path)
    r_theta = load_r_theta(r_theta_path)
    fits: dict[str, ArxFit] = fit_surrogates(physics, orders, train_frac)
    ours = run_surrogate_chain(physics, fits, twin, rollout_init="physics")
    theta_dev = {
        name: float(np.max(np.abs(fits[name].theta - ref) / np.abs(ref)))
        for name, ref in r_theta.items()
    }
    rollout_dev = {
        signal: float(np.max(np.abs(ours[signal].to_numpy() - r_surrogate[signal].to_numpy())))
        for signal in R_SURROGATE_COLUMNS
    }
    checks = [
        Check(
            id="arx_theta_matches_r",
            kind="crosscheck",
            statement="our least-squares ARX fit on R's seed-11 physics gives R's coefficients",
            expected=f"max relative deviation <= {theta_rtol:g} per module",
            observed=theta_dev,
            passed=all(dev <= theta_rtol for dev in theta_dev.values()),
        ),
        Check(
            id="arx_rollout_matches_r",
            kind="crosscheck",
            statement="our recursive surrogate-chain rollout on R's signals equals R's rollout",
            expected=f"max absolute deviation <= {rollout_atol:g} per signal",
            observed=rollout_dev,
            passed=all(dev <= rollout_atol for dev in rollout_dev.values()),
        ),
    ]
    return checks, {"theta_max_rel_dev": theta_dev, "rollout_max_abs_dev": rollout_dev}


def load_r_fault_scenario(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Return R's faulted residuals and its Hungarian-mapped regime posteriors.

    Returns
    -------
    (residuals, posteriors) : tuple of DataFrame
        ``residuals``: ``t, regime, e0 … e4`` (R's fault scenario, seed 11);
        ``posteriors``: ``p_<regime>`` per step, R's smoothed state posteriors ``gamma_S1…S4``
        summed per regime through the Hungarian map of R's Viterbi path (rows sum to 1).
    """
    from dtwin.faults import REGIMES, hungarian_map, mapped_posteriors

    gamma_columns = [f"gamma_S{k}" for k in range(1, 5)]
    raw = _read_csv(path, ["t", "regime", "viterbi_state", *RESIDUALS, *gamma_columns])
    mapping = hungarian_map(
        raw["viterbi_state"].to_numpy(), raw["regime"].to_numpy(), all_states=[1, 2, 3, 4]
    )
    probs = mapped_posteriors(raw[gamma_columns].to_numpy(), mapping)
    posteriors = pd.DataFrame({f"p_{regime}": probs[regime] for regime in REGIMES})
    return raw[["t", "regime", *RESIDUALS]].copy(), posteriors
