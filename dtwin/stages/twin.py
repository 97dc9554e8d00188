"""Stage "twin" (paper §3, §4.1; Figs. 1–3): simulate, fit ARX surrogates, residuals, figures.

Figures of this stage live in :mod:`dtwin.figures.fig01_pipeline`,
:mod:`dtwin.figures.fig02_arx_vs_physics` and :mod:`dtwin.figures.fig03_residual_acf`. Config
sections (``config/config.yaml``): ``simulation``, ``command``, ``twin``, ``arx``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.command import make_command, n_steps_for
from dtwin.config_sections import ArxSettings, SimulationSettings
from dtwin.params import TwinParams, command_params_from_mapping, twin_params_from_mapping
from dtwin.physics import simulate_physics
from dtwin.surrogate import (
    compute_residuals,
    fit_surrogates,
    fits_from_theta_table,
    run_surrogate_chain,
    theta_table,
)

__all__ = [
    "simulate_asset",
    "fit_twin_surrogates",
    "roll_out_twin",
]


def simulate_asset(
    simulation: SimulationSettings | Mapping[str, Any],
    command: Mapping[str, Any],
    twin: TwinParams | Mapping[str, Any],
) -> pd.DataFrame:
    """Simulate the physical asset with one generator seeded from ``simulation.seed``.

    Returns the physics table of :func:`dtwin.physics.simulate_physics` (``t`` and signals).
    ``simulation`` and ``twin`` are parsed here unless they come parsed.
    """
    simulation = SimulationSettings.from_mapping(simulation)
    twin_params = twin_params_from_mapping(twin)
    n_steps = n_steps_for(simulation.T, twin_params.dt)
    rng = np.random.default_rng(simulation.seed)
    u_cmd = make_command(n_steps, twin_params.dt, command_params_from_mapping(command), rng)
    return simulate_physics(twin_params, u_cmd, rng)


def fit_twin_surrogates(
    physics: pd.DataFrame, arx: ArxSettings | Mapping[str, Any]
) -> pd.DataFrame:
    """Fit the ARX surrogates on the training window; return the coefficient table."""
    arx = ArxSettings.from_mapping(arx)
    fits = fit_surrogates(physics, arx.orders, arx.train_frac)
    return theta_table(fits)


def roll_out_twin(
    physics: pd.DataFrame,
    theta: pd.DataFrame,
    twin: TwinParams | Mapping[str, Any],
    rollout_init: str,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Roll the surrogate chain out; return ``(surrogate, residuals)`` tables."""
    surrogate = run_surrogate_chain(
        physics, fits_from_theta_table(theta), twin_params_from_mapping(twin), rollout_init
    )
    return surrogate, compute_residuals(surrogate, physics)
