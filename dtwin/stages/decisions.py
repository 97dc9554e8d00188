"""Stage "decisions" (paper §5, Table 1; r_notes.md §8): MCDA/TOPSIS action timeline.

Config section ``mcda`` (weights, rolling window, gate, dwell, margin) plus ``twin.dt``.
Inputs are the fault scenario's faulted residuals and Hungarian-mapped regime posteriors.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from dtwin.mcda import McdaResult, McdaSettings, run_mcda

__all__ = ["mcda_settings_from_mapping", "select_mcda_actions"]


def mcda_settings_from_mapping(mcda: Mapping[str, Any], *, legacy_r: bool = False) -> McdaSettings:
    """Return :class:`McdaSettings` from the ``mcda`` config section."""
    return McdaSettings(
        weights=dict(mcda["weights"]),
        roll_sec=mcda["roll_sec"],
        gate_quantile=mcda["gate_quantile"],
        gate_p_nominal=mcda["gate_p_nominal"],
        min_dwell_sec=mcda["min_dwell_sec"],
        switch_margin=mcda["switch_margin"],
        legacy_r=legacy_r,
    )


def select_mcda_actions(
    residuals: pd.DataFrame, posteriors: pd.DataFrame, mcda: Mapping[str, Any], dt: float
) -> McdaResult:
    """Run the selection on the fault scenario; the timeline gains ``t`` and ``regime``."""
    result = run_mcda(residuals, posteriors, dt, mcda_settings_from_mapping(mcda))
    timeline = result.timeline
    timeline.insert(1, "t", residuals["t"].to_numpy())
    timeline.insert(2, "regime", residuals["regime"].to_numpy())
    return result
