"""Which effect causes the gap: candidates fitted and scored (docs/gap.md §Which).

Every candidate of a module with a gap (:mod:`dtwin.gap.effects`, plus ``parameter_mismatch``)
is fitted on the training part together with the module's linear parameters
(:mod:`dtwin.gap.fit`), then scored on the **choosing part** by
``n_eff·ln(MSE) + p·ln(n_eff)`` (BIC with the effective sample size of the module's noise, so
that slowly varying noise is not counted as independent evidence). The lowest score wins;
``unexplained`` if it removes less than ``min_share`` of the choosing part's excess gap
(:func:`required_share`). Each candidate's three shrinks on the scoring part are computed here
too (§How far), so that its :class:`~dtwin.gap.results.CandidateReport` is complete.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from dtwin.gap.effects import (
    UNEXPLAINED,
    Effect,
    effect_by_name,
    effects_for_module,
    quantization_variance,
    quantizer_log_density,
)
from dtwin.gap.fit import CandidateFit, fit_candidate, refit_delay, training_view
from dtwin.gap.localise import normalised_rms
from dtwin.gap.models import module_part, profiled_window_error, simulate_module
from dtwin.gap.noise import excess_gap, shrink_pct, whitened, whitening_filter
from dtwin.gap.oe_reference import plain_linear_error
from dtwin.gap.results import CandidateReport, GapSettings
from dtwin.gap.where import ModuleWork, Split
from dtwin.twin.paper_modules import BANDLIMITED, EULER, FOH
from dtwin.twin.wiring import PLANT

__all__ = [
    "FittedCandidate",
    "NEST_MARGIN_PCT",
    "NEST_DEPARTURE",
    "NEST_EVIDENCE",
    "fit_candidates",
    "NESTED_PART_SAMPLES",
    "LINEAR_ALTERNATIVE_ORDER",
    "nested_test",
    "score_candidates",
    "linear_refit_gap",
    "choose",
    "other_gaps",
    "required_share",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FittedCandidate:
    """A fitted candidate: its prediction ``(n_samples,)`` and its choosing/scoring gaps."""

    effect: Effect
    fit: CandidateFit
    predicted: np.ndarray
    gap_choose: float
    gap_score: float


def _finite(gap: float) -> float:
    return gap if math.isfinite(gap) else math.inf


def _effect_params(effect: Effect | None, fit: CandidateFit, nominal, tol) -> dict[str, float]:
    if effect is not None and not effect.refits_linear:
        return dict(zip(effect.params, fit.theta, strict=True))
    if nominal is None:
        return dict(fit.lin)
    moved = {}
    for key, value in nominal.items():
        fitted = fit.lin[key]
        scale = abs(value) if value != 0 else 1.0
        moved[key] = abs(fitted - value) / scale
    beyond = {k: fit.lin[k] for k, r in moved.items() if r > tol}
    if not beyond and moved:
        key = max(moved, key=moved.get)
        beyond = {key: fit.lin[key]}
    return beyond


def fit_candidates(work: ModuleWork, split: Split, *, quick: bool = False) -> None:
    """Fit every candidate of the module on the training part; append them to ``work``.

    ``parameter_mismatch`` comes first and the effects start from its re-fitted linear twin;
    each candidate's gaps on the choosing and the scoring part are kept (docs/gap.md §Which).
    A form and the form it nests are each fitted again from the other's fit where that trains
    better (:func:`_nested_pair`). ``quick`` (the nested test's screening fit): each candidate
    refined from its best start only, and a calibrated plant's delay not searched again.
    """
    start = work.lin_base
    fits: dict[str, CandidateFit] = {}
    refine = {"n_refine": 1} if quick else {}  # the fit's default: its three best starts
    for effect in effects_for_module(work.name, include_mismatch=not work.calibrated):
        plain = fits.get(effect.nests[0]) if effect.nests and effect.nested_starts else None
        if plain is None:
            fitted = fit_candidate(work.data, effect, start, n_train=split.n_train, **refine)
        else:  # a wider form starts from the form it contains, as fitted (docs/gap.md §Which)
            scales = work.data.scales
            starts = effect.nested_starts(plain.theta, scales) + effect.starts(scales)
            fitted = fit_candidate(
                work.data, effect, plain.lin, n_train=split.n_train, starts=starts, **refine
            )
        # a calibrated plant's delay was chosen without the effect
        if work.calibrated and work.data.role == PLANT and not quick:
            fitted = refit_delay(work.data, effect, fitted, split.n_train)
        if effect.refits_linear:
            start = fitted.lin  # the effects start from the re-fitted linear twin
        fits[effect.name] = fitted
        if plain is not None and effect.plain_part is not None:
            plain_effect = effect_by_name(effect.nests[0])
            again, fitted = _nested_pair(work, split, plain_effect, plain, effect, fitted, refine)
            fits[effect.name] = fitted
            if again is not plain:
                fits[plain_effect.name] = again
                index = next(
                    i for i, c in enumerate(work.candidates) if c.effect.name == plain_effect.name
                )
                work.candidates[index] = _fitted_candidate(work, split, plain_effect, again)
        work.candidates.append(_fitted_candidate(work, split, effect, fitted))


def _nested_pair(work, split, plain_effect, plain, effect, wide, refine):
    """Return ``(plain, wide)``: a form and a wider form nesting it, each re-fitted from the other.

    Nested models (docs/gap.md §Which): the plain form's optimum trains at least as well as the
    wider form restricted to the plain subspace, and the wider form's at least as well as the
    plain form's. A wider fit that trains better is fitted again as the plain form from its
    plain part (``Effect.plain_part``; Stribeck friction with ``Fs ≤ Fc`` is exactly Coulomb
    friction at ``Fc``), with its linear parameters and delay; then, if the plain form now
    trains better than the wider one, the wider form from that plain fit (its first nested
    start). Each fit is kept only if it trains better than the one it would replace
    (``fit_candidate(incumbent=...)``): a plain fit stopped at a worse optimum (a closed-loop
    rig's Coulomb friction at a 6-sample delay, Fc 449 for a true 346, choosing gap 0.43, while
    its Stribeck fit at delay 0 had no bump, Fc 346, gap 0.12) no longer loses to the wider
    form by the optimiser's luck alone.
    """
    n_train = split.n_train
    if wide.train_rms < plain.train_rms:
        plain = fit_candidate(
            work.data,
            plain_effect,
            wide.lin,
            n_train=n_train,
            starts=[effect.plain_part(wide.theta)],
            incumbent=plain,
            **refine,
        )
    if plain.train_rms < wide.train_rms:
        wide = fit_candidate(
            work.data,
            effect,
            plain.lin,
            n_train=n_train,
            starts=effect.nested_starts(plain.theta, work.data.scales)[:1],
            incumbent=wide,
            **refine,
        )
    return plain, wide


def _fitted_candidate(work: ModuleWork, split: Split, effect: Effect, fitted: CandidateFit):
    """Return ``effect``'s :class:`FittedCandidate`: its prediction and choosing/scoring gaps."""
    predicted = simulate_module(work.data, fitted.lin, effect, fitted.theta)
    gaps = [
        _finite(normalised_rms(work.data.output, predicted, part, work.norm))
        for part in (split.choose, split.score)
    ]
    logger.debug("%s %s: choosing/scoring gap %.4g/%.4g", work.name, effect.name, *gaps)
    return FittedCandidate(effect, fitted, predicted, *gaps)


def _quantizer_floor_and_deviance(work: ModuleWork, fitted: CandidateFit, held: slice):
    """Return a quantizer candidate's noise floor and deviance over ``held`` (normalised units).

    ``held`` is the choosing part: both serve the choice only, never a reported shrink (which
    uses the module's one floor). A quantizer after noise makes part of the noise
    unpredictable: its variance is the floor of this candidate
    (:func:`~dtwin.gap.effects.quantization_variance`). Its deviance is ``−2·mean log p(y)``
    of the quantizer's own density
    (:func:`~dtwin.gap.effects.quantizer_log_density`) less ``log(2π) + 1``, on the scale of a
    Gaussian candidate's ``log(mse)``: values on a lattice are then evidence for it even when
    its mean prediction is no better (docs/gap.md §Which). The noise after the quantizer is
    what the module's noise leaves beyond the noise before it, at least ``q/100``.
    """
    step, offset, before = fitted.theta
    noise = work.floor.rms
    clean = simulate_module(work.data, fitted.lin)[held]
    extra = quantization_variance(clean - offset, step, before)
    floor = math.sqrt(max(noise**2 - before**2, 0.0) + extra) / work.norm
    if not step > 0:
        return floor, math.log(max(float(np.mean((work.data.output[held] - clean) ** 2)), 1e-300))
    after = max(math.sqrt(max(noise**2 - before**2, 0.0)), step / 100.0)
    log_p = quantizer_log_density(work.data.output[held], clean, step, offset, before, after)
    deviance = -2.0 * float(np.mean(log_p)) - 2.0 * math.log(work.norm)
    return floor, deviance - math.log(2 * math.pi) - 1.0


def linear_refit_gap(work: ModuleWork) -> float:
    """Return the scoring-part gap of the twin with only its linear parameters re-fitted.

    That is the ``parameter_mismatch`` fit (every linear parameter free, same training part);
    a module calibrated from data has no such candidate: its linear twin is already fitted
    freely on the training part (docs/gap.md §How far).
    """
    for fitted in work.candidates:
        if fitted.effect.refits_linear:
            return fitted.gap_score
    return work.gap_scored


def _three_shrinks(work: ModuleWork, effect: Effect, gap_after: float, refit: float) -> tuple:
    """Return ``(raw, own, excess, clipped)``: the three shrinks (%) on the scoring part.

    ``own`` compares with the linear re-fit ``refit`` (the twin as given for
    ``parameter_mismatch``, which is that re-fit); ``excess`` uses the module's one noise floor
    for every candidate; ``clipped`` when the gap after is within it (docs/gap.md §How far).
    """
    floor = work.floor.rms / work.norm
    before = work.gap_scored
    reference = before if effect.refits_linear else refit
    excess_after = excess_gap(gap_after, floor)
    return (
        shrink_pct(before, gap_after),
        shrink_pct(excess_gap(reference, floor), excess_after),
        shrink_pct(excess_gap(before, floor), excess_after),
        bool(gap_after <= floor),
    )


def _share_part(work: ModuleWork, split: Split) -> slice:
    """Return the part a candidate's share of the excess gap is measured on (docs/gap.md §Which).

    The choosing part, unless the module's twin has no excess over its floor there: a module is
    flagged on the training and choosing parts together (§Where), and a gap that lies in the
    training part alone left every candidate a share of nothing, 0 %, so the answer was
    ``unexplained`` whatever the candidates removed (a rig's quadratic damping whose fitted
    candidate reached 0.0133 on the choosing part, below its floor of 0.0149, where the gap of
    0.0273 lay in the training part). Then it is those two parts together, where the gap was
    found.
    """
    floor = work.floor.rms / work.norm
    if work.gap_before > floor:
        return split.choose
    return split.decide


def score_candidates(work: ModuleWork, split: Split, settings: GapSettings):
    """Return the module's :class:`CandidateReport` list, best (lowest choosing score) first.

    ``score = n_eff·deviance + n_params·ln(n_eff)`` on the choosing part (docs/gap.md §Which);
    the shrinks on the scoring part (§How far).
    """
    n_eff = work.n_eff
    floor = work.floor.rms / work.norm
    share_part = _share_part(work, split)
    excess_choose = excess_gap(
        normalised_rms(work.data.output, work.sim_before, share_part, work.norm), floor
    )
    refit = linear_refit_gap(work)
    tolerance = settings.calibration_tolerance
    reports = []
    for fitted in work.candidates:
        effect, fit, gap = fitted.effect, fitted.fit, fitted.gap_choose
        gap_share = gap
        if share_part != split.choose:
            gap_share = _finite(
                normalised_rms(work.data.output, fitted.predicted, share_part, work.norm)
            )
        floor_c = floor
        deviance = math.log(max(gap * gap, 1e-300))  # a Gaussian's, less log(2π) + 1
        if effect.lattice:
            floor_c, deviance = _quantizer_floor_and_deviance(work, fit, split.choose)
        score = n_eff * deviance + fit.n_free * math.log(max(n_eff, 2.0))
        raw, own, excess, clipped = _three_shrinks(work, effect, fitted.gap_score, refit)
        reports.append(
            CandidateReport(
                module=work.name,
                effect=effect.name,
                params=_effect_params(effect, fit, work.lin_nominal, tolerance),
                lin=dict(fit.lin),
                n_params=fit.n_free,
                choosing_gap=gap,
                choosing_share_pct=shrink_pct(excess_choose, excess_gap(gap_share, floor_c)),
                scoring_gap_after=fitted.gap_score,
                raw_shrink_pct=raw,
                own_shrink_pct=own,
                excess_shrink_pct=excess,
                excess_clipped=clipped,
                score=score,
                weight=0.0,
            )
        )
    if not reports:  # a calibrated M3 or M4: no candidate once parameter_mismatch is out
        return []
    best = min(r.score for r in reports)
    weights = np.array([math.exp(-(r.score - best) / 2.0) for r in reports])
    weights /= weights.sum()
    reports = [
        replace(r, score=r.score - best, weight=float(w))
        for r, w in zip(reports, weights, strict=True)
    ]
    return sorted(reports, key=lambda r: r.score)


#: Most samples of the training part, and of the choosing part, the nested test uses: on a
#: longer recording it fits and compares over the contiguous stretch of at most twice this many
#: samples around their boundary, so its memory and CPU do not grow with the recording.
NESTED_PART_SAMPLES = 10_000
#: Order of the plain linear model OE(n, n) an effect must beat in the nested test: the twin's
#: second-order plant and two more second-order stages (an actuator's and a sensor's or
#: filter's dynamics, the linear parts a measured chain has and a plant twin lacks).
LINEAR_ALTERNATIVE_ORDER = 6


def _linear_alternative(part: ModuleWork, split: Split, whiten, scored) -> float | None:
    """Return the whitened choosing-part sum of squares of the plain linear alternative.

    ``OE(n, n)`` with ``n`` = :data:`LINEAR_ALTERNATIVE_ORDER`
    (:func:`~dtwin.gap.oe_reference.plain_linear_error`) on the nested test's part, its
    innovations over the test's ``scored`` samples. None for a module that is not a windowed
    exact plant, or when the fitted model does not cover those samples (an overflowing ``F``).
    """
    data = part.data
    if data.role != PLANT or data.discretisation == EULER or data.horizon is None:
        return None
    first = 0 if data.discretisation in (FOH, BANDLIMITED) else 1  # does u[k] act on x[k]?
    delay = int(part.lin_base.get("delay_samples", 0))
    error = plain_linear_error(data, delay, split.n_train, LINEAR_ALTERNATIVE_ORDER, first)
    innovations = whitened(error[split.choose], whiten)[scored]
    if not np.all(np.isfinite(innovations)):
        return None
    return float(innovations @ innovations)


def _linear_bar(
    part: ModuleWork, split: Split, whiten, scored, candidate_sum: float, removed: float, min_gap
) -> str | None:
    """Return the bar a nested-test candidate clears, or None when it does not.

    The windowed exact plant: the candidate's whitened choosing-part sum of squares
    ``candidate_sum`` (over the ``scored`` samples, whitened by ``whiten``) must be below the
    plain linear alternative's (:func:`_linear_alternative`); any other module: it must remove
    at least ``min_gap`` of the linear twin's error (``removed``; docs/gap.md §Where).
    """
    alternative = _linear_alternative(part, split, whiten, scored)
    if alternative is None:
        return ">= min_gap" if removed >= min_gap else None
    beaten = int(np.count_nonzero(scored)) * math.log(alternative / candidate_sum)
    logger.debug("%s nested test: the candidate beats OE alternative by T %.2f", part.name, beaten)
    order = LINEAR_ALTERNATIVE_ORDER
    return f"more than a plain linear OE({order}, {order}) model does" if beaten > 0 else None


def nested_test(work: ModuleWork, split: Split, settings: GapSettings) -> str | None:
    """Return why a module within its noise threshold has a gap after all, or None.

    The nested test (docs/gap.md §Where) for a module calibrated from data, or whose floor holds
    process noise read from the data (a twin file without noise levels,
    :func:`~dtwin.gap.noise.process_noise_floor`: a faint effect may pass for that noise): every
    candidate is fitted on the training part and compared on the choosing part with the linear twin,
    the better of the calibrated one and the same one re-fitted by the candidates' own fit (so that
    a candidate's gain is not a better fit of the linear part). Both errors are whitened by the AR
    noise model of the candidate's training error (:func:`whitening_filter`): the candidate nests
    the linear twin, so its error is the noise whether the effect is there or not, whereas the
    linear twin's error holds a present effect, whose slow part its noise model would take for
    coloured noise. Each model's error is that of its windows with their initial states fitted to
    the whole window (:func:`~dtwin.gap.models.profiled_window_error`): the states are nuisance
    parameters of both models, and the warm-up's estimate leaves a state error in every window that
    a candidate force damps on clean data as well.
    ``T = n·ln(Σε_linear²/Σε_candidate²)`` over the ``n`` whitened choosing samples is then the
    likelihood ratio of the nested Gaussian models with coloured noise. The module has a gap
    when the best-scored candidate (:func:`score_candidates`, nested forms as in
    :func:`choose`) reaches ``χ²_p(1 − significance/K)`` (``p`` its effect parameters, ``K``
    the candidates: a test of size ``significance`` over all of them) **and** explains the
    choosing part better than a plain linear model of higher order does: an
    ``OE(n, n)`` model (:data:`LINEAR_ALTERNATIVE_ORDER`,
    :func:`~dtwin.gap.oe_reference.plain_linear_error`: the twin's delay, a same-sample term
    only when the hold lets ``u[k]`` act on ``x[k]``, each window's ``n`` initial outputs
    fitted to it), whitened alike. The test's null is the twin, and a twin is itself an
    approximation: over many samples a candidate that takes up a small misfit of its linear
    structure passes the test as a faint effect does (a first-order lag recorded over 1e6
    samples, a 400-tap kernel, read cubic stiffness at ``T`` = 94; OE(6, 6) fits it better by
    ``T`` = 360). A misfit a linear model removes as well is not credited to an effect, as a
    shrink credited to one excludes what re-fitting the linear twin achieves (docs/gap.md
    §How far). A module other than the windowed exact plant has no such alternative and keeps
    the bar ``√(gap_linear² − gap_candidate²) ≥ min_gap``.

    On a recording with more than :data:`NESTED_PART_SAMPLES` training or choosing samples
    the candidates are fitted and compared on the contiguous part of at most that many of each
    around their boundary (:func:`~dtwin.gap.models.module_part`, windowed as the fit sees it:
    :func:`~dtwin.gap.fit.training_view`); only when the test finds a gap are they fitted
    again on the whole training part, every start refined (the test's own fits refine the best
    start only: ``fit_candidates(quick=True)``), into ``work.candidates``.
    """
    start = max(0, split.n_train - NESTED_PART_SAMPLES)
    stop = min(split.n_choose, split.n_train + NESTED_PART_SAMPLES)
    if start == 0 and stop == split.n_choose:
        part, part_split = replace(work, candidates=[]), split
    else:
        # windowed as the fit sees a long window (a recording's window may outlast the part)
        data = training_view(module_part(work.data, start, stop), split.n_train - start)[0]
        part_split = Split(split.n_train - start, stop - start, stop - start)
        simulated = simulate_module(data, work.lin_base)
        part = replace(
            work,
            data=data,
            sim_before=simulated,
            gap_before=normalised_rms(data.output, simulated, part_split.choose, work.norm),
            gap_scored=math.nan,
            candidates=[],
        )
    fit_candidates(part, part_split, quick=True)
    ranked = score_candidates(part, part_split, settings)
    if not ranked:
        return None
    best = _plain_over_nesting(ranked)
    fitted = next(c for c in part.candidates if c.effect.name == best.effect)
    output, choose = part.data.output, part_split.choose
    refit = fit_candidate(part.data, None, part.lin_base, n_train=part_split.n_train)
    models = [(fitted.fit.lin, fitted.effect, fitted.fit.theta), (part.lin_base, None, ())]
    models.append((refit.lin, None, ()))
    # each window's initial state profiled out of every model's error (a nuisance of both)
    profiled = [profiled_window_error(part.data, lin, eff, theta) for lin, eff, theta in models]
    # the noise model of the model that nests the other: its error is noise under both
    whiten = whitening_filter(profiled[0][: part_split.n_train])
    innovations = np.stack([whitened(error[choose], whiten) for error in profiled])
    scored = np.all(np.isfinite(innovations), axis=0)
    n_scored = int(np.count_nonzero(scored))
    if n_scored < 2 * len(whiten):
        return None
    sums = np.sum(innovations[:, scored] ** 2, axis=1)
    linear = 1 + int(np.argmin(sums[1:]))
    if not (sums[0] > 0 and sums[linear] > 0):
        return None
    statistic = n_scored * math.log(sums[linear] / sums[0])
    n_params = max(fitted.effect.n_params, 1)
    critical = float(chi2.ppf(1.0 - settings.significance / len(ranked), n_params))
    predictions = (fitted.predicted, part.sim_before, simulate_module(part.data, refit.lin))
    gaps = [normalised_rms(output, prediction, choose, work.norm) for prediction in predictions]
    removed = math.sqrt(max(gaps[linear] ** 2 - gaps[0] ** 2, 0.0))
    logger.debug(
        "%s nested test: %s T %.2f (critical %.2f, n %d, AR(%d)), removes %.4g (gap %.4g -> %.4g)",
        work.name,
        best.effect,
        statistic,
        critical,
        n_scored,
        len(whiten) - 1,
        removed,
        gaps[linear],
        gaps[0],
    )
    if statistic < critical:
        return None
    # the linear alternative is fitted only for a significant candidate
    bar = _linear_bar(part, part_split, whiten, scored, sums[0], removed, settings.min_gap)
    if bar is None:
        return None
    fit_candidates(work, split)  # the answer's candidates: every start refined, whole part
    return (
        f"gap {work.gap_cal:.3g} within the noise threshold {work.threshold:.3g}, but "
        f"{best.effect} lowers the linear twin's choosing-part gap {gaps[linear]:.3g} to "
        f"{gaps[0]:.3g}: likelihood ratio {statistic:.1f} over {n_scored} samples whitened by "
        f"an AR({len(whiten) - 1}) noise model, each window's initial state fitted, >= "
        f"chi2_{n_params} {critical:.1f} (size {settings.significance:g} over {len(ranked)} "
        f"candidates; removes {removed:.3g} of the output's spread, {bar})"
    )


def choose(flagged: list[ModuleWork], ranked: Mapping[str, list], settings: GapSettings):
    """Return ``(source, chosen)``: the source module's work and its winning candidate.

    The source is the flagged module furthest above its threshold (``gap_cal/threshold``);
    ``chosen`` is its best-scored candidate if that removes at least its required share of the
    choosing part's excess gap (:func:`required_share`), else None (docs/gap.md §Which). Both
    are None when nothing is flagged. Every number used here is the choosing part's.
    """
    source = max(flagged, key=lambda w: w.gap_cal / w.threshold) if flagged else None
    chosen = None
    if source is not None:
        if not ranked[source.name]:
            return source, None
        best = _plain_over_nesting(ranked[source.name])
        # a module flagged by the nested test has its gap because this candidate passed it
        chosen = best if source.nested is not None or _clears_bar(best, settings) else None
    return source, chosen


#: Share of the choosing excess (percentage points) a candidate must remove beyond a candidate
#: it nests (``Effect.nests``) to be chosen over it (docs/gap.md §Which).
NEST_MARGIN_PCT = 5.0
#: Departure from the nested form (``Effect.departure``: a breakaway force 25 % above the
#: sliding one) from which a wider form scored :data:`NEST_EVIDENCE` better is chosen whatever
#: its margin.
NEST_DEPARTURE = 0.25
#: Score difference (BIC, ``−2·ln`` of the Bayes factor) by which a departing wider form must
#: beat the form it nests: "strong" evidence on Kass and Raftery's scale (J. Am. Stat. Assoc.
#: 90, 1995).
NEST_EVIDENCE = 6.0


def _plain_over_nesting(ranked: Sequence[CandidateReport]) -> CandidateReport:
    """Return the best candidate, or the plain one it nests if the data do not show more.

    Stribeck friction with its breakaway force equal to its sliding one is Coulomb friction:
    with many effective samples the score prefers the wider form for any small mismatch of
    shape (a sharper sign), not for a bump. The plain form is kept unless the wider one removes
    :data:`NEST_MARGIN_PCT` more of the choosing excess, or its fitted parameters depart from
    the plain form by :data:`NEST_DEPARTURE` or more (a breakaway force 25 % above the sliding
    one, which the plain form's level cannot hold) and it scores :data:`NEST_EVIDENCE` better
    where the plain form leaves part of the choosing excess (a plain form that explains all of
    it down to the noise floor leaves nothing a bump could show); kept, the plain form carries
    both weights.
    """
    best = ranked[0]
    effect = effect_by_name(best.effect)
    theta = [best.params.get(name, math.nan) for name in effect.params]
    departs = effect.departure is not None and effect.departure(theta) >= NEST_DEPARTURE
    for name in effect.nests:
        plain = next((r for r in ranked if r.effect == name), None)
        if plain is None:
            continue
        # a bump can show only where the plain form leaves an excess above the floor
        leaves = plain.choosing_share_pct < 100.0
        shown = departs and leaves and plain.score - best.score >= NEST_EVIDENCE
        if not shown and best.choosing_share_pct - plain.choosing_share_pct < NEST_MARGIN_PCT:
            return replace(plain, weight=plain.weight + best.weight)
    return best


def _clears_bar(candidate, settings: GapSettings) -> bool:
    """Return whether ``candidate`` removes its :func:`required_share` of the choosing gap."""
    return candidate.choosing_share_pct >= 100 * required_share(candidate.effect, settings)


def other_gaps(
    flagged: Sequence[ModuleWork],
    source: ModuleWork | None,
    ranked: Mapping[str, list],
    settings: GapSettings,
) -> tuple[dict[str, Any], ...]:
    """Return the flagged modules other than the source: where a second effect is needed.

    Each is ``{module, effect, choosing_share_pct, gap_over_threshold}``, furthest above its
    threshold first: ``effect`` is the module's best-scored candidate if it clears
    :func:`required_share` on the choosing part (as the source's answer must), else
    ``unexplained``. The answer itself is unchanged: it names the larger effect and these
    say when two are needed (docs/gap.md, arm (g)).
    """
    others = sorted((w for w in flagged if w is not source), key=lambda w: -w.gap_cal / w.threshold)
    found = []
    for work in others:
        best = ranked[work.name][0] if ranked.get(work.name) else None
        explained = best is not None and _clears_bar(best, settings)
        found.append(
            {
                "module": work.name,
                "effect": best.effect if explained else UNEXPLAINED,
                "choosing_share_pct": None if best is None else float(best.choosing_share_pct),
                "gap_over_threshold": float(work.gap_cal / work.threshold),
            }
        )
    return tuple(found)


def required_share(effect: str, settings: GapSettings) -> float:
    """Return the share of the excess gap candidate ``effect`` must remove to be the answer.

    ``min_linear_share`` for a candidate of linear form (``Effect.linear_form``: inside the
    twin's own model class, exact when right), ``min_share`` for the others, whose forms may
    only approximate a measured effect (docs/gap.md §Which).
    """
    linear = effect_by_name(effect).linear_form
    return settings.min_linear_share if linear else settings.min_share
