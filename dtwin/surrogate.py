"""The digital twin: ARX surrogates wired as the physical chain, and module residuals.

Paper §3.2 and §2 Eq. (1); r_notes.md §2–3. The wiring comes from
:data:`dtwin.twin.wiring.MODULES`: each ARX module is fitted on the *physics* input/output pair of
the training window and rolled out from its *surrogate* input (M0 from the true command, M1
from the M0 surrogate, both sensors from the M1 surrogate); M3 and M4 are recomputed
algebraically from surrogate signals, the KPI with the backward-difference velocity.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError, require_in_range
from dtwin.arx import ARX_MODULES, ROLLOUT_INITS, ArxFit, ArxOrders, fit_arx, simulate_arx
from dtwin.params import TwinParams
from dtwin.physics import PHYSICS_STEPS, backward_velocity
from dtwin.twin.wiring import MODULES, RESIDUALS, SIGNALS

__all__ = [
    "n_train_samples",
    "fit_surrogates",
    "run_surrogate_chain",
    "compute_residuals",
    "theta_table",
    "fits_from_theta_table",
]


def n_train_samples(n_steps: int, train_frac: float) -> int:
    """Return the training-window length ``int(train_frac·n_steps)`` (R: ``as.integer``)."""
    train_frac = require_in_range("arx.train_frac", train_frac, 0.0, 1.0)
    return int(train_frac * n_steps)


def fit_surrogates(
    physics: pd.DataFrame, orders: Mapping[str, ArxOrders], train_frac: float
) -> dict[str, ArxFit]:
    """Fit one ARX model per ARX module on the physics signals of the training window.

    Parameters
    ----------
    physics : DataFrame
        Output of :func:`dtwin.physics.simulate_physics` (columns :data:`SIGNALS`).
    orders : mapping of module name to ArxOrders
        Must cover :data:`ARX_MODULES`.
    train_frac : float
        Fraction of samples, from the start, used for fitting (paper: 0.5).

    Returns
    -------
    dict of module name to ArxFit
    """
    missing = [name for name in ARX_MODULES if name not in orders]
    if missing:
        raise DtwinValueError(f"arx.orders is missing module(s): {', '.join(missing)}")
    n_train = n_train_samples(len(physics), train_frac)
    window = physics.iloc[:n_train]
    fits = {}
    for module in MODULES:
        if module.surrogate != "arx":
            continue
        fits[module.name] = fit_arx(
            window[module.output].to_numpy(),
            window[module.inputs[0]].to_numpy(),
            orders[module.name],
        )
    return fits


def run_surrogate_chain(
    physics: pd.DataFrame,
    fits: Mapping[str, ArxFit],
    twin: TwinParams,
    rollout_init: str = "physics",
) -> pd.DataFrame:
    """Roll the surrogate chain out over the whole horizon.

    Parameters
    ----------
    physics : DataFrame
        Physics signals (the command ``u_cmd`` drives M0; first samples seed the rollouts).
    fits : mapping of module name to ArxFit
        From :func:`fit_surrogates`.
    twin : TwinParams
        For the algebraic modules (fusion weight, KPI weights) and ``dt``.
    rollout_init : {"physics", "zeros"}
        Initial rollout values: the first ``na`` physics samples, or zeros.

    Returns
    -------
    DataFrame
        Columns ``t`` and :data:`SIGNALS`; ``u_cmd`` is the true command and ``v`` the
        backward-difference velocity of the surrogate position.
    """
    if rollout_init not in ROLLOUT_INITS:
        raise DtwinValueError(
            f"arx.rollout_init must be one of {', '.join(ROLLOUT_INITS)} (got {rollout_init!r})"
        )
    signals = {"u_cmd": physics["u_cmd"].to_numpy()}
    for module in MODULES:
        if module.surrogate == "arx":
            fit = fits[module.name]
            if rollout_init == "physics":
                initial = physics[module.output].to_numpy()[: fit.orders.na]
            else:
                initial = np.zeros(fit.orders.na)
            output = simulate_arx(fit, signals[module.inputs[0]], initial)
            signals[module.output] = output
            if "v" in module.outputs:
                signals["v"] = backward_velocity(output, twin.dt)
        else:
            signals.update(PHYSICS_STEPS[module.name](signals, twin, None))
    table = pd.DataFrame({"t": physics["t"].to_numpy()})
    for name in SIGNALS:
        table[name] = signals[name]
    return table


def compute_residuals(surrogate: pd.DataFrame, physics: pd.DataFrame) -> pd.DataFrame:
    """Return the module residuals ``e = surrogate − physics`` (paper Eq. (1)).

    Returns
    -------
    DataFrame
        Columns ``t`` and :data:`RESIDUALS` (``e0, e1, e2a, e2b, e3, e4``), one row per sample.
    """
    if len(surrogate) != len(physics):
        raise DtwinValueError(
            "surrogate and physics must have the same length "
            f"(got {len(surrogate)} and {len(physics)})"
        )
    table = pd.DataFrame({"t": physics["t"].to_numpy()})
    for module in MODULES:
        table[module.residual] = (
            surrogate[module.output].to_numpy() - physics[module.output].to_numpy()
        )
    return table[["t", *RESIDUALS]]


def theta_table(fits: Mapping[str, ArxFit]) -> pd.DataFrame:
    """Return the fitted coefficients as a long table.

    Columns: ``module``, ``na``, ``nb``, ``d``, ``n_train``, ``coef`` (``a1``…, ``b1``…) and
    ``value``.
    """
    rows = []
    for name, fit in fits.items():
        labels = [f"a{i}" for i in range(1, fit.orders.na + 1)]
        labels += [f"b{j}" for j in range(1, fit.orders.nb + 1)]
        for label, value in zip(labels, fit.theta, strict=True):
            rows.append(
                {
                    "module": name,
                    "na": fit.orders.na,
                    "nb": fit.orders.nb,
                    "d": fit.orders.d,
                    "n_train": fit.n_train,
                    "coef": label,
                    "value": float(value),
                }
            )
    return pd.DataFrame(rows)


def fits_from_theta_table(table: pd.DataFrame) -> dict[str, ArxFit]:
    """Rebuild the fits written by :func:`theta_table` (the inverse of that function)."""
    required = {"module", "na", "nb", "d", "n_train", "coef", "value"}
    missing = sorted(required - set(table.columns))
    if missing:
        raise DtwinValueError(f"ARX coefficient table is missing column(s): {', '.join(missing)}")
    fits = {}
    for name, rows in table.groupby("module", sort=False):
        first = rows.iloc[0]
        orders = ArxOrders(int(first["na"]), int(first["nb"]), int(first["d"]))
        theta = rows["value"].to_numpy(dtype=float)
        if len(theta) != orders.na + orders.nb:
            raise DtwinValueError(
                f"module {name}: {len(theta)} coefficients for na={orders.na}, nb={orders.nb}"
            )
        fits[str(name)] = ArxFit(orders=orders, theta=theta, n_train=int(first["n_train"]))
    return fits
