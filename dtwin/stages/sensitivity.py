"""Stage "sensitivity" (paper §5, Fig. 11): run one configuration and replicate of the sweep.

The sweep itself — grid, seeds, result records and their aggregation — is
:mod:`dtwin.sensitivity_sweep` (numpy and pandas only, so the aggregate rule does not import
hmmlearn); this module runs one point: simulate (or rebuild R's signals), refit the ARX
surrogates, the HMM and both plant corrections. Config sections: ``simulation``, ``command``,
``twin``, ``arx``, ``sensitivity``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import (
    require_in_range,
    require_nonnegative,
)
from dtwin.bias_correction import correct_bias, correct_plant_bias_viterbi
from dtwin.config_sections import ArxSettings, SimulationSettings, SweepPointSettings
from dtwin.hmm import fit_hmm, zscore
from dtwin.params import TwinParams, twin_params_from_mapping
from dtwin.physics import fuse, sensor_first_order
from dtwin.sensitivity_sweep import (
    CorrectionScore,
    SweepPoint,
    SweepRun,
    replicate_seed,
    scale_twin,
)
from dtwin.stages.twin import fit_twin_surrogates, roll_out_twin, simulate_asset
from dtwin.twin.wiring import RESIDUALS

__all__ = ["r_sweep_physics", "sweep_point", "sweep_point_on_r_signals"]


def r_sweep_physics(
    r_physics: pd.DataFrame,
    twin: TwinParams | Mapping[str, Any],
    alpha: float,
    m_A: float,
    m_B: float,
) -> pd.DataFrame:
    """Return R's physics for one configuration of its sweep, rebuilt from R's seed-11 run.

    Parameters
    ----------
    r_physics : DataFrame
        R's nominal seed-11 physics (α 0.6, unit multipliers), columns ``t`` and
        ``u_cmd, u_act, x, v, y_A, y_B, y_fused, z``
        (:func:`dtwin.reference.loaders.load_r_physics`).
    twin : TwinParams or mapping
        The ``twin`` config section (sensor time constants and biases, ``dt``).
    alpha, m_A, m_B : float
        The configuration.

    Returns
    -------
    DataFrame
        Same columns; ``y_A``, ``y_B`` carry the measurement noise times ``m_A``, ``m_B`` and
        ``y_fused`` is recomputed with α.

    Notes
    -----
    R draws the same standard normals for every configuration (``set.seed(11)`` each time)
    and scales them by the noise sd (r_notes.md §9), so a sensor reading is
    ``ỹ + b + m·σ·ε`` with ``ỹ`` the noise-free first-order response to the physics position.
    ``σ·ε = y − ỹ − b`` is recovered from the nominal run and rescaled. Actuator, plant and KPI
    signals do not depend on the configuration.
    """
    params = twin_params_from_mapping(twin)
    x = r_physics["x"].to_numpy(dtype=float)
    out = r_physics.copy()
    for which, mult in (("A", m_A), ("B", m_B)):
        sensor = getattr(params, f"sensor_{which}")
        clean = sensor_first_order(x, sensor.tau, params.dt, sensor.bias)
        noise = r_physics[f"y_{which}"].to_numpy(dtype=float) - clean
        out[f"y_{which}"] = clean + require_nonnegative(f"m_{which}", mult) * noise
    out["y_fused"] = fuse(out["y_A"], out["y_B"], require_in_range("alpha", alpha, 0.0, 1.0))
    return out


def _score(method: str, residuals: np.ndarray, e1_after: np.ndarray) -> CorrectionScore:
    e1 = residuals[:, RESIDUALS.index("e1")]
    after = residuals.copy()
    after[:, RESIDUALS.index("e1")] = e1_after
    return CorrectionScore(
        method=method,
        rmse_e1_before=float(np.sqrt(np.mean(e1**2))),
        rmse_e1_after=float(np.sqrt(np.mean(e1_after**2))),
        mae_e1_before=float(np.mean(np.abs(e1))),
        mae_e1_after=float(np.mean(np.abs(e1_after))),
        l2_before=float(np.mean(np.linalg.norm(residuals, axis=1))),
        l2_after=float(np.mean(np.linalg.norm(after, axis=1))),
    )


def _evaluate(
    physics: pd.DataFrame,
    point: SweepPoint,
    source: str,
    physics_seed: int | None,
    hmm_seed: int,
    twin: TwinParams,
    arx: ArxSettings | Mapping[str, Any],
    sweep: SweepPointSettings,
) -> SweepRun:
    """Refit the surrogates and the HMM on ``physics`` and score both corrections."""
    arx = ArxSettings.from_mapping(arx)
    surrogate, residual_table = roll_out_twin(
        physics, fit_twin_surrogates(physics, arx), twin, arx.rollout_init
    )
    residuals = residual_table[list(RESIDUALS)].to_numpy()
    hmm = sweep.hmm
    fit = fit_hmm(zscore(residuals).values, hmm.n_states, seed=hmm_seed, **hmm.fit_options())
    plant = correct_plant_bias_viterbi(
        surrogate["x"], physics["x"], fit.smoothed, fit.viterbi, **sweep.code.options()
    )
    weighted = correct_bias(
        surrogate,
        physics,
        fit.smoothed,
        alpha=twin.fusion.alpha,
        w1=twin.kpi.w1,
        w2=twin.kpi.w2,
        dt=twin.dt,
        **sweep.paper.options(),
    )
    usable = ~fit.restarts["status"].isin(["failed", "degenerate"])
    return SweepRun(
        point=point,
        source=source,
        physics_seed=physics_seed,
        hmm_seed=hmm_seed,
        n_steps=len(physics),
        log_likelihood=fit.log_likelihood,
        n_iter=fit.n_iter,
        converged=fit.converged,
        n_usable_starts=int(usable.sum()),
        scores=(
            _score("code", residuals, plant.e1_after),
            _score("paper", residuals, weighted.residuals_after["e1"].to_numpy()),
        ),
    )


def sweep_point(
    point: SweepPoint,
    *,
    simulation: SimulationSettings | Mapping[str, Any],
    command: Mapping[str, Any],
    twin: TwinParams | Mapping[str, Any],
    arx: Mapping[str, Any],
    sensitivity: SweepPointSettings | Mapping[str, Any],
) -> SweepRun:
    """Run one configuration and replicate of the sweep on our own simulation.

    Parameters
    ----------
    point : SweepPoint
    simulation, command, twin, arx : mapping
        The config sections of the same names (the twin's fusion weight and sensor noise are
        overridden by the point, :func:`scale_twin`).
    sensitivity : SweepPointSettings or mapping
        The ``sensitivity`` section's ``seed`` (EM seed of replicate 0), ``hmm`` and
        ``correction`` (``code`` and ``paper``): :class:`dtwin.config_sections.SweepPointSettings`.

    Returns
    -------
    SweepRun
        ``source = "ours"``; physics seed ``replicate_seed(simulation.seed, r)`` and EM seed
        ``replicate_seed(sensitivity.seed, r)``.

    Notes
    -----
    Per point: simulate (:func:`dtwin.stages.twin.simulate_asset`), fit the ARX surrogates on
    the training window, roll the chain out, z-score ``e0 … e4``, fit the HMM (best of
    ``n_restarts`` EM starts) and score both corrections of ``e1`` (Eq. (27)).
    """
    sweep = SweepPointSettings.from_mapping(sensitivity)
    simulation = SimulationSettings.from_mapping(simulation)
    physics_seed = replicate_seed(simulation.seed, point.replicate)
    hmm_seed = replicate_seed(sweep.seed, point.replicate)
    scaled = scale_twin(twin, point.alpha, point.m_A, point.m_B)
    physics = simulate_asset(replace(simulation, seed=physics_seed), command, scaled)
    return _evaluate(physics, point, "ours", physics_seed, hmm_seed, scaled, arx, sweep)


def sweep_point_on_r_signals(
    point: SweepPoint,
    r_physics: pd.DataFrame,
    *,
    twin: TwinParams | Mapping[str, Any],
    arx: Mapping[str, Any],
    sensitivity: SweepPointSettings | Mapping[str, Any],
) -> SweepRun:
    """Run one configuration on R's own seed-11 signals (:func:`r_sweep_physics`).

    The inputs to the HMM are then exactly R's (the pre-correction RMSE, MAE and L2 match R's
    sweep table); only the EM starts differ. The EM seed is that of the replicate, so
    replicates on R's signals differ in the EM starts alone. Returns ``source =
    "r_signals"``, ``physics_seed = None``.
    """
    sweep = SweepPointSettings.from_mapping(sensitivity)
    hmm_seed = replicate_seed(sweep.seed, point.replicate)
    scaled = scale_twin(twin, point.alpha, point.m_A, point.m_B)
    physics = r_sweep_physics(r_physics, scaled, point.alpha, point.m_A, point.m_B)
    return _evaluate(physics, point, "r_signals", None, hmm_seed, scaled, arx, sweep)
