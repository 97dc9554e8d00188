"""Stage "correction" (paper §4.3; Figs. 5, 6): the targeted intervention on the fault scenario.

What the authors' ``TargetedIntervention.R`` does (r_notes.md §7A): the faulted surrogate
streams are corrected with the posterior-weighted state bias of the fault-scenario HMM
(:func:`dtwin.bias_correction.correct_bias`), and the residuals before and after are compared. Two
variants are computed:

- ``smoothed``: the paper's correction, with ``γ_t = P(S_t | e_1:T)`` (it looks ahead);
- ``filtered``: the same state means ``μ_kj`` (learned offline from the smoothed fit), but the
  bias at t uses only ``P(S_t | e_1:t)``, which is what a live twin can do.

Figures of this stage live in :mod:`dtwin.figures.fig05_correction_timeseries` and
:mod:`dtwin.figures.fig06_correction_distributions`. Config sections: ``correction`` and the
``dt``/``fusion``/``kpi`` keys of ``twin``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.bias_correction import BiasCorrection, correct_bias
from dtwin.config_sections import CorrectionSettings
from dtwin.params import ALGEBRAIC_SECTIONS, TwinParams, twin_params_from_mapping
from dtwin.state_tables import posterior_matrix
from dtwin.twin.wiring import RESIDUALS

__all__ = [
    "VARIANTS",
    "correct_twin",
    "targeted_intervention",
]

#: Correction variants: which posteriors weight the state means.
VARIANTS: tuple[str, ...] = ("smoothed", "filtered")


def correct_twin(
    surrogate: pd.DataFrame,
    physics: pd.DataFrame,
    posteriors: np.ndarray,
    twin: TwinParams | Mapping[str, Any],
    correction: CorrectionSettings | Mapping[str, Any],
    state_means: np.ndarray | None = None,
) -> BiasCorrection:
    """:func:`dtwin.bias_correction.correct_bias` with the ``twin`` and ``correction`` sections.

    ``twin`` needs ``dt``, ``fusion`` and ``kpi``. Both sections are parsed here unless they
    come parsed (:class:`~dtwin.params.TwinParams`,
    :class:`~dtwin.config_sections.CorrectionSettings`).
    """
    twin = twin_params_from_mapping(twin, require_all=False, required=ALGEBRAIC_SECTIONS)
    correction = CorrectionSettings.from_mapping(correction)
    return correct_bias(
        surrogate,
        physics,
        posteriors,
        alpha=twin.fusion.alpha,
        w1=twin.kpi.w1,
        w2=twin.kpi.w2,
        dt=twin.dt,
        **correction.options(),
        state_means=state_means,
    )


def targeted_intervention(
    physics: pd.DataFrame,
    faulted: pd.DataFrame,
    states: pd.DataFrame,
    twin: TwinParams | Mapping[str, Any],
    correction: CorrectionSettings | Mapping[str, Any],
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Correct the faulted twin with smoothed and with filtered posteriors (paper §4.3).

    Parameters
    ----------
    physics : DataFrame
        Physics signals (``t``, ``u_act``, ``x``, ``y_A``, ``y_B``, ``y_fused``, ``z``).
    faulted : DataFrame
        Faulted surrogate streams of the fault scenario (``t``, ``regime``, ``u_act``, ``x``,
        ``y_A``, ``y_B``).
    states : DataFrame
        The fault fit's states table (``gamma_S*`` smoothed, ``filtered_S*`` filtered).
    twin : TwinParams or mapping
        ``dt``, ``fusion``, ``kpi`` of the ``twin`` section.
    correction : CorrectionSettings or mapping
        The ``correction`` section: ``kappa``, ``ema_alpha``, ``rate_max``.

    Returns
    -------
    (residuals, metrics)
        ``residuals``: ``t``, ``regime``, then ``<e>_before``, ``<e>_smoothed`` and
        ``<e>_filtered`` for every residual channel ``e`` (physical units);
        ``metrics``: one row per variant and channel with the columns of
        :attr:`dtwin.bias_correction.BiasCorrection.metrics` (``variant`` first).
    """
    twin = twin_params_from_mapping(twin, require_all=False, required=ALGEBRAIC_SECTIONS)
    correction = CorrectionSettings.from_mapping(correction)
    smoothed = correct_twin(faulted, physics, posterior_matrix(states, "gamma"), twin, correction)
    filtered = correct_twin(
        faulted,
        physics,
        posterior_matrix(states, "filtered"),
        twin,
        correction,
        state_means=smoothed.state_means.to_numpy(),
    )
    residuals = pd.DataFrame({"t": faulted["t"].to_numpy(), "regime": faulted["regime"]})
    for e in RESIDUALS:
        residuals[f"{e}_before"] = smoothed.residuals_before[e].to_numpy()
        residuals[f"{e}_smoothed"] = smoothed.residuals_after[e].to_numpy()
        residuals[f"{e}_filtered"] = filtered.residuals_after[e].to_numpy()
    metrics = pd.concat(
        [
            result.metrics.assign(variant=variant)
            for variant, result in zip(VARIANTS, (smoothed, filtered), strict=True)
        ],
        ignore_index=True,
    )
    metrics = metrics[["variant", *(c for c in metrics.columns if c != "variant")]]
    return residuals, metrics
