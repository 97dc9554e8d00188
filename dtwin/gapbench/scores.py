"""Scoring diagnoses against the withheld truth: the ``gap_benchmark`` artifact.

Specification: docs/gap.md §Benchmark (cases, rules), §Scores and §Targets.

:func:`score_cases` joins each case's key (the truth from :mod:`dtwin.gapbench.generator` or
:mod:`dtwin.gapbench.rigs`) with its ``diagnosis.json`` and returns one row per case;
:func:`benchmark_metrics` gives the accuracies (each with its Wilson interval), the three
shrinks (docs/gap.md §How far), the fitted parameters' errors and the reliability of the
confidence; :func:`benchmark_checks` states the targets as checks. The figure is drawn by
:mod:`dtwin.figures.gap_benchmark`.

Table columns (:func:`score_cases`): ``case, family, arm, effect, module, expected_effect,
in_list, magnitude, snr, n_samples, diagnosed_module, diagnosed_effect, confidence,
raw_shrink_pct, own_shrink_pct, excess_shrink_pct, excess_clipped, refit_shrink_pct,
kpi_shrink_pct, module_ok, effect_ok, also_needed, second_named, param_name, param_true,
param_fitted, param_error`` (``refit_shrink_pct``: the excess shrink of the linear re-fit
alone, what the own share leaves out; ``also_needed``: the other modules the diagnosis says
need a second effect, ``"M2a:sensor_bias_drift"`` joined by ``"; "``; ``second_named``: for
a two-effect case, whether it names the other effect there).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from typing import Any

import pandas as pd

from dtwin.artifacts import Check
from dtwin.gap.confidence import FITTING_CASES
from dtwin.gap.effects import NONE, PARAMETER_MISMATCH, UNEXPLAINED
from dtwin.gapbench.generator import CASE_EFFECTS
from dtwin.gapbench.rigs import RIG_FORCES
from dtwin.proportions import wilson_interval

#: The benchmark arm of two effects at once (:mod:`dtwin.gapbench.arms`, case type ``two__a+b``).
TWO_ARM = "two"

__all__ = [
    "TARGETS",
    "RIG_TARGETS",
    "DEFAULT_ARM",
    "CEILINGS",
    "CONFIDENCE_BINS",
    "MAGNITUDE_BINS",
    "SHRINK_COLUMNS",
    "CALIBRATION_MIN_ANSWERS",
    "true_parameter",
    "reliability_table",
    "calibration_metrics",
    "score_cases",
    "benchmark_metrics",
    "benchmark_checks",
]

#: The targets on the full benchmark (docs/gap.md §Targets) (≥ 10 cases per effect). The
#: calibration target is a ceiling: ``max_calibration_gap`` ≤ 0.10.
TARGETS: dict[str, float] = {
    "module_accuracy": 0.95,
    "effect_accuracy": 0.90,
    "none_accuracy": 0.90,
    "unexplained_accuracy": 0.80,
    "median_own_shrink_pct": 70.0,
    "median_parameter_error": 0.15,
    "max_calibration_gap": 0.10,
}

#: Targets that are ceilings (observed ≤ target); the others are floors.
CEILINGS: frozenset[str] = frozenset({"median_parameter_error", "max_calibration_gap"})

#: The rig family's targets (docs/gap.md §Rig family) (≥ 30 cases).
RIG_TARGETS: dict[str, float] = {
    "module_accuracy": 0.90,
    "effect_accuracy": 0.85,
    "median_excess_shrink_pct": 80.0,
}

#: The targets of each benchmark family of other physics (docs/gap.md §Your own twin).
FAMILY_TARGETS: dict[str, float] = {
    "module_accuracy": 0.95,
    "effect_accuracy": 0.85,
    "none_accuracy": 0.90,
    "unexplained_accuracy": 0.80,
}

#: The arm of a case whose key names none (docs/gap.md §Scores).
DEFAULT_ARM = "default"

#: Edges of the confidence bins of the reliability table.
CONFIDENCE_BINS: tuple[float, ...] = (0.0, 0.5, 0.8, 0.95, 0.99, 1.0)

#: Fewest answers of a confidence bin the calibration target holds for (docs/gap.md §Targets:
#: every bin of at least 20 answers within 0.10 of its accuracy).
CALIBRATION_MIN_ANSWERS = 20

#: Edges of the effect-magnitude bins (0 = barely above the noise, 1 = strong).
MAGNITUDE_BINS: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)

#: The three shrinks of docs/gap.md §How far, the effect's own share first (the headline).
SHRINK_COLUMNS: tuple[str, ...] = ("own_shrink_pct", "raw_shrink_pct", "excess_shrink_pct")


def _paper_truth(effect: str, params: Mapping[str, Any], key: Mapping[str, Any], dt: float):
    """Return ``(name, true value, value without the effect)`` of a paper-asset case, or None.

    The case effect's own :attr:`~dtwin.gapbench.case_effects.CaseEffect.truth`: only where the
    real form is in the catalogue's family (docs/gap.md §Scores): a cubic stiffness of power
    exactly 2, a symmetric saturation or dead zone; never a damping power other than 2 or a
    drift that is not a line.
    """
    case_effect = CASE_EFFECTS.get(effect)
    if case_effect is None or case_effect.truth is None:
        return None
    return case_effect.truth(params, key, dt)


def true_parameter(key: Mapping[str, Any], dt: float) -> tuple[str, float, float] | None:
    """Return the true parameter that sets the effect's size, in the catalogue's name and units.

    Parameters
    ----------
    key : mapping
        A case's ``key.json`` (:mod:`dtwin.gapbench.generator`, :mod:`dtwin.gapbench.rigs`).
    dt : float
        The recording's sample time, s (a delay's truth is in samples).

    Returns
    -------
    (name, value, reference) or None
        ``reference`` is the value without the effect (0; 1 for a gain; the nominal value for
        a ``parameter_mismatch``; inf for a saturation level, whose error is then relative to
        the value). None when the real form has no catalogue parameter (docs/gap.md §Scores).
    """
    effect, params = key["effect"], key.get("params") or {}
    if key.get("family") == "rig":
        name = RIG_FORCES[effect].size if effect in RIG_FORCES else None
        return (name, float(params[name]), 0.0) if name in params else None
    truth = _paper_truth(effect, params, key, dt)
    return None if truth is None else (truth[0], float(truth[1]), float(truth[2]))


def _fitted_parameter(diagnosis: Mapping[str, Any], name: str) -> float | None:
    """Return the chosen candidate's fitted ``name`` (an effect or a linear parameter)."""
    if name in (diagnosis.get("params") or {}):
        return float(diagnosis["params"][name])
    for candidate in diagnosis.get("candidates") or []:
        if (
            candidate["module"] == diagnosis["module"]
            and candidate["effect"] == diagnosis["effect"]
        ):
            value = (candidate.get("linear_params") or {}).get(name)
            return None if value is None else float(value)
    return None


def _parameter_columns(key, diagnosis, effect_ok: bool) -> dict[str, Any]:
    """Return ``param_name, param_true, param_fitted, param_error`` of a right diagnosis.

    ``param_error = |fitted − true| / |true − reference|`` (the error relative to the effect's
    size; relative to the value for a saturation level); NaN when not comparable.
    """
    out = {"param_name": None, "param_true": math.nan, "param_fitted": math.nan}
    out.update(param_error=math.nan, param_low=math.nan, param_high=math.nan)
    dt = float((diagnosis.get("recording") or {}).get("dt") or key.get("dt") or math.nan)
    truth = true_parameter(key, dt) if effect_ok and key["expected_effect"] != NONE else None
    if truth is None:
        return out
    name, value, reference = truth
    fitted = _fitted_parameter(diagnosis, name)
    size = abs(value) if math.isinf(reference) else abs(value - reference)
    out.update(param_name=name, param_true=value)
    if fitted is not None and size > 0:
        out.update(param_fitted=fitted, param_error=abs(fitted - value) / size)
    bounds = (diagnosis.get("param_intervals") or {}).get(name)
    if fitted is not None and bounds is not None and None not in bounds:
        out.update(param_low=float(bounds[0]), param_high=float(bounds[1]))
    return out


def _refit_shrink(diagnosis: Mapping[str, Any]) -> float | None:
    """Return the excess shrink (%) of the linear re-fit alone: ``gap_before → gap_refit``.

    The part of a candidate's excess shrink that the own share does not credit to the effect
    (docs/gap.md §How far); None without a chosen effect.
    """
    before, refit = diagnosis.get("gap_before"), diagnosis.get("gap_refit")
    if before is None or refit is None:
        return None
    floor = (diagnosis["modules"][diagnosis["module"]].get("noise_floor")) or 0.0
    excess_before = math.sqrt(max(before * before - floor * floor, 0.0))
    if excess_before <= 0:
        return None
    excess_refit = math.sqrt(max(refit * refit - floor * floor, 0.0))
    return 100.0 * (1.0 - excess_refit / excess_before)


def _family_names() -> tuple[str, ...]:
    """Return the benchmark families of other physics (imported late: families imports this)."""
    from dtwin.gapbench.families import FAMILIES

    return tuple(FAMILIES)


def score_cases(cases: Iterable[tuple[str, Mapping[str, Any], Mapping[str, Any]]]) -> pd.DataFrame:
    """Return one row per case from ``(case name, key, diagnosis)`` triples (see the columns)."""
    rows = []
    for name, key, diagnosis in cases:
        expected = key["expected_effect"]
        truth_module = key["module"] if expected != NONE else None
        module_ok = diagnosis["module"] == truth_module
        accepted = key.get("accepted_effects") or [expected]  # friction: either name
        effect_ok = bool(module_ok and diagnosis["effect"] in accepted)
        table_case = key.get("family") in _family_names()
        if table_case:  # a twin table's answer: located in the unit, named at the right place
            from dtwin.gapbench.families import score_family_case

            scored = score_family_case(key, diagnosis)
            module_ok = bool(scored["located"]) if expected != NONE else module_ok
            effect_ok = bool(scored["named"] and (expected != NONE or module_ok))
        rows.append(
            {
                "case": name,
                "family": key.get("family", "paper"),
                "arm": key.get("arm", DEFAULT_ARM),
                "effect": key["effect"],
                "module": truth_module,
                "expected_effect": expected,
                "in_list": bool(key["in_list"]),
                "magnitude": float(key["magnitude"]),
                "snr": key.get("snr"),
                "n_samples": int(key["n_samples"]),
                "diagnosed_module": diagnosis["module"],
                "diagnosed_effect": diagnosis["effect"],
                "confidence": diagnosis.get("confidence"),
                **{column: diagnosis.get(column) for column in SHRINK_COLUMNS},
                "excess_clipped": diagnosis.get("excess_clipped"),
                "refit_shrink_pct": None if table_case else _refit_shrink(diagnosis),
                "kpi_shrink_pct": diagnosis.get("kpi_shrink_pct"),
                "module_ok": bool(module_ok),
                "effect_ok": effect_ok,
                **_second_effect_columns(key, diagnosis),
                **_parameter_columns(key, diagnosis, effect_ok and not table_case),
            }
        )
    return pd.DataFrame(rows)


def _second_effect_columns(key: Mapping[str, Any], diagnosis: Mapping[str, Any]) -> dict:
    """Return ``also_needed`` (``module:effect; ...``) and ``second_named`` (two-effect cases).

    A two-effect case's key names both effects (``effect = "two__<a>+<b>"``) and expects the
    larger; ``second_named`` is True when ``also_needed`` names the other one (any module),
    None for every other case. A twin table's diagnosis (``dtwin.gap.table/1``) lists the other
    units with a gap of their own by name only, which ``also_needed`` keeps as they are.
    """
    others = diagnosis.get("also_needed") or []
    named = [o if isinstance(o, str) else f"{o['module']}:{o['effect']}" for o in others]
    second = None
    if key.get("arm") == TWO_ARM:
        pair = str(key["effect"]).split("__")[-1].split("+")
        rest = [e for e in pair if e != key["expected_effect"]] or pair[1:]
        second = bool(rest) and any(
            isinstance(o, Mapping) and o["effect"] == rest[0] for o in others
        )
    return {"also_needed": "; ".join(named), "second_named": second}


def _rate(flags: pd.Series) -> dict[str, Any]:
    """Return ``{k, n, rate, low, high}``: a proportion with its Wilson 95 % interval."""
    k, n = int(flags.astype(bool).sum()), int(len(flags))
    low, high = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None, "low": low, "high": high}


def _labelled(table: pd.DataFrame) -> pd.Series:
    """Return, per case, whether its answer names a catalogue effect (not none/unexplained)."""
    if "diagnosed_effect" not in table:
        return pd.Series(False, index=table.index)
    answers = table["diagnosed_effect"]
    return answers.notna() & ~answers.isin([NONE, UNEXPLAINED])


def _second_effect_flags(table: pd.DataFrame) -> dict[str, pd.Series]:
    """Return ``second_effect_named`` (two-effect cases) and ``false_second_effect`` (others).

    ``second_effect_named``: the diagnosis says a second effect is needed and names it;
    ``false_second_effect``: a one-effect or ``none`` case told a second effect is needed.
    """
    if "also_needed" not in table:
        return {}
    two = table.arm == TWO_ARM
    return {
        "second_effect_named": table[two].second_named.fillna(False).astype(bool),
        "false_second_effect": table[~two].also_needed.fillna("").astype(bool),
    }


def _median(values: pd.Series) -> float | None:
    values = pd.to_numeric(values, errors="coerce").dropna()
    return float(values.median()) if len(values) else None


def reliability_table(table: pd.DataFrame) -> list[dict[str, Any]]:
    """Return the reliability table: per confidence bin, mean confidence against accuracy.

    Over cases whose diagnosis names an effect (a confidence exists); accuracy is the share
    diagnosed right, with its Wilson interval; ``gap = |accuracy − mean confidence|``. Bins
    :data:`CONFIDENCE_BINS`, closed on the right (the first also on the left); empty bins are
    left out.
    """
    confidence = pd.to_numeric(table.get("confidence"), errors="coerce")
    named = table[confidence.notna()].assign(confidence=confidence[confidence.notna()])
    edges = list(CONFIDENCE_BINS)
    labels = [f"({a:g}, {b:g}]" for a, b in itertools.pairwise(edges)]
    labels[0] = f"[{edges[0]:g}, {edges[1]:g}]"
    bins = pd.cut(named.confidence, edges, labels=labels, include_lowest=True)
    rows = []
    for label, group in named.groupby(bins, observed=True):
        rate = _rate(group.effect_ok)
        mean_confidence = float(group.confidence.mean())
        rows.append(
            {
                "bin": str(label),
                "mean_confidence": mean_confidence,
                **rate,
                "gap": abs(rate["rate"] - mean_confidence),
            }
        )
    return rows


def _case_numbers(table: pd.DataFrame) -> pd.Series | None:
    """Return each case's number ``NN`` (of ``<type>_NN``), or None without a ``case`` column."""
    if "case" not in table:
        return None
    return pd.to_numeric(table["case"].astype(str).str.rsplit("_", n=1).str[-1], errors="coerce")


def _max_gap(rows: list[dict[str, Any]], min_answers: int) -> float | None:
    gaps = [row["gap"] for row in rows if row["n"] >= min_answers]
    return max(gaps) if gaps else None


def calibration_metrics(
    table: pd.DataFrame, min_answers: int = CALIBRATION_MIN_ANSWERS
) -> dict[str, Any] | None:
    """Return the confidence's reliability on the cases it was fitted on and on the others.

    The confidence map (:data:`dtwin.gap.confidence.STEPS`) was fitted on the answers of the
    cases numbered :data:`~dtwin.gap.confidence.FITTING_CASES`; the **checking** set is every
    other case (other seeds), every family together. Each set gets its
    :func:`reliability_table` and ``max_gap``: the largest ``|accuracy − mean confidence|``
    over its bins of at least ``min_answers`` answers (None when no bin has that many); the
    target (docs/gap.md §Targets) is the checking set's. None when the table names no cases.
    """
    numbers = _case_numbers(table)
    if numbers is None:
        return None
    fitting = numbers.isin(FITTING_CASES)
    out: dict[str, Any] = {"min_answers": int(min_answers)}
    for name, part in (("fitting", table[fitting]), ("checking", table[~fitting]), ("all", table)):
        rows = reliability_table(part)
        out[name] = {
            "n_answers": int(sum(row["n"] for row in rows)),
            "reliability": rows,
            "max_gap": _max_gap(rows, min_answers),
        }
    return out


def _parameter_errors(right: pd.DataFrame) -> dict[str, Any]:
    """Return the median parameter error per effect (with n) and over every effect."""
    errors = right.dropna(subset=["param_error"])
    per_effect = {
        effect: {"median": float(group.param_error.median()), "n": int(len(group))}
        for effect, group in errors.groupby("effect")
    }
    return {
        "median_parameter_error": float(errors.param_error.median()) if len(errors) else None,
        "n_parameter_errors": int(len(errors)),
        "parameter_error_by_effect": per_effect,
        **_interval_coverage(right),
    }


def _interval_coverage(right: pd.DataFrame) -> dict[str, Any]:
    """Return how often the answer's 95 % interval holds the true parameter, overall and per effect.

    Over right diagnoses with a true catalogue parameter (§Scores) and an interval for it:
    ``interval_coverage`` ``{k, n, rate, low, high}`` (Wilson 95 %), ``interval_coverage_by_effect``
    the same per effect, and ``interval_missing``, right diagnoses with a true parameter but no
    interval (a parameter the data did not determine).
    """
    if "param_low" not in right:
        return {"interval_coverage": None, "interval_coverage_by_effect": {}}
    scored = right.dropna(subset=["param_error"])
    has = scored.dropna(subset=["param_low", "param_high"])
    inside = (has.param_low <= has.param_true) & (has.param_true <= has.param_high)
    return {
        "interval_coverage": _rate(inside),
        "interval_coverage_by_effect": {
            effect: _rate(group) for effect, group in inside.groupby(has.effect)
        },
        "interval_missing": int(len(scored) - len(has)),
    }


def _shrink_metrics(right: pd.DataFrame) -> dict[str, Any]:
    """Return the three shrinks' medians over right in-list diagnoses, and the clipped count.

    ``median_refit_shrink_pct``: the excess shrink of the linear re-fit alone (what the own
    share does not credit to the effect), over right diagnoses other than
    ``parameter_mismatch`` (for which the re-fit is the effect).
    """
    clipped = right.excess_clipped.astype("boolean").fillna(False) if len(right) else right
    return {
        "n_shrinks": int(len(right)),
        **{f"median_{column}": _median(right[column]) for column in SHRINK_COLUMNS},
        "n_excess_clipped": int(clipped.sum()) if len(right) else 0,
        # the linear re-fit's share, over effects other than the re-fit itself
        "median_refit_shrink_pct": _median(
            right[right.effect != PARAMETER_MISMATCH]["refit_shrink_pct"]
        )
        if "refit_shrink_pct" in right
        else None,
        "median_kpi_shrink_pct": _median(right.kpi_shrink_pct),
    }


def _family_metrics(table: pd.DataFrame) -> dict[str, Any]:
    """Return one family's (or arm's) accuracies, shrinks, parameter errors and reliability.

    ``module_accuracy``: right module (or null for ``none``) over cases with an effect;
    ``effect_accuracy``: right module and effect over in-list cases; ``none_accuracy``;
    ``unexplained_accuracy``: out-of-list cases answered ``unexplained`` in the right module;
    ``out_of_list_labelled``: out-of-list cases answered with a catalogue effect instead (a
    wrong label; docs/gap.md §Scores: arm (f) allows at most 20 %); ``intervals``: each of them as
    ``{k, n, rate, low, high}`` (Wilson 95 %); the three shrinks' medians over in-list cases
    diagnosed right (docs/gap.md §Scores).
    """
    with_effect = table[table.expected_effect != NONE]
    in_list = table[table.in_list]
    right = in_list[in_list.effect_ok]
    groups = {
        "module_accuracy": with_effect.module_ok,
        "effect_accuracy": in_list.effect_ok,
        "none_accuracy": table[table.expected_effect == NONE].effect_ok,
        "unexplained_accuracy": table[table.expected_effect == UNEXPLAINED].effect_ok,
        "out_of_list_labelled": _labelled(table[table.expected_effect == UNEXPLAINED]),
        **_second_effect_flags(table),
    }
    intervals = {name: _rate(flags) for name, flags in groups.items()}
    bins = pd.cut(table.magnitude, list(MAGNITUDE_BINS), include_lowest=True)
    by_magnitude = with_effect.groupby(bins[with_effect.index], observed=False).effect_ok
    reliability = reliability_table(table)
    gaps = [row["gap"] for row in reliability]
    return {
        "n_cases": len(table),
        "cases_per_effect": table.groupby("effect").size().to_dict(),
        **{name: interval["rate"] for name, interval in intervals.items()},
        "intervals": intervals,
        **_shrink_metrics(right),
        **_parameter_errors(right),
        "reliability": reliability,
        "max_calibration_gap": max(gaps) if gaps else None,
        "accuracy_by_effect": {
            effect: _rate(group.effect_ok) for effect, group in table.groupby("effect")
        },
        "accuracy_by_magnitude": {
            str(interval): {**_rate(group), "edges": [float(interval.left), float(interval.right)]}
            for interval, group in by_magnitude
        },
    }


def _with_arms(table: pd.DataFrame) -> dict[str, Any]:
    """Return :func:`_family_metrics` of ``table`` with ``arms``: the same per arm."""
    metrics = _family_metrics(table)
    arms = table["arm"] if "arm" in table else pd.Series(DEFAULT_ARM, table.index)
    metrics["arms"] = {
        str(arm): _family_metrics(table[arms == arm]) for arm in sorted(arms.unique())
    }
    return metrics


def benchmark_metrics(table: pd.DataFrame) -> dict[str, Any]:
    """Return the benchmark's metrics, the rig family's apart, each family's arms apart.

    The top-level metrics are the paper asset's cases (family ``paper``); ``rig`` holds the same
    metrics for the rig family (docs/gap.md §Rig family), or None when it has no case. Each has
    ``arms``: the same metrics per value of the ``arm`` column (one arm ``default`` when the
    keys name none).
    """
    table = table.reset_index(drop=True)
    family = table["family"] if "family" in table else pd.Series("paper", table.index)
    metrics = _with_arms(table[family == "paper"])
    rig = table[family == "rig"]
    metrics["rig"] = _with_arms(rig) if len(rig) else None
    metrics["families"] = {
        name: _with_arms(table[family == name])
        for name in _family_names()
        if (family == name).any()
    }
    metrics["calibration"] = calibration_metrics(table)
    metrics["interval_coverage_all"] = _interval_coverage(table[table.in_list & table.effect_ok])
    return metrics


def _target_met(name: str, target: float, observed: float | None) -> bool:
    if observed is None:
        return False
    return bool(observed <= target) if name in CEILINGS else bool(observed >= target)


def benchmark_checks(table: pd.DataFrame, metrics: Mapping[str, Any]) -> list[Check]:
    """Return the artifact's checks: validity (cases scored) and the targets as claims.

    The targets are :data:`TARGETS` (docs/gap.md §Targets); those in :data:`CEILINGS` are met
    at or below the target, the others at or above it.
    """
    checks = [
        Check(
            "cases_scored",
            "validity",
            "every generated case has a diagnosis",
            "n_cases > 0",
            int(len(table)),
            bool(len(table) > 0),
        )
    ]
    calibration = metrics.get("calibration")
    if calibration is not None:
        gap = calibration["checking"]["max_gap"]
        target = TARGETS["max_calibration_gap"]
        checks.append(
            Check(
                "target_calibration_checking_set",
                "target",
                "docs/gap.md target: on the cases the confidence was not fitted on (every "
                f"family), every bin of >= {calibration['min_answers']} answers within "
                f"{target} of its accuracy ({calibration['checking']['n_answers']} answers)",
                target,
                gap,
                _target_met("max_calibration_gap", target, gap),
            )
        )
    families = [("", TARGETS, metrics, "docs/gap.md target")]
    if metrics.get("rig"):
        families.append(("rig_", RIG_TARGETS, metrics["rig"], "docs/gap.md rig-family target"))
    for name, observed in (metrics.get("families") or {}).items():
        source = f"docs/gap.md {name}-family target"
        families.append((f"{name}_", FAMILY_TARGETS, observed, source))
    for prefix, targets, observed_metrics, source in families:
        for name, target in targets.items():
            observed = observed_metrics.get(name)
            relation = "<=" if name in CEILINGS else ">="
            checks.append(
                Check(
                    f"target_{prefix}{name}",
                    "target",
                    f"{source}: {name} {relation} {target} ({observed_metrics['n_cases']} cases)",
                    target,
                    observed,
                    _target_met(name, target, observed),
                )
            )
    return checks
