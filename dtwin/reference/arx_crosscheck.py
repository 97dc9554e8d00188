"""Crosscheck of the ARX surrogates (paper §3.2) against the authors' R code on R's signals.

numpy cannot replay R's random stream, so the seed-11 signals R produced are read from
``config/reference/faulted_pipeline_seed11_rerun.csv`` and our code is run on them: the ARX
coefficients must match R's (``arx_theta_seed11_rerun.csv``) and the rollouts R's unfaulted
surrogate signals. Run by rule ``fit_surrogates`` (``results/arx_crosscheck.json``) and
reported by Fig. 2.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

from dtwin.artifacts import Check
from dtwin.arx import ArxFit, ArxOrders
from dtwin.params import TwinParams
from dtwin.reference.columns import R_SURROGATE_COLUMNS
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.reference.loaders import load_r_physics, load_r_theta
from dtwin.surrogate import fit_surrogates, run_surrogate_chain

__all__ = ["crosscheck_arx"]


def crosscheck_arx(
    r_pipeline_path: str | os.PathLike,
    r_theta_path: str | os.PathLike,
    orders: Mapping[str, ArxOrders],
    train_frac: float,
    twin: TwinParams,
    theta_rtol: float = 1e-6,
    rollout_atol: float = 1e-9,
) -> CrosscheckResult:
    """Fit our ARX models on R's physics signals and compare with R.

    Parameters
    ----------
    r_pipeline_path, r_theta_path : path
        ``faulted_pipeline_seed11_rerun.csv`` and ``arx_theta_seed11_rerun.csv``.
    orders : mapping of str to ArxOrders
        ARX orders per module (the ``arx.orders`` config).
    train_frac : float
        Share of the run the ARX models are fitted on.
    twin : TwinParams
        The twin's parameters (fusion and KPI of the rollout).
    theta_rtol : float, default 1e-6
        Allowed relative deviation of every coefficient.
    rollout_atol : float, default 1e-9
        Allowed absolute deviation of every rollout sample.

    Returns
    -------
    CrosscheckResult
        Two ``crosscheck`` checks (coefficients within ``theta_rtol`` relative, rollouts
        within ``rollout_atol`` absolute); metrics ``theta_max_rel_dev`` and
        ``rollout_max_abs_dev``, the per-module deviations behind them.
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
    return CrosscheckResult(
        checks, {"theta_max_rel_dev": theta_dev, "rollout_max_abs_dev": rollout_dev}
    )
