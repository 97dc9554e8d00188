"""A plain output-error fit of the plant: the reference a calibrated twin must not lose to.

Specification: docs/gap.md §Calibration from data.

A system-identification engineer's first model of a plant rig is a discrete output-error model
``OE(nb = 3, nf = 2)`` with the input delay known: ``x[k] = B(q)/F(q)·u[k − d] + const`` with
``B(q) = b₀ + b₁q⁻¹ + b₂q⁻²`` (the same-sample term included) and ``F(q) = 1 + f₁q⁻¹ + f₂q⁻²``,
fitted by least squares on the simulation error. :func:`output_error_reference` fits it on the
training part and predicts the whole recording **over the same windows, with the same warm-up
initial states** as the exact plant (:func:`dtwin.gap.models.plant_windows`), so its held-out
gap is measured exactly like the twin's. The twin's physical parameters are fewer (``m, c, k``,
an offset and a hold); if the reference does much better, the twin's structure, not the data,
is what limits it, and the report says so. :func:`plain_linear_error` is the same fit at a
higher order, the linear alternative an effect must beat in the nested test (docs/gap.md
§Where).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from dtwin.gap.models import ModuleData, plant_windows, warmup_samples

__all__ = ["output_error_reference", "plain_linear_error", "REFERENCE_ORDER"]

#: ``(nb, nf, first)`` of the reference: OE(3, 2) with the same-sample term.
REFERENCE_ORDER = (3, 2, 0)


def _delayed(u: np.ndarray, delay: int) -> np.ndarray:
    return np.concatenate([np.full(delay, u[0]), u[: len(u) - delay]]) if delay else u


def _simulate(theta, u, y, windows, warmup, order=REFERENCE_ORDER, profile=False) -> np.ndarray:
    """Windows of the OE model, each from a least-squares initial state.

    ``order = (nb, nf, first)``: ``B(q) = q^−first·(b₀ + … + b_{nb−1}q^{1−nb})``, ``F`` of degree
    ``nf``. Each window's ``nf`` initial outputs are fitted to its warm-up (the warm-up then
    NaN, not scored) or, with ``profile``, to the whole window (every sample predicted).
    """
    nb, nf, first = order
    b = np.concatenate([np.zeros(first), theta[:nb]])
    f, const = np.r_[1.0, theta[nb : nb + nf]], theta[nb + nf]
    # row i: the input through 1/F whose output starts y_j = δ_ij, j < nf
    seeds = lfilter(f, [1.0], np.eye(nf), axis=1)
    out = np.full(len(u), np.nan)
    by_length: dict[int, list[int]] = {}
    for start, stop in windows:
        by_length.setdefault(stop - start, []).append(start)
    for length, starts in by_length.items():
        rows = np.asarray(starts)[:, None] + np.arange(length)
        forced = lfilter(b, f, u[rows], axis=1) + lfilter([const], f, np.ones(length))
        pad = np.zeros((nf, max(length, nf)))
        pad[:, :nf] = seeds
        basis = lfilter([1.0], f, pad, axis=1)[:, :length].T  # (length, nf)
        fitted = length if profile else warmup
        if not np.all(np.isfinite(basis[:fitted])):  # a trial F unstable enough to overflow
            continue  # its windows stay NaN (the fit's residual clips them)
        solve = np.linalg.pinv(basis[:fitted])
        states = (y[rows[:, :fitted]] - forced[:, :fitted]) @ solve.T
        prediction = forced + states @ basis.T
        if not profile:
            prediction[:, :warmup] = np.nan
        out[rows] = prediction
    return out


def _arx_start(u: np.ndarray, y: np.ndarray, order=REFERENCE_ORDER) -> np.ndarray:
    nb, nf, first = order
    rows = np.arange(max(nb - 1 + first, nf), len(y))
    phi = [u[rows - first - j] for j in range(nb)] + [-y[rows - j] for j in range(1, nf + 1)]
    phi = np.column_stack([*phi, np.ones(len(rows))])
    coef, *_ = np.linalg.lstsq(phi, y[rows], rcond=None)
    return coef


def _fit(data: ModuleData, delay: int, n_train: int, order) -> tuple:
    """Return ``(theta, u, y, windows, warmup)``: OE of ``order`` fitted on the training windows."""
    u = _delayed(np.asarray(data.inputs["u_act"], dtype=float), int(delay))
    y = np.asarray(data.output, dtype=float)
    horizon = data.horizon or len(y)
    warmup = warmup_samples(horizon)
    windows = [w for w in plant_windows(len(y), horizon, data.restarts) if w[1] - w[0] > warmup]
    train = [w for w in windows if w[1] <= n_train]
    scale = float(np.std(y[:n_train])) or 1.0
    scored = np.zeros(len(y), dtype=bool)  # the same samples at every trial
    for start, stop in train:
        scored[start + warmup : stop] = True

    def residual(theta):
        with np.errstate(all="ignore"):  # an unstable trial denominator: errors clipped
            predicted = _simulate(theta, u, y, train, warmup, order)
            error = (predicted - y)[scored] / scale
        return np.clip(np.nan_to_num(error, nan=1e6, posinf=1e6, neginf=-1e6), -1e6, 1e6)

    start = _arx_start(u[:n_train], y[:n_train], order)
    fitted = least_squares(residual, start, method="trf", max_nfev=200, x_scale="jac")
    return fitted.x, u, y, windows, warmup


def output_error_reference(data: ModuleData, delay: int, n_train: int) -> np.ndarray:
    """Return the plain OE(3, 2) fit's prediction of the plant output, shape ``(n_samples,)``.

    Parameters
    ----------
    data : ModuleData
        The plant's recorded signals, with the exact plant's ``horizon`` and ``restarts``.
    delay : int
        Whole-sample input delay (the calibrated twin's).
    n_train : int
        Training samples; the fit sees only them.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)
        NaN on the warm-up samples of each window (not scored), like the twin's prediction.
    """
    theta, u, y, windows, warmup = _fit(data, delay, n_train, REFERENCE_ORDER)
    with np.errstate(all="ignore"):
        return _simulate(theta, u, y, windows, warmup)


def plain_linear_error(data: ModuleData, delay: int, n_train: int, order: int, first: int):
    """Return a higher-order plain OE model's error, each window's state fitted to it, ``(n,)``.

    ``OE(order, order)`` (``order`` taps of ``B`` from lag ``first`` on, ``F`` of degree
    ``order``, an offset) fitted on the training part like :func:`output_error_reference`, then
    run over every window with its ``order`` initial outputs fitted to the **whole** window
    (as :func:`~dtwin.gap.models.profiled_window_error` does for the twin): ``recorded −
    predicted``, NaN outside the windows and on windows whose fitted ``F`` overflows. The
    nested test's linear alternative (docs/gap.md §Where).
    """
    theta, u, y, windows, _ = _fit(data, delay, n_train, (order, order, first))
    with np.errstate(all="ignore"):
        return y - _simulate(theta, u, y, windows, 0, (order, order, first), profile=True)
