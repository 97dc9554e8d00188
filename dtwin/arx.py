"""ARX surrogates: least-squares fit and recursive rollout (paper §3.2, Eqs. (19)–(24)).

The model is ``y_t = Σ_{i=1..na} a_i·y_{t−i} + Σ_{j=1..nb} b_j·u_{t−d−j} + e_t`` with no
intercept (Eq. (22)). ``d`` is the paper's optional input delay: with ``d = 0`` the most recent
input in the regressor is ``u_{t−1}`` (the convention of the paper and of the authors' code,
which r_notes.md §2 calls "input delay 1").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dtwin._lfilter import lfilter, lfiltic
from dtwin._validation import (
    DtwinValueError,
    require_finite_array,
    require_min_length,
)
from dtwin.twin.wiring import MODULES

__all__ = [
    "ARX_MODULES",
    "ROLLOUT_INITS",
    "ArxOrders",
    "ArxFit",
    "arx_regressors",
    "fit_arx",
    "simulate_arx",
]


#: Modules the twin replaces with an ARX model.
ARX_MODULES: tuple[str, ...] = tuple(m.name for m in MODULES if m.surrogate == "arx")

#: How rollouts start: ``"physics"`` (first physics samples, the authors' fault and
#: sensitivity scripts) or ``"zeros"`` (ARX_vs_Phys.R).
ROLLOUT_INITS: tuple[str, ...] = ("physics", "zeros")


@dataclass(frozen=True)
class ArxOrders:
    """Lag orders of one ARX model: ``na`` output lags, ``nb`` input lags, input delay ``d``."""

    na: int
    nb: int
    d: int = 0

    def __post_init__(self) -> None:
        for name in ("na", "nb", "d"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise DtwinValueError(f"arx order {name} must be an integer (got {value!r})")
        if self.na < 0 or self.nb < 1 or self.d < 0:
            raise DtwinValueError(
                "arx orders need na >= 0, nb >= 1, d >= 0 "
                f"(got na={self.na}, nb={self.nb}, d={self.d})"
            )

    @property
    def n_lags(self) -> int:
        """Samples of history a prediction needs: ``p = max(na, nb + d)``."""
        return max(self.na, self.nb + self.d)


@dataclass(frozen=True)
class ArxFit:
    """A fitted ARX model.

    Attributes
    ----------
    orders : ArxOrders
    theta : numpy.ndarray, shape (na + nb,)
        ``[a_1 … a_na, b_1 … b_nb]`` (Eq. (24)).
    n_train : int
        Number of samples the fit used.
    """

    orders: ArxOrders
    theta: np.ndarray
    n_train: int

    @property
    def a(self) -> np.ndarray:
        """Output coefficients ``a_1 … a_na``, shape ``(na,)``."""
        return self.theta[: self.orders.na]

    @property
    def b(self) -> np.ndarray:
        """Input coefficients ``b_1 … b_nb``, shape ``(nb,)``."""
        return self.theta[self.orders.na :]


def arx_regressors(
    y: np.ndarray, u: np.ndarray, orders: ArxOrders
) -> tuple[np.ndarray, np.ndarray]:
    """Return the stacked regressors Φ, shape ``(n − p, na + nb)``, and targets, shape ``(n − p,)``.

    Row ``t`` (for ``t = p … n−1``) is ``φ_t = [y_{t−1} … y_{t−na}, u_{t−d−1} … u_{t−d−nb}]``
    (Eq. (23)); ``p = max(na, nb + d)``.
    """
    p = orders.n_lags
    rows = np.arange(p, len(y))
    output_lags = [y[rows - i] for i in range(1, orders.na + 1)]
    input_lags = [u[rows - orders.d - j] for j in range(1, orders.nb + 1)]
    return np.column_stack(output_lags + input_lags), y[rows]


def fit_arx(y: np.ndarray, u: np.ndarray, orders: ArxOrders) -> ArxFit:
    """Fit an ARX model by least squares and return an :class:`ArxFit`.

    Parameters
    ----------
    y, u : array, shape (n,)
        Output and input of the training window (same units as the rollout will use).
    orders : ArxOrders

    Returns
    -------
    ArxFit

    Raises
    ------
    DtwinValueError
        If the series are too short, of unequal length, non-finite, or the regressors are
        rank-deficient (a constant input, for example).

    Notes
    -----
    Eq. (24): ``θ̂ = (ΦᵀΦ)⁻¹ΦᵀY``, solved from the normal equations exactly as written (the
    authors' R code does the same, which keeps the crosscheck to 1e-6 relative).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(200)
    >>> y = np.zeros(200)
    >>> for t in range(1, 200):
    ...     y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1]
    >>> np.round(fit_arx(y, u, ArxOrders(1, 1)).theta, 6).tolist()
    [0.9, 0.5]
    """
    y = require_finite_array("y", y)
    u = require_finite_array("u", u)
    if y.shape != u.shape:
        raise DtwinValueError(f"y and u must have the same length (got {len(y)} and {len(u)})")
    n_params = orders.na + orders.nb
    require_min_length("training window", y, orders.n_lags + n_params)
    phi, target = arx_regressors(y, u, orders)
    gram = phi.T @ phi
    if np.linalg.matrix_rank(phi) < n_params:
        raise DtwinValueError(
            f"ARX regressors are rank-deficient (rank {np.linalg.matrix_rank(phi)} < {n_params}); "
            "is the input constant over the training window?"
        )
    theta = np.linalg.solve(gram, phi.T @ target)
    return ArxFit(orders=orders, theta=theta, n_train=len(y))


def simulate_arx(fit: ArxFit, u: np.ndarray, initial_y: np.ndarray) -> np.ndarray:
    """Roll an ARX model out recursively over the whole input and return ``ŷ``, shape ``(n,)``.

    Parameters
    ----------
    fit : ArxFit
    u : array, shape (n,)
        Input over the full horizon.
    initial_y : array, shape (na,)
        ``ŷ_0 … ŷ_{na−1}``; samples ``na … p−1`` start at 0, as in the authors' code.

    Notes
    -----
    ``ŷ_t = Σ a_i·ŷ_{t−i} + Σ b_j·u_{t−d−j}`` for ``t = p … n−1``: the model's own past
    predictions feed back (a simulation, not a one-step prediction). Implemented as one linear
    filter with initial conditions (:func:`scipy.signal.lfilter`'s arithmetic, through
    :mod:`dtwin._lfilter`), exact to rounding.
    """
    u = require_finite_array("u", u)
    orders = fit.orders
    initial_y = require_finite_array("initial_y", np.atleast_1d(initial_y))
    if initial_y.shape != (orders.na,):
        raise DtwinValueError(f"initial_y must have shape ({orders.na},) (got {initial_y.shape})")
    p = orders.n_lags
    require_min_length("u", u, p + 1)
    y_hat = np.zeros(len(u))
    y_hat[: orders.na] = initial_y
    numerator = np.concatenate([np.zeros(orders.d + 1), fit.b])
    denominator = np.concatenate([[1.0], -fit.a])
    past_y = y_hat[p - 1 :: -1] if p > 0 else np.zeros(0)
    past_u = u[p - 1 :: -1]
    state = lfiltic(numerator, denominator, past_y, past_u)
    y_hat[p:], _ = lfilter(numerator, denominator, u[p:], zi=state)
    return y_hat
