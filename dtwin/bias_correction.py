"""Posterior-weighted bias correction of the surrogate chain (paper §4.3 Eq. (25); §5 Eq. (27)).

The correction of the authors' ``TargetedIntervention.R`` (r_notes.md §7A):

1. state means of the raw, physical-unit residuals, ``μ_kj = Σ_t γ_t(k) e_j(t) / Σ_t γ_t(k)``;
2. the posterior-weighted bias ``b̂_j(t) = Σ_k γ_t(k) μ_kj`` (Eq. (25));
3. gain κ, then an exponential moving average, then a rate limiter;
4. the shaped bias is subtracted from the outputs of the ARX modules (``u_act``, ``x``,
   ``y_A``, ``y_B``); fusion and the KPI (backward-difference velocity) are recomputed from
   the corrected signals, so the biases of ``e3``/``e4`` are computed but not applied.

The posteriors may be smoothed (``P(S_t | e_1:T)``, the paper) or filtered
(``P(S_t | e_1:t)``, a causal correction). The variant of the sensitivity sweep
(``RobustnessAnalysis.R``, r_notes.md §7C) is :func:`correct_plant_bias_viterbi`.
Arrays are time-first, shape ``(T,)`` or ``(T, n_channels)``.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from dtwin._lfilter import lfilter
from dtwin._validation import (
    DtwinValueError,
    require_finite_array,
    require_in_range,
    require_nonnegative,
    require_number,
    require_positive,
)
from dtwin.physics import backward_velocity, fuse, kpi
from dtwin.twin.wiring import MODULES, RESIDUALS

__all__ = [
    "CORRECTED_SIGNALS",
    "exponential_moving_average",
    "rate_limit",
    "BiasShaping",
    "shaped_bias",
    "state_residual_means",
    "BiasCorrection",
    "correct_bias",
    "PlantBiasCorrection",
    "correct_plant_bias_viterbi",
]

#: Outputs of the ARX modules, from which the shaped bias is subtracted (u_act, x, y_A, y_B).
CORRECTED_SIGNALS: tuple[str, ...] = tuple(m.output for m in MODULES if m.surrogate == "arx")

_SIGNAL_OF = {m.residual: m.output for m in MODULES}
_OUTPUTS: tuple[str, ...] = tuple(m.output for m in MODULES)


def _continued(name: str, initial: Any, x: np.ndarray) -> np.ndarray:
    """Return ``initial`` as one row shaped like ``x[:1]`` (the output just before ``x[0]``)."""
    row = require_finite_array(name, initial, ndim=None)
    if row.size != int(np.prod(x.shape[1:], dtype=int)):
        raise DtwinValueError(f"{name} must hold one value per channel (got shape {row.shape})")
    return row.reshape(x[:1].shape)


def exponential_moving_average(x: Any, alpha: float, initial: Any = None) -> np.ndarray:
    """Return the EMA ``out[0] = x[0]``, ``out[i] = α·x[i] + (1−α)·out[i−1]`` along time.

    Parameters
    ----------
    x : array, shape (T,) or (T, n_channels)
    alpha : float
        Smoothing weight of the newest sample, in (0, 1].
    initial : array, shape () or (n_channels,), optional
        The output just before ``x[0]``, to continue a series cut into pieces:
        ``out[0] = α·x[0] + (1−α)·initial``, bit for bit the value of the uncut series.

    Returns
    -------
    ndarray, same shape as ``x``
        Every output lies between the running minimum and maximum of its channel.

    Examples
    --------
    >>> exponential_moving_average([0.0, 1.0, 1.0], 0.5).tolist()
    [0.0, 0.5, 0.75]
    >>> exponential_moving_average([1.0], 0.5, initial=0.5).tolist()
    [0.75]
    """
    alpha = require_in_range("ema_alpha", alpha, 0.0, 1.0)
    if alpha == 0.0:
        raise DtwinValueError("ema_alpha must be > 0 (got 0.0)")
    x = require_finite_array("x", x, ndim=None)
    if x.ndim not in (1, 2) or len(x) == 0:
        raise DtwinValueError(f"x must be (T,) or (T, n_channels) with T >= 1 (got {x.shape})")
    before = x[:1] if initial is None else _continued("initial", initial, x)
    zi = (1.0 - alpha) * before  # x[:1]: out[0] = α·x[0] + (1−α)·x[0] = x[0]
    out, _ = lfilter([alpha], [1.0, -(1.0 - alpha)], x, axis=0, zi=zi)
    return out


def rate_limit(x: Any, r_max: float, initial: Any = None) -> np.ndarray:
    """Return ``x`` with every step clamped to ``±r_max``.

    ``out[0] = x[0]``, ``out[i] = out[i−1] + clip(x[i] − out[i−1], −r_max, r_max)``.

    Parameters
    ----------
    x : array, shape (T,) or (T, n_channels)
    r_max : float
        Largest change per sample (signal units), ≥ 0.
    initial : array, shape () or (n_channels,), optional
        The output just before ``x[0]``, to continue a series cut into pieces: ``out[0]`` is
        then ``initial`` plus the clamped step, bit for bit the value of the uncut series.

    Returns
    -------
    ndarray, same shape as ``x``

    Examples
    --------
    >>> rate_limit([0.0, 1.0, 1.0, -1.0], 0.4).tolist()
    [0.0, 0.4, 0.8, 0.4]
    >>> rate_limit([1.0, 1.0], 0.4, initial=0.4).tolist()
    [0.8, 1.0]
    """
    r_max = require_nonnegative("rate_max", r_max)
    x = require_finite_array("x", x, ndim=None)
    if x.ndim not in (1, 2) or len(x) == 0:
        raise DtwinValueError(f"x must be (T,) or (T, n_channels) with T >= 1 (got {x.shape})")
    # One channel at a time in Python floats (the same IEEE operations as numpy's, without a
    # numpy call per sample): min(max(step, −r), r) is np.clip's value for finite steps.
    columns = x.reshape(len(x), -1)
    before = None if initial is None else _continued("initial", initial, x).ravel().tolist()
    out = np.empty_like(columns)
    for channel in range(columns.shape[1]):
        values = columns[:, channel].tolist()
        if before is not None:
            values = [before[channel], *values]
        limited = [values[0]]
        previous = values[0]
        for value in values[1:]:
            step = value - previous
            previous = previous + (-r_max if step < -r_max else (r_max if step > r_max else step))
            limited.append(previous)
        out[:, channel] = limited if before is None else limited[1:]
    return out.reshape(x.shape)


class BiasShaping(NamedTuple):
    """Result of :func:`shaped_bias`: the applied bias and the EMA it was limited from.

    Attributes
    ----------
    applied : ndarray, shape (T, n_channels)
        ``rate_limit(EMA(κ·b̂))``, signal units.
    smoothed : ndarray, shape (T, n_channels)
        ``EMA(κ·b̂)`` before the rate limiter.
    """

    applied: np.ndarray
    smoothed: np.ndarray


def shaped_bias(
    bias: Any,
    *,
    kappa: float,
    ema_alpha: float,
    rate_max: float,
    initial: tuple[Any, Any] | None = None,
) -> BiasShaping:
    """Shape the posterior-weighted bias: gain κ, then the EMA, then the rate limiter (§4.3).

    Parameters
    ----------
    bias : array, shape (T, n_channels)
        The bias ``b̂(t) = Σ_k γ_t(k) μ_k`` of Eq. (25), signal units.
    kappa, ema_alpha, rate_max : float
        Gain, EMA weight (:func:`exponential_moving_average`) and step bound per sample
        (:func:`rate_limit`, signal units).
    initial : (smoothed, applied), optional
        The last row of a previous call's ``smoothed`` and ``applied``, shape (n_channels,)
        each: the series continues across calls bit for bit (a live twin shapes each chunk of
        samples as it arrives).

    Returns
    -------
    BiasShaping

    Examples
    --------
    >>> bias = np.array([[0.0], [1.0], [1.0], [1.0]])
    >>> whole = shaped_bias(bias, kappa=1.0, ema_alpha=0.5, rate_max=0.3)
    >>> first = shaped_bias(bias[:2], kappa=1.0, ema_alpha=0.5, rate_max=0.3)
    >>> rest = shaped_bias(bias[2:], kappa=1.0, ema_alpha=0.5, rate_max=0.3,
    ...                    initial=(first.smoothed[-1], first.applied[-1]))
    >>> whole.applied.ravel().tolist(), rest.applied.ravel().tolist()
    ([0.0, 0.3, 0.6, 0.875], [0.6, 0.875])
    """
    smoothed_before, applied_before = (None, None) if initial is None else initial
    x = kappa * bias
    loop = None if initial is None or np.ndim(x) != 2 else _compiled_shaping()
    if loop is not None:  # a continued series of rows (a live stream's chunk)
        alpha = require_in_range("ema_alpha", ema_alpha, 0.0, 1.0)
        if alpha == 0.0:
            raise DtwinValueError("ema_alpha must be > 0 (got 0.0)")
        r_max = require_nonnegative("rate_max", rate_max)
        x = require_finite_array("x", x, ndim=2)
        if len(x) == 0:
            raise DtwinValueError(f"x must be (T, n_channels) with T >= 1 (got {x.shape})")
        smoothed, applied = np.empty_like(x), np.empty_like(x)
        loop(np.ascontiguousarray(x), alpha, r_max, _continued("initial", smoothed_before, x)[0],
             _continued("initial", applied_before, x)[0], smoothed, applied)  # fmt: skip
        return BiasShaping(applied, smoothed)
    smoothed = exponential_moving_average(x, ema_alpha, initial=smoothed_before)
    return BiasShaping(rate_limit(smoothed, rate_max, initial=applied_before), smoothed)


def _shaping_rows(x, alpha, r_max, smoothed_before, applied_before, smoothed, applied) -> None:
    """Write the EMA of ``x`` (T, C) and its rate-limited series, continued from the rows before.

    The arithmetic of :func:`exponential_moving_average` (scipy's ``lfilter`` recursion with
    ``b = [α]``, ``a = [1, −(1−α)]``: ``y = z + α·x``, ``z = x·0 − y·a₁``, from ``z = (1−α)·``
    the row before) and of :func:`rate_limit`, in the same order: the same bits. Compiled
    (:func:`_compiled_shaping`) it takes microseconds where those two take 0.1 ms a call.
    """
    a1 = -(1.0 - alpha)
    for j in range(x.shape[1]):
        z = (1.0 - alpha) * smoothed_before[j]
        previous = applied_before[j]
        for k in range(x.shape[0]):
            value = x[k, j]
            y = z + alpha * value
            z = value * 0.0 - y * a1
            smoothed[k, j] = y
            step = y - previous
            previous = previous + (-r_max if step < -r_max else (r_max if step > r_max else step))
            applied[k, j] = previous


_COMPILED_SHAPING: list = []


def _compiled_shaping():
    """Return :func:`_shaping_rows` compiled where numba is loaded already, else None.

    Importing numba costs more than the short series of the DAG's jobs take; the monitor has
    it loaded.
    """
    if "numba" not in sys.modules:
        return None
    if not _COMPILED_SHAPING:
        from dtwin._jit import njit

        _COMPILED_SHAPING.append(njit(cache=True)(_shaping_rows))
    return _COMPILED_SHAPING[0]


def _require_posteriors(posteriors: Any, n_steps: int) -> np.ndarray:
    gamma = require_finite_array("posteriors", posteriors, ndim=2)
    if len(gamma) != n_steps:
        raise DtwinValueError(f"posteriors must have {n_steps} rows (got {len(gamma)})")
    if gamma.min() < -1e-9 or gamma.max() > 1 + 1e-9:
        raise DtwinValueError(
            f"posteriors must lie in [0, 1] (got range [{gamma.min():.3g}, {gamma.max():.3g}])"
        )
    sums = gamma.sum(axis=1)
    worst = int(np.argmax(np.abs(sums - 1.0)))
    if abs(sums[worst] - 1.0) > 1e-6:
        raise DtwinValueError(
            f"posteriors rows must sum to 1 (got {sums[worst]:.9g} at row {worst})"
        )
    return gamma


def state_residual_means(residuals: Any, posteriors: Any) -> np.ndarray:
    """Return the posterior-weighted state means ``μ_kj = Σ_t γ_t(k) e_j(t) / Σ_t γ_t(k)``.

    Parameters
    ----------
    residuals : array, shape (T, n_channels)
        Residuals in physical units.
    posteriors : array, shape (T, K)
        State posteriors, rows summing to 1.

    Returns
    -------
    ndarray, shape (K, n_channels)
        A state with zero total weight gets mean 0 (it never contributes to Eq. (25)).
    """
    e = require_finite_array("residuals", residuals, ndim=2)
    gamma = _require_posteriors(posteriors, len(e))
    weight = gamma.sum(axis=0)
    means = gamma.T @ e
    np.divide(means, weight[:, None], out=means, where=weight[:, None] > 0)
    means[weight <= 0] = 0.0
    return means


def _metrics(before: np.ndarray, after: np.ndarray, channels: list[str]) -> pd.DataFrame:
    rmse_before = np.sqrt(np.mean(before**2, axis=0))
    rmse_after = np.sqrt(np.mean(after**2, axis=0))
    mae_before = np.mean(np.abs(before), axis=0)
    mae_after = np.mean(np.abs(after), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_rmse = 100.0 * (rmse_before - rmse_after) / rmse_before
        d_mae = 100.0 * (mae_before - mae_after) / mae_before
    return pd.DataFrame(
        {
            "channel": channels,
            "rmse_before": rmse_before,
            "rmse_after": rmse_after,
            "mae_before": mae_before,
            "mae_after": mae_after,
            "drmse_pct": d_rmse,
            "dmae_pct": d_mae,
        }
    )


def _signals(name: str, table: Any, columns: tuple[str, ...], n_steps: int | None) -> dict:
    missing = [c for c in columns if c not in table]
    if missing:
        raise DtwinValueError(f"{name} is missing column(s) {', '.join(missing)}")
    out = {c: require_finite_array(f"{name}.{c}", np.asarray(table[c])) for c in columns}
    lengths = {len(v) for v in out.values()}
    if len(lengths) != 1 or (n_steps is not None and lengths != {n_steps}):
        raise DtwinValueError(f"{name} columns must have equal length (got {sorted(lengths)})")
    return out


def _derived(signals: Mapping[str, np.ndarray], alpha, w1, w2, dt) -> dict[str, np.ndarray]:
    """Add the algebraic modules: fusion and the KPI with backward-difference velocity."""
    out = dict(signals)
    out["y_fused"] = fuse(signals["y_A"], signals["y_B"], alpha)
    out["z"] = kpi(signals["x"], backward_velocity(signals["x"], dt), w1, w2)
    return out


@dataclass(frozen=True)
class BiasCorrection:
    """Result of :func:`correct_bias`.

    Attributes
    ----------
    state_means : DataFrame
        μ_kj, one row per state, columns ``e0 … e4`` (physical units).
    bias : DataFrame
        The posterior-weighted bias b̂_j(t) of Eq. (25), columns ``e0 … e4``, before gain and
        shaping.
    applied : DataFrame
        The bias subtracted from each corrected signal (after κ, EMA, rate limiter),
        columns :data:`CORRECTED_SIGNALS`.
    corrected : DataFrame
        Corrected surrogate signals ``u_act, x, y_A, y_B, y_fused, z``.
    residuals_before, residuals_after : DataFrame
        Surrogate − physics, columns ``e0 … e4``, before and after the correction.
    metrics : DataFrame
        One row per residual channel: ``channel``, ``rmse_before``, ``rmse_after``,
        ``mae_before``, ``mae_after``, ``drmse_pct`` = 100·(before − after)/before,
        ``dmae_pct``.
    """

    state_means: pd.DataFrame
    bias: pd.DataFrame
    applied: pd.DataFrame
    corrected: pd.DataFrame
    residuals_before: pd.DataFrame
    residuals_after: pd.DataFrame
    metrics: pd.DataFrame


def correct_bias(
    surrogate: Any,
    physics: Any,
    posteriors: Any,
    *,
    alpha: float,
    w1: float,
    w2: float,
    dt: float,
    kappa: float = 0.8,
    ema_alpha: float = 0.15,
    rate_max: float = 0.05,
    state_means: Any = None,
) -> BiasCorrection:
    """Correct the surrogate chain with the posterior-weighted state bias (Eq. (25)).

    Parameters
    ----------
    surrogate : DataFrame or mapping of arrays
        Surrogate signals (faulted, if faults were injected) with columns ``u_act``, ``x``,
        ``y_A``, ``y_B``, each shape (T,); ``y_fused`` and ``z`` are recomputed from them.
    physics : DataFrame or mapping of arrays
        Physics signals ``u_act, x, y_A, y_B, y_fused, z``, shape (T,) each.
    posteriors : array, shape (T, K)
        State posteriors γ_t(k) (smoothed, or filtered for a causal correction).
    alpha : float
        Fusion weight on sensor A.
    w1, w2 : float
        KPI weights.
    dt : float
        Sample period, s.
    kappa : float, default 0.8
        Gain on the bias.
    ema_alpha : float, default 0.15
        EMA weight (:func:`exponential_moving_average`), applied first.
    rate_max : float, default 0.05
        Rate-limiter step bound (:func:`rate_limit`), applied second, signal units/sample.
    state_means : array, shape (K, 6), optional
        μ_kj to use instead of estimating them from these residuals and posteriors (e.g.
        means from a calibration run, for a fully causal correction).

    Returns
    -------
    BiasCorrection

    Notes
    -----
    ``b̂_j(t) = Σ_k γ_t(k) μ_kj`` (Eq. (25)) with ``μ_kj`` the posterior-weighted mean of the
    raw residual ``e_j`` in state k over the whole series; the applied bias is
    ``rate_limit(EMA(κ·b̂))``; corrected = surrogate − applied for ``u_act, x, y_A, y_B``,
    then ``y_fused`` and ``z`` are recomputed. Residuals are corrected − physics.
    """
    kappa = require_number("correction.kappa", kappa)
    alpha = require_in_range("twin.fusion.alpha", alpha, 0.0, 1.0)
    w1 = require_number("twin.kpi.w1", w1)
    w2 = require_number("twin.kpi.w2", w2)
    dt = require_positive("twin.dt", dt)
    phys = _signals("physics", physics, _OUTPUTS, None)
    n_steps = len(phys["x"])
    surr = _signals("surrogate", surrogate, CORRECTED_SIGNALS, n_steps)
    gamma = _require_posteriors(posteriors, n_steps)

    before_signals = _derived(surr, alpha, w1, w2, dt)
    before = np.column_stack(
        [before_signals[_SIGNAL_OF[e]] - phys[_SIGNAL_OF[e]] for e in RESIDUALS]
    )
    if state_means is None:
        means = state_residual_means(before, gamma)
    else:
        means = require_finite_array("state_means", state_means, ndim=2)
        if means.shape != (gamma.shape[1], len(RESIDUALS)):
            raise DtwinValueError(
                f"state_means must have shape ({gamma.shape[1]}, {len(RESIDUALS)}) "
                f"(got {means.shape})"
            )
    bias = gamma @ means  # Eq. (25), (T, 6)
    corrected_index = [RESIDUALS.index(m.residual) for m in MODULES if m.surrogate == "arx"]
    applied = shaped_bias(
        bias[:, corrected_index], kappa=kappa, ema_alpha=ema_alpha, rate_max=rate_max
    ).applied
    corrected_arx = {
        signal: surr[signal] - applied[:, i] for i, signal in enumerate(CORRECTED_SIGNALS)
    }
    corrected = _derived(corrected_arx, alpha, w1, w2, dt)
    after = np.column_stack([corrected[_SIGNAL_OF[e]] - phys[_SIGNAL_OF[e]] for e in RESIDUALS])
    return BiasCorrection(
        state_means=pd.DataFrame(means, columns=list(RESIDUALS)).rename_axis("state"),
        bias=pd.DataFrame(bias, columns=list(RESIDUALS)),
        applied=pd.DataFrame(applied, columns=list(CORRECTED_SIGNALS)),
        corrected=pd.DataFrame({s: corrected[s] for s in _OUTPUTS}),
        residuals_before=pd.DataFrame(before, columns=list(RESIDUALS)),
        residuals_after=pd.DataFrame(after, columns=list(RESIDUALS)),
        metrics=_metrics(before, after, list(RESIDUALS)),
    )


@dataclass(frozen=True)
class PlantBiasCorrection:
    """Result of :func:`correct_plant_bias_viterbi` (plant channel ``e1`` only).

    Attributes
    ----------
    state_means_z : ndarray, shape (K,)
        Mean of z-scored ``e1`` over the samples Viterbi-assigned to each state (0 for states
        that never occur on the path).
    applied : ndarray, shape (T,)
        Bias subtracted from the surrogate position, m (after κ, EMA, rate limiter).
    x_corrected : ndarray, shape (T,)
        Corrected surrogate position, m.
    e1_before, e1_after : ndarray, shape (T,)
        Plant residual before and after, m.
    metrics : DataFrame
        One row, ``channel = "e1"``, with the columns of :attr:`BiasCorrection.metrics`.
    """

    state_means_z: np.ndarray
    applied: np.ndarray
    x_corrected: np.ndarray
    e1_before: np.ndarray
    e1_after: np.ndarray
    metrics: pd.DataFrame


def correct_plant_bias_viterbi(
    x_surrogate: Any,
    x_physics: Any,
    posteriors: Any,
    viterbi: Any,
    *,
    kappa: float = 0.6,
    ema_alpha: float = 0.15,
    rate_max: float = 5e-4,
) -> PlantBiasCorrection:
    """Correct the plant position as the authors' sensitivity sweep does (r_notes.md §7C).

    Parameters
    ----------
    x_surrogate, x_physics : array, shape (T,)
        Surrogate and physics positions, m; ``e1 = x_surrogate − x_physics``.
    posteriors : array, shape (T, K)
        State posteriors γ_t(k).
    viterbi : array of int, shape (T,)
        Viterbi path, states numbered 0 … K−1 (the columns of ``posteriors``).
    kappa : float, default 0.6
        Gain (the code's value; the paper states 0.8).
    ema_alpha : float, default 0.15
    rate_max : float, default 5e-4
        Rate-limiter bound, m/sample (the code's value; the paper states 0.05).

    Returns
    -------
    PlantBiasCorrection

    Notes
    -----
    ``z = (e1 − mean e1)/sd e1`` (sample sd); ``m_k`` = mean of ``z`` over the Viterbi
    samples of state k; ``b_z(t) = Σ_k γ_t(k) m_k``; the bias in metres is
    ``κ·(b_z·sd + mean)`` (κ applies to the mean too, as in the code); then EMA, then the rate
    limiter; ``x_corrected = x_surrogate − bias``.
    """
    kappa = require_number("sensitivity.kappa", kappa)
    x_s = require_finite_array("x_surrogate", x_surrogate)
    x_p = require_finite_array("x_physics", x_physics)
    if x_s.shape != x_p.shape or len(x_s) < 2:
        raise DtwinValueError(
            "x_surrogate and x_physics must have equal length >= 2 "
            f"(got {x_s.shape} and {x_p.shape})"
        )
    gamma = _require_posteriors(posteriors, len(x_s))
    path = np.asarray(viterbi)
    if path.shape != x_s.shape or not np.issubdtype(path.dtype, np.integer):
        raise DtwinValueError(
            f"viterbi must be integers of shape {x_s.shape} (got {path.dtype} {path.shape})"
        )
    n_states = gamma.shape[1]
    if path.min() < 0 or path.max() >= n_states:
        raise DtwinValueError(
            f"viterbi states must lie in 0 … {n_states - 1} (got {path.min()} … {path.max()})"
        )
    e1 = x_s - x_p
    mean, sd = float(e1.mean()), float(e1.std(ddof=1))
    if sd <= 0:
        raise DtwinValueError("e1 must have non-zero variance to be z-scored (got sd 0)")
    z = (e1 - mean) / sd
    counts = np.bincount(path, minlength=n_states)
    sums = np.bincount(path, weights=z, minlength=n_states)
    means_z = np.divide(sums, counts, out=np.zeros(n_states), where=counts > 0)
    bias = kappa * ((gamma @ means_z) * sd + mean)
    applied = rate_limit(exponential_moving_average(bias, ema_alpha), rate_max)
    x_corrected = x_s - applied
    e1_after = x_corrected - x_p
    return PlantBiasCorrection(
        state_means_z=means_z,
        applied=applied,
        x_corrected=x_corrected,
        e1_before=e1,
        e1_after=e1_after,
        metrics=_metrics(e1[:, None], e1_after[:, None], ["e1"]),
    )
