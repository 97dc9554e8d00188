"""Scoring diagnoses against the withheld truth: the ``gap_benchmark`` artifact.

Specification: docs/gap.md §Benchmark (cases, rules) and §Targets.

:func:`score_cases` joins each case's key (the truth from :mod:`dtwin.gap.generator`) with its
``diagnosis.json`` and returns one row per case; :func:`benchmark_metrics` gives the accuracies
docs/gap.md §Targets sets targets for; :func:`benchmark_checks` states them as checks. The
figure is drawn by :mod:`dtwin.figures.gap_benchmark`.

Table columns (:func:`score_cases`): ``case, family, effect, module, expected_effect, in_list,
magnitude, snr, n_samples, diagnosed_module, diagnosed_effect, shrink_pct, raw_shrink_pct,
kpi_shrink_pct, module_ok, effect_ok``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from dtwin.artifacts import Check
from dtwin.gap.effects import NONE, UNEXPLAINED

__all__ = ["TARGETS", "RIG_TARGETS", "score_cases", "benchmark_metrics", "benchmark_checks"]

#: The targets on the full benchmark (docs/gap.md §Targets) (≥ 10 cases per effect).
TARGETS: dict[str, float] = {
    "module_accuracy": 0.95,
    "effect_accuracy": 0.90,
    "none_accuracy": 0.90,
    "unexplained_accuracy": 0.80,
    "median_shrink_pct": 85.0,
}

#: The rig family's targets (docs/gap.md §Rig family) (≥ 30 cases).
RIG_TARGETS: dict[str, float] = {
    "module_accuracy": 0.90,
    "effect_accuracy": 0.85,
    "median_shrink_pct": 80.0,
}


def score_cases(cases: Iterable[tuple[str, Mapping[str, Any], Mapping[str, Any]]]) -> pd.DataFrame:
    """Return one row per case from ``(case name, key, diagnosis)`` triples (see the columns)."""
    rows = []
    for name, key, diagnosis in cases:
        expected = key["expected_effect"]
        truth_module = key["module"] if expected != NONE else None
        module_ok = diagnosis["module"] == truth_module
        rows.append(
            {
                "case": name,
                "family": key.get("family", "paper"),
                "effect": key["effect"],
                "module": truth_module,
                "expected_effect": expected,
                "in_list": bool(key["in_list"]),
                "magnitude": float(key["magnitude"]),
                "snr": key.get("snr"),
                "n_samples": int(key["n_samples"]),
                "diagnosed_module": diagnosis["module"],
                "diagnosed_effect": diagnosis["effect"],
                "shrink_pct": diagnosis["shrink_pct"],
                "raw_shrink_pct": diagnosis["raw_shrink_pct"],
                "kpi_shrink_pct": diagnosis["kpi_shrink_pct"],
                "module_ok": bool(module_ok),
                "effect_ok": bool(module_ok and diagnosis["effect"] == expected),
            }
        )
    return pd.DataFrame(rows)


def _mean(values: pd.Series) -> float | None:
    return float(values.mean()) if len(values) else None


def benchmark_metrics(table: pd.DataFrame) -> dict[str, Any]:
    """Return the benchmark's accuracies and shrink statistics, the rig family's apart.

    The top-level metrics are the paper asset's cases (family ``paper``); ``rig`` holds the same
    metrics for the rig family (docs/gap.md §Rig family), or None when it has no case.
    """
    paper = table[table.family == "paper"] if "family" in table else table
    rig = table[table.family == "rig"] if "family" in table else table.iloc[:0]
    metrics = _family_metrics(paper)
    metrics["rig"] = _family_metrics(rig) if len(rig) else None
    return metrics


def _family_metrics(table: pd.DataFrame) -> dict[str, Any]:
    """Return one family's accuracies and shrink statistics.

    ``module_accuracy``: right module (or null for ``none``) over cases with an effect;
    ``effect_accuracy``: right module and effect over in-list cases; ``none_accuracy``;
    ``unexplained_accuracy``: out-of-list cases answered ``unexplained`` in the right module;
    ``median_shrink_pct``: median held-out excess shrink over in-list cases diagnosed right.
    """
    with_effect = table[table.expected_effect != NONE]
    in_list = table[table.in_list]
    none = table[table.expected_effect == NONE]
    out = table[(table.expected_effect == UNEXPLAINED)]
    right = in_list[in_list.effect_ok]
    shrinks = pd.to_numeric(right.shrink_pct, errors="coerce").dropna()
    per_effect = table.groupby("effect").effect_ok.mean().round(3).to_dict()
    bins = pd.cut(table.magnitude, [0, 0.25, 0.5, 0.75, 1.0], include_lowest=True)
    by_magnitude = table[table.expected_effect != NONE].groupby(bins, observed=False).effect_ok
    return {
        "n_cases": len(table),
        "cases_per_effect": table.groupby("effect").size().to_dict(),
        "module_accuracy": _mean(with_effect.module_ok),
        "effect_accuracy": _mean(in_list.effect_ok),
        "none_accuracy": _mean(none.effect_ok),
        "unexplained_accuracy": _mean(out.effect_ok),
        "median_shrink_pct": float(shrinks.median()) if len(shrinks) else None,
        "median_raw_shrink_pct": float(pd.to_numeric(right.raw_shrink_pct).median())
        if len(right)
        else None,
        "median_kpi_shrink_pct": float(pd.to_numeric(right.kpi_shrink_pct).dropna().median())
        if right.kpi_shrink_pct.notna().any()
        else None,
        "accuracy_by_effect": per_effect,
        "accuracy_by_magnitude": {
            str(k): (None if np.isnan(v) else round(float(v), 3))
            for k, v in by_magnitude.mean().items()
        },
    }


def benchmark_checks(table: pd.DataFrame, metrics: Mapping[str, Any]) -> list[Check]:
    """Return the artifact's checks: validity (cases scored) and the targets as claims.

    The targets are :data:`TARGETS` (docs/gap.md §Targets).
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
    families = [("", TARGETS, metrics, "docs/gap.md target")]
    if metrics.get("rig"):
        families.append(("rig_", RIG_TARGETS, metrics["rig"], "docs/gap.md rig-family target"))
    for prefix, targets, observed_metrics, source in families:
        for name, target in targets.items():
            observed = observed_metrics.get(name)
            checks.append(
                Check(
                    f"target_{prefix}{name}",
                    "claim",
                    f"{source}: {name} >= {target} ({observed_metrics['n_cases']} cases)",
                    target,
                    observed,
                    bool(observed is not None and observed >= target),
                )
            )
    return checks
