"""The data and results of one EM start, shared by the compiled and the reference engines.

:mod:`dtwin._multistart` runs the starts, :mod:`dtwin._em_kernels` and
:mod:`dtwin._em_reference` (hmmlearn) are the engines; all three read these types, which import
nothing of dtwin's, so no engine module imports another in a circle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GAUSSIAN", "AR1", "EmError", "EmData", "EmRun"]

#: Emission families of :class:`EmData` (``kind`` of :mod:`dtwin._em_kernels`, equal there).
GAUSSIAN, AR1 = 0, 1


class EmError(Exception):
    """EM produced non-finite values, or a forward pass underflowed, for one start."""


@dataclass(frozen=True)
class EmData:
    """The training sequence as each engine reads it.

    Attributes
    ----------
    kind : int
        :data:`dtwin._em_kernels.GAUSSIAN` or :data:`dtwin._em_kernels.AR1`.
    kernel : ndarray, shape (T', C)
        Rows of the compiled kernels: ``(x, x²)`` (Gaussian) or ``(y, x, y², yx, x²)`` (AR(1)).
    reference : ndarray
        Rows of the hmmlearn models: ``X`` (Gaussian) or the AR design rows.
    """

    kind: int
    kernel: np.ndarray
    reference: np.ndarray


@dataclass(frozen=True)
class EmRun:
    """One finished EM start.

    Attributes
    ----------
    startprob, transmat : ndarray, shapes (K,), (K, K)
        π and A.
    emission : ndarray, shape (P, K, D)
        Emission parameters: (means, variances) or (intercepts, coefs, variances).
    history : ndarray, shape (n_iter + 1,)
        log p(X) of the parameters entering each iteration, then of the returned ones.
    stopped : bool
        The tolerance stopped EM (not the iteration cap).
    posteriors : ndarray, shape (T', K), or None
        Smoothed posteriors γ_t(k) under the returned parameters; :func:`fit_starts` keeps them
        only for its best start (a T′×K array per start: 32 MB at T′ = 1e6, K = 4).
    implementation : str
        ``scaling`` (scaled recursions) or ``log`` (log-space recursions, run when the scaled
        ones underflowed); compiled or hmmlearn's, by the engine.
    """

    startprob: np.ndarray
    transmat: np.ndarray
    emission: np.ndarray
    history: np.ndarray
    stopped: bool
    posteriors: np.ndarray | None
    implementation: str

    @property
    def occupancy(self) -> np.ndarray:
        """Expected occupancy ``Σ_t γ_t(k)`` per state, samples."""
        return self.posteriors.sum(axis=0)
