"""The Ljung–Box statistic from an autocorrelation.

Shared by the paper's residual tests (:mod:`dtwin.residual_stats`) and the diagnoser's noise
floor (:mod:`dtwin.gap.noise`); each computes its own autocorrelation, the paper's over a whole
series, the diagnoser's over pairs inside the runs of a gapped one.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ljung_box_statistic"]


def ljung_box_statistic(acf: np.ndarray, n_samples: int) -> np.ndarray:
    """Return the Ljung–Box ``Q(h) = n (n + 2) Σ_{k=1..h} r_k² / (n − k)`` for ``h = 1 … H``.

    Parameters
    ----------
    acf : array, shape (H + 1,)
        An autocorrelation ``r_0 = 1, r_1 … r_H`` of ``n_samples`` values.
    n_samples : int
        The ``n`` of the formula.

    Returns
    -------
    numpy.ndarray, shape (H,)
        ``Q(1) … Q(H)``; under white noise ``Q(h)`` is χ² with ``h`` degrees of freedom, less
        one per fitted ARMA parameter.
    """
    n = n_samples
    return n * (n + 2) * np.cumsum(acf[1:] ** 2 / (n - np.arange(1, len(acf))))
