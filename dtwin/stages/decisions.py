"""Stage "decisions" (paper §5, Table 1; r_notes.md §8): MCDA/TOPSIS action timeline.

Config section ``mcda`` (weights, rolling window, gate, dwell, margin) plus ``twin.dt``.
Inputs are the fault scenario's faulted residuals and Hungarian-mapped regime posteriors.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from dtwin.mcda import McdaResult, McdaSettings, run_mcda

__all__ = ["select_mcda_actions"]


def select_mcda_actions(
    residuals: pd.DataFrame,
    posteriors: pd.DataFrame,
    mcda: McdaSettings | Mapping[str, Any],
    dt: float,
) -> McdaResult:
    """Run the selection on the fault scenario; the timeline gains ``t`` and ``regime``."""
    result = run_mcda(residuals, posteriors, dt, McdaSettings.from_mapping(mcda))
    timeline = result.timeline
    timeline.insert(1, "t", residuals["t"].to_numpy())
    timeline.insert(2, "regime", residuals["regime"].to_numpy())
    return result
