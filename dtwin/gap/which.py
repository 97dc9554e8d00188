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

from dtwin.gap.effects import (
    UNEXPLAINED,
    Effect,
    effect_by_name,
    effects_for_module,
    quantization_variance,
    quantizer_log_density,
)
from dtwin.gap.fit import CandidateFit, fit_candidate, refit_delay
from dtwin.gap.localise import normalised_rms
from dtwin.gap.models import simulate_module
from dtwin.gap.results import CandidateReport, GapSettings
from dtwin.gap.where import ModuleWork, Split
from dtwin.wiring import PLANT

__all__ = [
    "FittedCandidate",
    "NEST_MARGIN_PCT",
    "NEST_DEPARTURE",
    "NEST_EVIDENCE",
    "shrink_pct",
    "fit_candidates",
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


def _excess(gap: float, floor: float) -> float:
    return math.sqrt(max(gap * gap - floor * floor, 0.0))


def shrink_pct(before: float, after: float) -> float:
    """Return ``100·(1 − after/before)``, the percentage a gap shrank (0 when ``before ≤ 0``)."""
    if before <= 0:
        return 0.0
    return 100.0 * (1.0 - after / before)


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


def fit_candidates(work: ModuleWork, split: Split) -> None:
    """Fit every candidate of the module on the training part; append them to ``work``.

    ``parameter_mismatch`` comes first and the effects start from its re-fitted linear twin;
    each candidate's gaps on the choosing and the scoring part are kept (docs/gap.md §Which).
    """
    start = work.lin_base
    fits: dict[str, CandidateFit] = {}
    for effect in effects_for_module(work.name, include_mismatch=not work.calibrated):
        plain = fits.get(effect.nests[0]) if effect.nests and effect.nested_starts else None
        if plain is None:
            fitted = fit_candidate(work.data, effect, start, n_train=split.n_train)
        else:  # a wider form starts from the form it contains, as fitted (docs/gap.md §Which)
            scales = work.data.scales
            starts = effect.nested_starts(plain.theta, scales) + effect.starts(scales)
            fitted = fit_candidate(
                work.data, effect, plain.lin, n_train=split.n_train, starts=starts
            )
        if work.calibrated and work.data.role == PLANT:  # its delay was chosen without the effect
            fitted = refit_delay(work.data, effect, fitted, split.n_train)
        if effect.refits_linear:
            start = fitted.lin  # the effects start from the re-fitted linear twin
        fits[effect.name] = fitted
        predicted = simulate_module(work.data, fitted.lin, effect, fitted.theta)
        gaps = [
            _finite(normalised_rms(work.data.output, predicted, part, work.norm))
            for part in (split.choose, split.score)
        ]
        work.candidates.append(FittedCandidate(effect, fitted, predicted, *gaps))
        logger.debug("%s %s: choosing/scoring gap %.4g/%.4g", work.name, effect.name, *gaps)


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
    excess_after = _excess(gap_after, floor)
    return (
        shrink_pct(before, gap_after),
        shrink_pct(_excess(reference, floor), excess_after),
        shrink_pct(_excess(before, floor), excess_after),
        bool(gap_after <= floor),
    )


def score_candidates(work: ModuleWork, split: Split, settings: GapSettings):
    """Return the module's :class:`CandidateReport` list, best (lowest choosing score) first.

    ``score = n_eff·deviance + n_params·ln(n_eff)`` on the choosing part (docs/gap.md §Which);
    the shrinks on the scoring part (§How far).
    """
    n_eff = work.n_eff
    floor = work.floor.rms / work.norm
    excess_choose = _excess(work.gap_before, floor)
    refit = linear_refit_gap(work)
    tolerance = settings.calibration_tolerance
    reports = []
    for fitted in work.candidates:
        effect, fit, gap = fitted.effect, fitted.fit, fitted.gap_choose
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
                choosing_share_pct=shrink_pct(excess_choose, _excess(gap, floor_c)),
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
        chosen = best if _clears_bar(best, settings) else None
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
