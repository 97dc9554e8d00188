"""How far the gap shrinks: the answer's chain, free run, intervals and reports (§How far).

On the **scoring part**, never used for a decision. Each candidate's three shrinks
(``raw_shrink_pct``: whole error; ``own_shrink_pct``: the effect's own share, against the twin
with only its linear parameters re-fitted; ``excess_shrink_pct``: the excess over the module's
one noise floor, ``√(gap² − floor²)``) come with its score (:mod:`dtwin.gap.which`). Here: the
chain re-run with the chosen effect added gives ``kpi_shrink_pct`` (:func:`chain_kpi_shrink`);
the source module run freely gives ``free_run_rms_before``/``_after`` (:func:`free_run_rms`);
the answer's parameters get 95 % intervals (:func:`answer_intervals`, docs/gap.md §Intervals).
:func:`module_reports` and :func:`verdict` assemble the fields of
:class:`~dtwin.gap.results.Diagnosis` (docs/gap.md §How far, §Statuses).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from dtwin.gap.confidence import calibrated_confidence
from dtwin.gap.effects import NONE, UNEXPLAINED, effect_by_name
from dtwin.gap.intervals import parameter_intervals, smoothed_fit
from dtwin.gap.localise import ModuleModel, normalised_rms, run_chain, upstream_modules
from dtwin.gap.models import simulate_module
from dtwin.gap.noise import shrink_pct
from dtwin.gap.recording import DERIVED_INPUTS, Recording
from dtwin.gap.results import ModuleReport
from dtwin.gap.where import ModuleWork, Split, nominal_lin
from dtwin.gap.which import linear_refit_gap
from dtwin.twin.wiring import MODULES, PLANT, only_module

__all__ = [
    "chain_before_after",
    "chain_kpi_shrink",
    "module_reports",
    "scoring_series",
    "free_run_rms",
    "answer_intervals",
    "verdict",
]


def chain_before_after(rec, twin, works, t, source, chosen) -> tuple[dict, dict]:
    """Return the chain's signals before and after the chosen effect is added.

    *Before* runs every module with its nominal (or calibrated) linear twin; *after* adds the
    chosen candidate to the source module (the same signals as *before* when nothing is
    chosen). Each signal has shape ``(n_samples,)`` (docs/gap.md §How far).
    """
    scales = {name: w.data.scales for name, w in works.items()}
    layouts = {name: w.data for name, w in works.items()}
    models = {}
    for module in MODULES:
        if module.name in works:
            models[module.name] = ModuleModel(works[module.name].lin_base)
        else:
            nominal = nominal_lin(module.name, twin)
            if nominal is not None:
                models[module.name] = ModuleModel(nominal)
    chain_before = run_chain(rec.signals, models, rec.dt, t, scales, layouts)
    chain_after = chain_before
    if chosen is not None:
        fitted = next(f for f in source.candidates if f.effect.name == chosen.effect)
        models_after = dict(models)
        models_after[source.name] = ModuleModel(fitted.fit.lin, fitted.effect, fitted.fit.theta)
        chain_after = run_chain(rec.signals, models_after, rec.dt, t, scales, layouts)
    return chain_before, chain_after


def chain_kpi_shrink(rec, chain_before, chain_after, source, chosen, scored, notes) -> tuple:
    """Return ``(kpi_signal, kpi_shrink_pct)`` on the scoring part; may append to ``notes``.

    The KPI signal is the most downstream recorded signal the chain simulates (``z`` first);
    its shrink is None when no effect was chosen or the source is not upstream of it.
    """
    kpi_signal = None
    for signal in ("z", "y_fused", "y_A", "y_B", "x", "u_act"):
        if signal in rec.signals and signal in chain_before:
            kpi_signal = signal
            break
    kpi_shrink = None
    if chosen is not None and kpi_signal is not None:
        if source.name in upstream_modules(kpi_signal):
            recorded = rec.signals[kpi_signal]
            norm = float(np.std(recorded)) or 1.0
            before = normalised_rms(recorded, chain_before[kpi_signal], scored, norm)
            after = normalised_rms(recorded, chain_after[kpi_signal], scored, norm)
            kpi_shrink = shrink_pct(before, after)
        else:
            notes.append(f"{source.name} is not upstream of the end-to-end signal {kpi_signal}")
    return kpi_signal, kpi_shrink


def _status(work: ModuleWork, flagged, source, chain_gap: float | None) -> tuple[str, str]:
    """Return ``(status, reason)`` of an analysed module (docs/gap.md §Statuses)."""
    if work in flagged:
        status = "source" if work is source else "gap"
        if work.nested is not None:
            return status, work.nested
        return status, (
            f"gap {work.gap_cal:.3g} after in-tolerance calibration exceeds the noise "
            f"threshold {work.threshold:.3g}"
        )
    if chain_gap is not None and chain_gap > 2 * max(work.gap_before, work.threshold):
        return "inherited", (
            f"local gap {work.gap_before:.3g} is within noise; chain gap {chain_gap:.3g} "
            "comes from upstream"
        )
    return "clean", f"gap {work.gap_cal:.3g} within the noise threshold {work.threshold:.3g}"


def _skipped_report(module, rec: Recording) -> ModuleReport:
    """Return the report of a module whose input or output column is missing."""
    missing = [
        s
        for s in (*module.inputs, module.output)
        if s not in rec.signals and s not in DERIVED_INPUTS
    ]
    return ModuleReport(
        module.name, "skipped", f"column(s) not in the recording: {', '.join(missing)}"
    )


def module_reports(rec, works, flagged, source, chosen, chains, split: Split) -> dict:
    """Return one :class:`ModuleReport` per module of the wiring table, in its order.

    ``chains`` is ``(chain_before, chain_after)`` from :func:`chain_before_after`; the status
    compares the choosing part's chain gap, the reported chain gaps are the scoring part's.
    """
    chain_before, chain_after = chains
    modules = {}
    for module in MODULES:
        name = module.name
        if name not in works:
            modules[name] = _skipped_report(module, rec)
            continue
        work = works[name]
        out = module.output
        chain_choose = chain_gap = chain_gap_after = None
        if out in chain_before:
            chain_choose = normalised_rms(
                work.data.output, chain_before[out], split.choose, work.norm
            )
            chain_gap = normalised_rms(work.data.output, chain_before[out], split.score, work.norm)
            chain_gap_after = normalised_rms(
                work.data.output, chain_after[out], split.score, work.norm
            )
        gap_after = refit = None
        if source is not None and name == source.name and chosen is not None:
            gap_after, refit = chosen.scoring_gap_after, linear_refit_gap(work)
        status, reason = _status(work, flagged, source, chain_choose)
        modules[name] = ModuleReport(
            name,
            status,
            reason,
            work.calibrated,
            work.gap_before,
            work.gap_cal,
            work.gap_scored,
            refit,
            gap_after,
            chain_gap,
            chain_gap_after,
            work.floor.rms / work.norm,
            work.floor_twin,
            work.floor_data,
            work.threshold,
            work.n_eff,
            work.lin_nominal,
            work.lin_base,
            work.data.discretisation if module.role == PLANT else None,
            work.data.horizon,
            work.reference_gap,
            work.tried,
        )
    return modules


def scoring_series(rec: Recording, source, ranked, scored: slice) -> dict[str, np.ndarray]:
    """Return the source module's scoring-part series for the figure, each ``(n_scored,)``.

    Keys ``t`` (s), ``recorded``, ``before`` (the twin) and ``after`` (the best candidate);
    empty when there is no source.
    """
    if source is None:
        return {}
    series = {
        "t": rec.t[scored],
        "recorded": source.data.output[scored],
        "before": source.sim_before[scored],
    }
    if not ranked[source.name]:
        return series
    best = ranked[source.name][0].effect
    series["after"] = next(f.predicted for f in source.candidates if f.effect.name == best)[scored]
    return series


def free_run_rms(works: Mapping[str, ModuleWork], source, chosen, split: Split) -> dict:
    """Return ``free_run_rms_before`` and ``free_run_rms_after`` (recording units) as a dict.

    The source module's twin (M1's when there is no source; neither: both None) is run freely
    over the scoring part from the recorded state at its first sample (no windows), with its
    linear twin (calibrated, or the twin file's) and with the chosen effect (None when no
    effect is chosen); each value is the RMS of recorded − simulated over the scoring part's
    simulated samples, in the output's units, comparable to a published free-run simulation
    error. A plant that is not strictly stable (``k = 0``: integrating, or ``c ≤ 0``) has no
    free-run error worth reporting (its position drifts with any force error): both None
    (docs/gap.md §How far).
    """
    work = source if source is not None else works.get(only_module(PLANT))
    none = {"free_run_rms_before": None, "free_run_rms_after": None}
    if work is None or (work.data.role == PLANT and not _strictly_stable(work.lin_base)):
        return none
    restarts = tuple(sorted({*work.data.restarts, split.n_choose}))
    data = replace(work.data, horizon=None, restarts=restarts)
    runs = {"free_run_rms_before": simulate_module(data, work.lin_base)}
    if chosen is not None and work is source:
        fitted = next(f for f in work.candidates if f.effect.name == chosen.effect)
        runs["free_run_rms_after"] = simulate_module(
            data, fitted.fit.lin, fitted.effect, fitted.fit.theta
        )
    return none | {key: _rms(data.output, sim, split.score) for key, sim in runs.items()}


def answer_intervals(source, chosen, split: Split) -> dict[str, tuple[float, float]]:
    """Return the 95 % interval of each of the answer's parameters (docs/gap.md §Intervals).

    Those of ``params``, and for ``parameter_mismatch`` every re-fitted linear parameter
    (:func:`dtwin.gap.intervals.parameter_intervals`, with the fit of a candidate whose form
    nests the answer's as its ``wider``, else the answer's form made smooth,
    :func:`~dtwin.gap.intervals.smoothed_fit`); empty without a chosen effect.
    """
    if chosen is None:
        return {}
    fitted = next(f for f in source.candidates if f.effect.name == chosen.effect)
    wider = next((f for f in source.candidates if chosen.effect in f.effect.nests), None)
    if wider is not None:
        wider = (wider.effect, wider.fit.lin, wider.fit.theta)
    else:
        fit = fitted.fit
        wider = smoothed_fit(source.data, fitted.effect, fit.lin, fit.theta, split.n_train)
    intervals = parameter_intervals(
        source.data,
        fitted.effect,
        fitted.fit.lin,
        fitted.fit.theta,
        split.n_train,
        other_part=(split.n_train, split.n_choose),
        wider=wider,
    )
    if effect_by_name(chosen.effect).refits_linear:
        return intervals
    return {name: value for name, value in intervals.items() if name in chosen.params}


def _strictly_stable(lin: Mapping[str, float]) -> bool:
    """Return whether the plant ``m·ẍ + c·ẋ + k·x = u`` is strictly stable (m, c, k > 0)."""
    return all(float(lin.get(key, 0.0)) > 0 for key in ("m", "c", "k"))


def _rms(recorded: np.ndarray, simulated: np.ndarray, part: slice) -> float | None:
    """Return RMS(recorded − simulated) over ``part``'s finite samples (None if there are none)."""
    error = (recorded - simulated)[part]
    error = error[np.isfinite(error)]
    return float(np.sqrt(np.mean(error**2))) if len(error) else None


def verdict(source, chosen) -> dict[str, Any]:
    """Return the answer's fields of :class:`Diagnosis` (module to ``excess_clipped``).

    ``none`` without a source, ``unexplained`` with a source but no chosen candidate
    (docs/gap.md §Statuses); the gaps and shrinks are the scoring part's.
    """
    verdict = dict.fromkeys(
        ("gap_before", "gap_refit", "gap_after", "raw_shrink_pct", "own_shrink_pct"), None
    )
    verdict.update(excess_shrink_pct=None, excess_clipped=None, params={}, confidence=None)
    verdict.update(bic_weight=None)
    if source is None:
        return {**verdict, "module": None, "effect": NONE}
    if chosen is None:
        return {**verdict, "module": source.name, "effect": UNEXPLAINED}
    return {
        "module": source.name,
        "effect": chosen.effect,
        "params": chosen.params,
        "confidence": calibrated_confidence(chosen.weight),
        "bic_weight": chosen.weight,
        "gap_before": source.gap_scored,
        "gap_refit": linear_refit_gap(source),
        "gap_after": chosen.scoring_gap_after,
        "raw_shrink_pct": chosen.raw_shrink_pct,
        "own_shrink_pct": chosen.own_shrink_pct,
        "excess_shrink_pct": chosen.excess_shrink_pct,
        "excess_clipped": chosen.excess_clipped,
    }
