"""Why the correction leaves a residual unchanged: the sentence Figs. 5 and 6 print and note.

The correction subtracts posterior-weighted state means (paper Eq. 25), so it can only remove
a residual's *mean* within a regime. In the DynamicsOff window e1 ≈ −0.2·x(t): whether that
window has a mean to remove depends on where the command's random step offsets put x(t),
which is a property of the draw, not of the correction (our correction on R's signals
reproduces R's table, the crosscheck of ``results/correction/crosscheck.json``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

__all__ = ["WINDOW", "window_stats", "unchanged_cause"]

#: The regime whose window decides e1 and e4 (the plant scaled to 0.8 of the twin's).
WINDOW = "DynamicsOff"


def window_stats(residuals: pd.DataFrame, channels: list[str]) -> dict[str, dict[str, float]]:
    """Mean and RMS of each channel's residual before correction inside :data:`WINDOW`.

    Parameters
    ----------
    residuals : DataFrame
        ``regime`` and ``<e>_before`` per channel (physical units).
    channels : list of str
        Residual channels.

    Returns
    -------
    dict
        Channel → ``{"mean": …, "rms": …}`` (NaN when the window is absent).
    """
    inside = residuals[residuals["regime"] == WINDOW]
    out = {}
    for e in channels:
        values = inside[f"{e}_before"].to_numpy(dtype=float)
        out[e] = {
            "mean": float(values.mean()) if values.size else float("nan"),
            "rms": float(np.sqrt(np.mean(values**2))) if values.size else float("nan"),
        }
    return out


def unchanged_cause(
    channel: str, drmse_pct: float, r_drmse_pct: float, stats: Mapping[str, float]
) -> str:
    """One line: the channel's reduction beside R's and its cause (the draw).

    Examples
    --------
    >>> unchanged_cause("e1", 0.03, 22.9, {"mean": -0.0006, "rms": 0.064})[:44]
    'e1: ΔRMSE 0.0 % (R 22.9 %). Cause: draw, Dyn'
    """
    return (
        f"{channel}: ΔRMSE {drmse_pct:.1f} % (R {r_drmse_pct:.1f} %). Cause: draw, "
        f"{WINDOW} mean {stats['mean']:.2g} vs RMS {stats['rms']:.2g}, nothing for a "
        "state-mean correction to remove"
    )
