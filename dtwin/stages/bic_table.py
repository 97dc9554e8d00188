"""The BIC table of Fig. 9 (paper §5): the join of the per-data-set sweeps.

Kept apart from :mod:`dtwin.stages.regimes` so the job that only joins the two sweeps' tables
(rule ``bic_sweep``) imports pandas, not the EM engine.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

__all__ = ["bic_sweep"]


def bic_sweep(tables: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """Rule ``bic_sweep``: the per-data-set BIC tables as one (``results/bic_sweep.csv``).

    Each table is :func:`dtwin.stages.regimes.bic_sweep_dataset`'s.

    The rows keep the given order (the workflow passes the nominal residuals first).

    Examples
    --------
    >>> a, b = pd.DataFrame({"K": [2]}), pd.DataFrame({"K": [3]})
    >>> bic_sweep([a, b])["K"].tolist()
    [2, 3]
    """
    return pd.concat(list(tables), ignore_index=True)
