"""Paper Fig. 2: physics (truth) vs ARX surrogate output of each module."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from dtwin.artifacts import Check, FigureArtifact, validity_finite
from dtwin.figures._style import PHYSICS_COLOR, SURROGATE_COLOR, apply_style
from dtwin.reference.crosscheck_result import CrosscheckResult
from dtwin.wiring import MODULES, RESIDUALS, Module

__all__ = ["fig02_arx_vs_physics", "plot_arx_vs_physics", "RMSE_RATIO", "rmse_like_r"]

#: "General agreement with noticeable discrepancies": every module's held-out RMSE within this
#: factor of R's (r_numbers.yaml nominal_rmse_test_half), i.e. discrepancies of R's size.
RMSE_RATIO = 1.5


def rmse_like_r(rmse: dict[str, float], r_rmse: dict[str, float]) -> bool:
    """Return True when every residual's RMSE is within a factor :data:`RMSE_RATIO` of R's."""
    return all(1 / RMSE_RATIO <= rmse[e] / r_rmse[e] <= RMSE_RATIO for e in r_rmse)


def plot_arx_vs_physics(
    physics: pd.DataFrame, surrogate: pd.DataFrame, modules: Sequence[Module], t_train_end: float
) -> Figure:
    """Draw one panel per module: physics output (solid) and surrogate output (dashed).

    Parameters
    ----------
    physics, surrogate : DataFrame
        Columns ``t`` (s) and the pipeline signals.
    modules : sequence of Module
        Panels, in order (the wiring table).
    t_train_end : float
        End of the ARX training window, s (shaded).
    """
    apply_style()
    n_rows = (len(modules) + 1) // 2
    figure, axes = plt.subplots(n_rows, 2, figsize=(11, 2.6 * n_rows), sharex=True)
    t = physics["t"].to_numpy()
    for ax, module in zip(axes.ravel(), modules, strict=False):
        signal = module.output
        ax.axvspan(t[0], t_train_end, color="#eeeeee", zorder=0, label="ARX training window")
        ax.plot(t, physics[signal], color=PHYSICS_COLOR, lw=1.4, label="physics (truth)")
        ax.plot(t, surrogate[signal], color=SURROGATE_COLOR, lw=1.4, ls="--", label="ARX twin")
        ax.set_title(f"{module.name}: {module.title} — {signal}")
        ax.set_ylabel(signal)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="upper center", ncol=3, bbox_to_anchor=(0.5, 1.0))
    figure.suptitle("Physics vs ARX surrogate across modules (paper Fig. 2)", y=1.03)
    figure.tight_layout()
    return figure


def _rmse(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def fig02_arx_vs_physics(
    physics: pd.DataFrame,
    surrogate: pd.DataFrame,
    residuals: pd.DataFrame,
    theta: pd.DataFrame,
    arx: Mapping[str, Any],
    crosscheck: CrosscheckResult,
    r_numbers: Mapping[str, Any],
) -> FigureArtifact:
    """Paper Fig. 2 with its RMSE metrics and the ARX crosschecks against R.

    Parameters
    ----------
    physics, surrogate, residuals : DataFrame
        ``results/physics.csv``, ``results/surrogate.csv``, ``results/residuals.csv``.
    theta : DataFrame
        ``results/arx_theta.csv`` (its ``n_train`` is the training window, samples).
    arx : mapping
        The ``arx`` config section (``rollout_init`` is reported).
    crosscheck : CrosscheckResult
        ``results/arx_crosscheck.json`` (our ARX fit and rollout on R's signals).
    r_numbers : mapping
        ``config/reference/r_numbers.yaml`` (R's RMSEs).
    """
    n_train = int(theta["n_train"].iloc[0])
    t_train_end = float(physics["t"].iloc[n_train - 1])
    figure = plot_arx_vs_physics(physics, surrogate, MODULES, t_train_end)
    rmse_all = {e: _rmse(residuals[e].to_numpy()) for e in RESIDUALS}
    rmse_test = {e: _rmse(residuals[e].to_numpy()[n_train:]) for e in RESIDUALS}
    r_rmse_test = {e: float(r_numbers["nominal_rmse_test_half"][e]) for e in RESIDUALS}
    correlation = {
        m.name: float(np.corrcoef(physics[m.output], surrogate[m.output])[0, 1]) for m in MODULES
    }
    checks = [
        validity_finite("surrogate_finite", "surrogate signals", surrogate.drop(columns="t")),
        validity_finite("residuals_finite", "residuals", residuals.drop(columns="t")),
        Check(
            id="general_agreement",
            kind="claim",
            statement=(
                "paper §4.1: physics and ARX curves show general agreement with some noticeable "
                "discrepancies (read here as: every module's held-out RMSE, samples after the "
                f"training window, within a factor {RMSE_RATIO:g} of R's; was correlation >= 0.9)"
            ),
            expected=f"RMSE / R's RMSE in [{1 / RMSE_RATIO:.3f}, {RMSE_RATIO:g}] per residual",
            observed={e: round(rmse_test[e] / r_rmse_test[e], 3) for e in RESIDUALS},
            passed=rmse_like_r(rmse_test, r_rmse_test),
            reference=r_rmse_test,
        ),
        *crosscheck.checks,
    ]
    metrics = {
        "n_steps": len(physics),
        "n_train": n_train,
        "rollout_init": arx["rollout_init"],
        "rmse_all_samples": rmse_all,
        "rmse_test_half": rmse_test,
        "r_rmse_all_samples_zero_seed": dict(r_numbers["nominal_rmse_zeroseed"]),
        "r_rmse_test_half": dict(r_numbers["nominal_rmse_test_half"]),
        "correlation_physics_twin": correlation,
        "crosscheck_deviations": crosscheck.metrics,
    }
    return FigureArtifact("fig02_arx_vs_physics", figure, metrics, checks)
