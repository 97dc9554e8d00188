"""95 % intervals of a fitted candidate's parameters (docs/gap.md §Intervals).

A candidate is fitted by least squares on its simulation error over the training part
(:func:`dtwin.gap.fit.fit_candidate`). Its residuals are neither independent nor of one
variance (a model error is slow; coloured noise; windows restarted from noisy states), so the
textbook covariance ``s²·(JᵀJ)⁻¹`` is too narrow. :func:`parameter_intervals` uses the
**sandwich** covariance with **batch means**: the training residuals are cut into
``n_blocks`` contiguous blocks, each block's score ``g_b = J_bᵀ·r_b`` is taken as one
independent observation, and

``cov = (JᵀJ)⁻¹ · (B/(B − p)) · Σ_b g_b g_bᵀ · (JᵀJ)⁻¹``,

``B`` blocks, ``p`` fitted parameters; the interval is ``θ ± t_{B−1}(0.975)·√cov_ii``
(White 1980; the batch-means variance of Conley 1999 / Ibragimov–Müller 2010 with a t
quantile). The Jacobian ``J`` of the residuals is taken by central differences at the fitted
parameters, over every free parameter of the fit (the linear ones too), so that an effect's
interval carries its trade-off with the re-fitted linear twin.

Three errors the sandwich does not see are added (docs/gap.md §Intervals): the spread between
the fits on two parts (``other_part``); the contrast with a wider catalogue form that nests the
candidate's, or with the candidate's form made smooth (``Effect.smoothed``) when none does
(``wider``: the narrower form's bias when the real effect needs the wider one); and
the limit of an input map that the recorded inputs do not reach (``Effect.input_limit``), which the
data bound only from below. No interval is narrower than the fit's own step tolerance
(:data:`~dtwin.gap.fit.FIT_XTOL`): a noiseless module fitted exactly leaves residuals at
rounding level.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.stats import t as student_t

from dtwin.gap.effects import Effect
from dtwin.gap.fit import (
    FIT_XTOL,
    fit_candidate,
    fit_diff_step,
    linear_typical,
    training_view,
)
from dtwin.gap.models import LINEAR_PARAMS, ModuleData, module_part, simulate_module
from dtwin.twin.paper_modules import EULER

__all__ = [
    "N_BLOCKS",
    "LEVEL",
    "fitted_names",
    "parameter_intervals",
    "smoothed_fit",
]

#: Contiguous blocks of the training residuals (independent observations of the score).
N_BLOCKS = 20
#: Coverage of the intervals.
LEVEL = 0.95
#: Central-difference step, relative to each parameter's typical size, where the fit takes
#: SciPy's default (a smooth training error); elsewhere the fit's own step
#: (:func:`dtwin.gap.fit.fit_diff_step`).
_STEP = 1e-4
#: Jacobian column, relative to the largest, below which a parameter is held at its value.
_UNSEEN = 1e-7
#: Sharpness starts of a smoothed form's fit (with the answer's own parameters).
_SHARPNESS_STARTS = (4.0, 12.0, 40.0)


def smoothed_fit(
    data: ModuleData, effect: Effect, lin: Mapping[str, float], theta: Sequence[float], n_train: int
) -> tuple[Effect, dict[str, float], tuple[float, ...]] | None:
    """Return the wider form of ``effect`` (``Effect.smoothed``) fitted from the answer's fit.

    ``(effect, lin, theta)`` as ``parameter_intervals(wider=...)`` takes it; None when the
    effect has no such form. The fit starts from the answer's parameters with each sharpness
    of ``_SHARPNESS_STARTS`` and frees the same linear parameters as the answer's fit.
    """
    wide = effect.smoothed
    if wide is None:
        return None
    starts = [[*theta, sharpness] for sharpness in _SHARPNESS_STARTS]
    fit = fit_candidate(data, wide, lin, n_train=n_train, starts=starts)
    return wide, dict(fit.lin), tuple(fit.theta)


def fitted_names(
    name: str, lin: Mapping[str, float], effect: Effect | None
) -> tuple[list[str], list[str]]:
    """Return the fit's free parameters: ``(linear ones, the effect's)``.

    The linear ones are those :func:`dtwin.gap.fit.fit_candidate` frees by default
    (:data:`~dtwin.gap.models.LINEAR_PARAMS` of the module, and ``u_offset`` when present).
    """
    linear = [k for k in (*LINEAR_PARAMS[name], "u_offset") if k in lin]
    own = list(effect.params) if effect is not None and not effect.refits_linear else []
    return linear, own


def _typical(data: ModuleData, lin, effect: Effect | None, names: Sequence[str]) -> np.ndarray:
    """Return each parameter's typical size (the step's scale), never 0."""
    scale_free = data.discretisation != EULER
    typical = dict(linear_typical(data.name, lin, data.scales, scale_free=scale_free))
    if effect is not None and not effect.refits_linear:
        typical.update(
            zip(effect.params, (abs(v) for v in effect.typical(data.scales)), strict=True)
        )
    values = np.array([abs(float(typical.get(k, 0.0))) for k in names], dtype=float)
    return np.where(values > 0, values, 1.0)


def _residual_fn(data: ModuleData, effect, lin, linear: Sequence[str], n_train: int):
    """Return ``residual(θ)``: recorded − simulated over the training part, ``(n_train,)``.

    ``θ`` is the free linear parameters (``linear``) followed by the effect's; unscored
    samples (a window's warm-up) are NaN.
    """
    view, segments = training_view(data, n_train)
    target = view.output[:n_train]
    n_lin = len(linear)
    fixed = dict(lin)

    def residual(vector: np.ndarray) -> np.ndarray:
        trial = dict(fixed)
        trial.update(zip(linear, vector[:n_lin], strict=True))
        simulated = simulate_module(
            view, trial, effect, vector[n_lin:], stop=n_train, segments=segments
        )
        return target - simulated

    return residual


def _jacobian(residual, theta: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Return the central-difference Jacobian ``∂r/∂θ``, shape ``(n_samples, p)``."""
    columns = []
    for index, step in enumerate(steps):
        up, down = theta.copy(), theta.copy()
        up[index] += step
        down[index] -= step
        columns.append((residual(up) - residual(down)) / (2.0 * step))
    return np.column_stack(columns)


def _steps(data: ModuleData, effect, beta: np.ndarray, typical: np.ndarray) -> np.ndarray:
    """Return each parameter's central-difference step, in its own units, ``(p,)``.

    Where the fit reads a rough training error with a wider step
    (:func:`dtwin.gap.fit.fit_diff_step`), the Jacobian takes that step as the fit does,
    ``step·max(1, |θ/typical|)·typical``: at a smaller one it is the slope of the error's
    small-scale steps, not of its trend. Elsewhere ``_STEP·typical``.
    """
    step = fit_diff_step(data, effect)
    if step is None:
        return _STEP * typical
    return step * np.maximum(1.0, np.abs(beta / typical)) * typical


def _linearised(data: ModuleData, effect, lin, theta, n_train: int):
    """Return a fitted candidate's ``(linear, names, θ, typical, r, J)`` over the training part.

    ``names`` are :func:`fitted_names` (linear first), ``θ`` their fitted values, ``r`` the
    residuals ``(n_train,)`` (NaN where unscored) and ``J`` their central-difference Jacobian
    ``(n_train, p)`` in units of each parameter's ``typical`` size (``k3 = 1e13`` beside
    ``m = 1e-3`` stays solvable).
    """
    linear, own = fitted_names(data.name, lin, effect)
    names = [*linear, *own]
    beta = np.array([float(lin[k]) for k in linear] + [float(v) for v in theta][: len(own)])
    residual = _residual_fn(data, effect, lin, linear, n_train)
    typical = _typical(data, lin, effect, names)
    with np.errstate(all="ignore"):
        r0 = residual(beta)
        jac = _jacobian(residual, beta, _steps(data, effect, beta, typical)) * typical
    return linear, names, beta, typical, r0, jac


def _block_influences(jac: np.ndarray, r0: np.ndarray, n_blocks: int) -> np.ndarray | None:
    """Return each block's influence ``(JᵀJ)⁻¹·J_bᵀ·r_b`` on the fit, ``(n_blocks, p)``.

    The batch-means sandwich covariance is ``B/(B − p)·Σ_b ψ_b ψ_bᵀ`` of these. A parameter
    whose Jacobian column is below ``_UNSEEN`` of the largest (in typical units) is one the
    residuals do not see at its step: a plant's ``k`` fitted at 1e-15 of its mode's size on an
    integrating rig, whose fit's box is then as narrow. It is held at its value, so its column
    is NaN and the others' influences are conditional on it. None when the rest of ``JᵀJ`` is
    singular or not finite (a parameter the data do not determine).
    """
    norms = np.sqrt(np.sum(jac**2, axis=0))
    seen = norms > _UNSEEN * np.max(norms, initial=0.0)
    hessian = jac[:, seen].T @ jac[:, seen]
    if not np.any(seen) or not np.all(np.isfinite(hessian)) or np.linalg.cond(hessian) > 1e14:
        return None
    bread = np.linalg.inv(hessian)
    influence = np.full((n_blocks, jac.shape[1]), np.nan)
    blocks = zip(np.array_split(jac[:, seen], n_blocks), np.array_split(r0, n_blocks), strict=True)
    influence[:, seen] = [bread @ (j.T @ r) for j, r in blocks]
    return influence


def _contrast_bias(names, beta, influence, wide, used, n_blocks: int) -> np.ndarray:
    """Return the squared bias of each parameter shared with a wider nesting form, else 0.

    ``d = θ − θ_wide`` has, when the narrower form is right, the batch-means variance
    ``V_d = B/(B − p_wide)·Σ_b (ψ_b − ψ_wide,b)²`` of the two fits' block influences; its
    excess ``max(d² − V_d, 0)`` estimates the squared bias of the narrower estimate when the
    real effect needs the wider form (the contrast of Hausman 1978).
    """
    _, wide_names, wide_beta, wide_typical, wide_r, wide_jac = wide
    bias = np.zeros(len(names))
    if n_blocks <= len(wide_beta) + 1:
        return bias
    wide_influence = _block_influences(wide_jac[used], wide_r[used], n_blocks)
    if wide_influence is None:
        return bias
    wide_influence = wide_influence * wide_typical
    wide_p = int(np.sum(np.isfinite(wide_influence[0])))
    for index, name in enumerate(names):
        if name in wide_names:
            other = wide_names.index(name)
            d = beta[index] - wide_beta[other]
            blocks = influence[:, index] - wide_influence[:, other]
            spread = np.sum(blocks**2) * n_blocks / (n_blocks - wide_p)
            if math.isfinite(spread):  # else held in one of the fits
                bias[index] = max(d * d - spread, 0.0)
    return bias


def parameter_intervals(
    data: ModuleData,
    effect: Effect | None,
    lin: Mapping[str, float],
    theta: Sequence[float],
    n_train: int,
    *,
    n_blocks: int = N_BLOCKS,
    level: float = LEVEL,
    other_part: tuple[int, int] | None = None,
    wider: tuple[Effect, Mapping[str, float], Sequence[float]] | None = None,
) -> dict[str, tuple[float, float]]:
    """Return the ``level`` interval of every free parameter of a fitted candidate.

    Parameters
    ----------
    data : ModuleData
        The module's data, as the candidate was fitted on it.
    effect : Effect or None
        The candidate (None or ``parameter_mismatch``: the linear twin alone).
    lin : mapping
        The fitted linear parameters (``CandidateFit.lin``).
    theta : sequence of float
        The fitted effect parameters (``CandidateFit.theta``).
    n_train : int
        Training samples (from the start).
    n_blocks : int, default :data:`N_BLOCKS`
        Blocks of the batch-means covariance.
    level : float, default 0.95
    other_part : (int, int), optional
        Samples ``[start, stop)`` after the training part on which the candidate is fitted
        again: half the squared difference of the two fits is added to each variance (the
        spread a statistical interval misses when the catalogue form only approximates the
        effect or the excitation differs between parts).
    wider : (Effect, mapping, sequence of float), optional
        A wider catalogue form that nests this one (:attr:`Effect.nests`: Stribeck friction
        for Coulomb friction) as fitted: ``(effect, lin, theta)``. Both estimate a parameter
        they share when the narrower form is right; only the wider one does when the real
        effect needs it. The contrast's excess over its own variance is added to the
        variance (:func:`_contrast_bias`), so the interval is a mean-squared-error one.

    Returns
    -------
    dict of str to (float, float)
        ``name → (low, high)`` for every name of :func:`fitted_names`; empty when the
        Jacobian is singular or not finite (a parameter the data do not determine).

    Notes
    -----
    The sandwich covariance with batch means of the module docstring; units are the
    parameters' own.
    """
    linear, names, beta, typical, r0, jac = _linearised(data, effect, lin, theta, n_train)
    used = np.isfinite(r0) & np.all(np.isfinite(jac), axis=1)
    if wider is not None:
        wide = _linearised(data, *wider, n_train)
        used &= np.isfinite(wide[4]) & np.all(np.isfinite(wide[5]), axis=1)
    p = len(beta)
    n_blocks = min(n_blocks, int(np.sum(used)) // max(2 * p, 1))
    influence = _block_influences(jac[used], r0[used], n_blocks) if n_blocks > p + 1 else None
    if influence is None:
        return {}
    influence = influence * typical  # parameters' own units, (n_blocks, p); NaN: held
    p_seen = int(np.sum(np.isfinite(influence[0])))
    variance = np.sum(influence**2, axis=0) * n_blocks / (n_blocks - p_seen)
    if other_part is not None:
        variance = variance + 0.5 * (beta - _refit(data, effect, lin, other_part, linear)) ** 2
    if wider is not None:
        variance = variance + _contrast_bias(names, beta, influence, wide, used, n_blocks)
    spread = np.sqrt(variance)
    half = student_t.ppf(0.5 + level / 2.0, n_blocks - 1) * spread
    # the fit stops once its step is below FIT_XTOL·(FIT_XTOL + ‖θ/typical‖) in typical units
    resolution = FIT_XTOL * (FIT_XTOL + np.linalg.norm(beta / typical)) * typical
    half = np.maximum(half, resolution)
    intervals = {
        name: (float(value - h), float(value + h))
        for name, value, h in zip(names, beta, half, strict=True)
        if math.isfinite(h)
    }
    if effect is not None and effect.input_limit and effect.input_limit[0] in intervals:
        name, signal = effect.input_limit
        mapped = effect.input_map(data.inputs[signal][:n_train], beta[len(linear) :], data.dt)
        low, high = intervals[name]
        intervals[name] = (min(low, float(np.max(np.abs(mapped)))), high)
    return intervals


def _refit(data, effect, lin, part: tuple[int, int], linear: Sequence[str]) -> np.ndarray:
    """Return the free parameters of the candidate fitted again on samples ``part`` alone."""
    start, stop = part
    fit = fit_candidate(
        module_part(data, start, stop), effect, lin, n_train=stop - start, free=linear
    )
    return np.array([float(fit.lin[k]) for k in linear] + [float(v) for v in fit.theta])
