"""The gap diagnoser's benchmark figure (not a paper figure; docs/gap.md §Benchmark).

One function per panel, so a panel (a rig family, say) can be added without touching the
others: :func:`draw_confusion` (true effect × diagnosed effect, coloured by the share of the
row), :func:`draw_shrinks` (the three shrinks of each right diagnosis on the scoring part, the
effect's own share first, one mark per case, on the confusion matrix's rows),
:func:`draw_accuracy` (effect accuracy per magnitude bin with Wilson intervals and the number
of cases), :func:`draw_reliability` (the reliability table: accuracy against mean confidence
per confidence bin) and :func:`draw_parameter_errors` (fitted against true parameter, one dot
per case), and with several arms or a rig family :func:`draw_arms` (each arm's and family's
accuracies). The scoring, the intervals included, is :mod:`dtwin.gapbench.scores`'s; this module
only draws its table and metrics.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from dtwin.artifacts import Check, FigureArtifact
from dtwin.figures._style import OURS_COLOR, R_COLOR, new_figure, panel_title, unitless

__all__ = [
    "draw_confusion",
    "draw_shrinks",
    "draw_accuracy",
    "draw_reliability",
    "draw_parameter_errors",
    "draw_arms",
    "arm_groups",
    "plot_gap_benchmark",
    "gap_benchmark",
]

#: How each shrink is drawn: (column, label, marker, filled, vertical offset on its row).
_SHRINK_MARKS = (
    ("own_shrink_pct", "own share", "o", True, 0.0),
    ("raw_shrink_pct", "raw error", "o", False, -0.28),
    ("excess_shrink_pct", "excess over noise", "x", True, 0.28),
)

#: Shrinks below this are drawn at it (a candidate can make the gap worse without bound).
_SHRINK_AXIS_LOW = -50.0


def _rows(table: pd.DataFrame) -> list[str]:
    return sorted(table.expected_effect.unique())


def draw_confusion(ax: Axes, table: pd.DataFrame) -> None:
    """Panel A: true (rows) × diagnosed (columns) effect, counts, colour = share of the row."""
    truths = _rows(table)
    answers = sorted(set(table.diagnosed_effect) | set(truths))
    matrix = pd.crosstab(table.expected_effect, table.diagnosed_effect).reindex(
        index=truths, columns=answers, fill_value=0
    )
    counts = matrix.to_numpy()
    share = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
    ax.imshow(share, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(answers)), answers, rotation=90)
    ax.set_yticks(range(len(truths)), truths)
    ax.grid(False)
    for (i, j), value in np.ndenumerate(counts):
        if value:
            ax.text(
                j,
                i,
                str(value),
                ha="center",
                va="center",
                fontsize=7,
                color="white" if share[i, j] > 0.5 else "black",
            )
    ax.set_xlabel("diagnosed effect")
    ax.set_ylabel("true effect (out-of-list → unexplained)")
    panel_title(ax, "A", "Diagnosis (colour: share of row)")


def draw_shrinks(ax: Axes, table: pd.DataFrame, target_pct: float) -> None:
    """Panel B: each right in-list diagnosis's three shrinks (scoring part), on its matrix row.

    The effect's own share (filled), the raw error (open) and the excess over the noise floor
    (cross) sit just above and below each other on the effect's row; values below
    ``_SHRINK_AXIS_LOW`` are drawn at it.
    """
    rows = {effect: i for i, effect in enumerate(_rows(table))}
    right = table[table.in_list & table.effect_ok]
    y = right.expected_effect.map(rows).to_numpy(dtype=float)
    for column, label, marker, filled, offset in _SHRINK_MARKS:
        values = pd.to_numeric(right[column], errors="coerce").to_numpy(dtype=float)
        color = OURS_COLOR if column == "own_shrink_pct" else R_COLOR
        style = {"color": color} if filled else {"facecolors": "none", "edgecolors": color}
        ax.scatter(
            np.clip(values, _SHRINK_AXIS_LOW, 100.0),
            y + offset,
            s=9,
            marker=marker,
            lw=0.7,
            zorder=3,
            label=label,
            **style,
        )
    ax.axvline(target_pct, color=R_COLOR, ls="--", lw=0.8)
    ax.set_xlim(_SHRINK_AXIS_LOW - 5, 105)
    ax.tick_params(labelleft=False)
    ax.set_xlabel("gap removed, scoring\npart (%)")
    ax.grid(axis="y", alpha=0.15)
    ax.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.3),
        fontsize=7,
        handletextpad=0.1,
        borderpad=0.2,
        frameon=False,
    )
    panel_title(ax, "B", "Shrinks")


def _rate_arrays(rates: Sequence[Mapping[str, Any]]) -> tuple[np.ndarray, ...]:
    """Return ``(rate, low, high, n)`` arrays of :func:`dtwin.gapbench.scores`'s rate entries."""
    rate = np.array([np.nan if r["rate"] is None else r["rate"] for r in rates], dtype=float)
    low = np.array([r["low"] for r in rates], dtype=float)
    high = np.array([r["high"] for r in rates], dtype=float)
    return rate, low, high, np.array([r["n"] for r in rates], dtype=int)


def _annotate_n(ax: Axes, xs: Sequence[float], ns: Sequence[int]) -> None:
    for x, count in zip(xs, ns, strict=True):
        ax.annotate(
            f"n={count}",
            (x, 0),
            xycoords=("data", "axes fraction"),
            xytext=(0, 3),
            textcoords="offset points",
            ha="center",
            va="bottom",
            fontsize=7,
        )


def _wilson_points(ax: Axes, x: np.ndarray, rates, fmt: str) -> tuple:
    """Draw rates at ``x`` with their Wilson 95 % intervals; return ``_rate_arrays(rates)``."""
    rate, low, high, n = _rate_arrays(rates)
    yerr = [rate - low, high - rate]
    ax.errorbar(x, rate, yerr=yerr, fmt=fmt, color=OURS_COLOR, ms=3.5, lw=1.0, capsize=2)
    return rate, low, high, n


def draw_accuracy(ax: Axes, metrics: Mapping[str, Any]) -> None:
    """Panel C: effect accuracy per magnitude bin, Wilson 95 % intervals, n per bin."""
    rates = list(metrics["accuracy_by_magnitude"].values())
    edges = np.array([r["edges"] for r in rates], dtype=float).reshape(-1, 2)
    centres = edges.mean(axis=1)
    _, low, _, n = _wilson_points(ax, centres, rates, "o-")
    _annotate_n(ax, centres, n)
    floor = np.nanmin(low) if np.isfinite(low).any() else 0.5
    ax.set_ylim(min(0.5, float(floor) - 0.05) - 0.08, 1.03)
    ax.set_xlim(0, 1)
    ax.set_xticks(np.unique(np.clip(edges, 0, 1)))
    ax.set_xlabel("effect magnitude\n(0 noise level, 1 strong)")
    ax.set_ylabel("effect accuracy")
    unitless(ax)
    panel_title(ax, "C", "By magnitude")


def draw_reliability(ax: Axes, metrics: Mapping[str, Any]) -> None:
    """Panel E: the reliability table, accuracy (Wilson 95 %) against mean confidence per bin.

    The diagonal is perfect calibration, the band ±10 points around it the target; the number
    of cases per bin is listed in the lower right corner, lowest confidence first.
    """
    rows = metrics["reliability"]
    line = np.array([0.0, 1.0])
    ax.fill_between(line, line - 0.1, line + 0.1, color=R_COLOR, alpha=0.15, lw=0)
    ax.plot(line, line, color=R_COLOR, lw=0.8, ls="--")
    if rows:
        confidence = np.array([r["mean_confidence"] for r in rows], dtype=float)
        _, _, _, n = _wilson_points(ax, confidence, rows, "o")
        # the bins crowd near confidence 1 (their labels overlapped on 810 cases): one line
        ax.text(
            0.97,
            0.03,
            "n: " + ", ".join(str(count) for count in n),
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
        )
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("mean confidence of the bin")
    ax.set_ylabel("accuracy")
    unitless(ax, "xy")
    panel_title(ax, "E", "Reliability")


def draw_parameter_errors(ax: Axes, table: pd.DataFrame, target: float) -> None:
    """Panel D: per effect, each right diagnosis's fitted-parameter error (one dot per case).

    ``param_error`` of :func:`dtwin.gapbench.scores.score_cases` on a log axis (at least 1e-4);
    effects whose real form has no catalogue parameter have no dot.
    """
    scored = table.dropna(subset=["param_error"]) if "param_error" in table else table.iloc[:0]
    effects = sorted(scored.effect.unique())
    rows = {effect: i for i, effect in enumerate(effects)}
    ax.scatter(
        np.maximum(scored.param_error.to_numpy(dtype=float), 1e-4),
        scored.effect.map(rows).to_numpy(dtype=float),
        s=9,
        color=OURS_COLOR,
        lw=0,
        zorder=3,
    )
    ax.axvline(target, color=R_COLOR, ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlim(5e-5, 20)
    ax.set_yticks(range(len(effects)), effects)
    ax.set_ylim(-0.6, max(len(effects), 1) - 0.4)
    ax.set_xlabel("|fitted − true| / effect size")
    unitless(ax, "x")
    ax.grid(axis="y", alpha=0.15)
    panel_title(ax, "D", "Parameter error")


#: Panel F's rows, in order: short names of the arms (dtwin/gapbench/arms.py ``ARMS``; the figures
#: layer does not import the gap layer) and the rig family.
_GROUP_LABELS = {
    "default": "default",
    "no_noise": "(a) no noise levels",
    "wrong_noise": "(b) noise levels ±25 %",
    "noisy_x": "(c) noisy x, no v, z",
    "continuous": "(d) continuous asset",
    "unseen": "(e) unseen forms",
    "near": "(f) near-catalogue",
    "two": "(g) two effects",
    "harder": "(h) continuous, coloured x",
    "rig": "rig family",
}

#: Panel F's accuracies: (metric of :func:`dtwin.gapbench.scores._family_metrics`, label, marker).
_ARM_MARKS = (
    ("module_accuracy", "module", "o"),
    ("effect_accuracy", "effect", "s"),
    ("none_accuracy", "none", "^"),
    ("unexplained_accuracy", "out-of-list → unexplained", "D"),
)


def arm_groups(metrics: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    """Return panel F's rows: ``(label, metrics)`` per arm of the paper family, then the rig family.

    Empty when there is one arm and no rig family (the default benchmark's figure keeps five
    panels then).
    """
    arms = metrics.get("arms") or {}
    order = list(_GROUP_LABELS)
    groups = [
        (_GROUP_LABELS.get(arm, arm), arms[arm])
        for arm in sorted(arms, key=lambda a: order.index(a) if a in order else len(order))
    ]
    if metrics.get("rig"):
        groups.append((_GROUP_LABELS["rig"], metrics["rig"]))
    return groups if len(groups) > 1 else []


def draw_arms(ax: Axes, groups: Sequence[tuple[str, Mapping[str, Any]]]) -> None:
    """Panel F: per arm (and the rig family) its accuracies with Wilson 95 % intervals.

    One row per group, top to bottom in the order given; a metric with no case in the group is
    not drawn. The row label gives the number of cases.
    """
    offsets = np.linspace(-0.27, 0.27, len(_ARM_MARKS))
    for (name, label, marker), offset in zip(_ARM_MARKS, offsets, strict=True):
        rows, rates = [], []
        for i, (_, group) in enumerate(groups):
            interval = group["intervals"][name]
            if interval["n"]:
                rows.append(i + offset)
                rates.append(interval)
        if not rates:
            continue
        rate, low, high, _ = _rate_arrays(rates)
        ax.errorbar(
            rate,
            rows,
            xerr=[rate - low, high - rate],
            fmt=marker,
            color=OURS_COLOR,
            mfc=OURS_COLOR if marker in ("o", "s") else "white",
            ms=3.5,
            lw=0.8,
            capsize=1.5,
            label=label,
        )
    ax.set_yticks(range(len(groups)), [f"{label} ({group['n_cases']})" for label, group in groups])
    ax.set_ylim(len(groups) - 0.5, -0.5)
    ax.set_xlim(0, 1.02)
    ax.set_xlabel("accuracy (Wilson 95 %)")
    unitless(ax, "x")
    ax.grid(axis="x", alpha=0.2)
    # above the axes, right of the title: inside, it covered the wide intervals of small arms
    ax.legend(
        loc="lower right",
        bbox_to_anchor=(1.0, 1.0),
        fontsize=7,
        ncol=2,
        frameon=False,
        borderaxespad=0.2,
    )
    panel_title(ax, "F", "By arm and family (cases)")


def plot_gap_benchmark(
    table: pd.DataFrame,
    metrics: Mapping[str, Any],
    targets: Mapping[str, float],
    no_effect: str = "none",
) -> Figure:
    """Draw the benchmark (five or six panels; the scoring is :mod:`dtwin.gapbench.scores`'s).

    Above: confusion matrix and the three shrinks on shared rows, accuracy by magnitude; below:
    the parameter errors and the reliability table; when the cases come from more than one arm
    or family, a last row with each one's accuracies (:func:`draw_arms`).

    Parameters
    ----------
    table : DataFrame
        :func:`dtwin.gapbench.scores.score_cases` (one row per case).
    metrics : mapping
        :func:`dtwin.gapbench.scores.benchmark_metrics` of the same cases.
    targets : mapping
        docs/gap.md §Targets: ``median_own_shrink_pct`` (%) and ``median_parameter_error``.
    no_effect : str
        The effect name of cases without an effect.
    """
    groups = arm_groups(metrics)
    if groups:
        figure = new_figure(7.3 + 0.17 * len(groups))
        heights = [1.5, 1.0, 0.12 * len(groups) + 0.2]
    else:
        figure = new_figure(7.0)
        heights = [1.5, 1.0]
    grid = figure.add_gridspec(
        len(heights), 3, width_ratios=[1.5, 0.75, 1.0], height_ratios=heights
    )
    ax_matrix = figure.add_subplot(grid[0, 0])
    draw_confusion(ax_matrix, table)
    draw_shrinks(
        figure.add_subplot(grid[0, 1], sharey=ax_matrix), table, targets["median_own_shrink_pct"]
    )
    draw_accuracy(figure.add_subplot(grid[0, 2]), metrics)
    draw_parameter_errors(
        figure.add_subplot(grid[1, 0:2]), table, targets.get("median_parameter_error", 0.15)
    )
    draw_reliability(figure.add_subplot(grid[1, 2]), metrics)
    if groups:
        draw_arms(figure.add_subplot(grid[2, :]), groups)
    return figure


def _others_sentence(others: int, panel_f: bool) -> str:
    """Return the caption's note on the cases of other families (not in panels A–E)."""
    if not others:
        return ""
    where = "in panel F and the JSON" if panel_f else "in the JSON only"
    return f" {others} cases of other families are {where}."


def _misses(table: pd.DataFrame, n_shown: int = 3) -> str:
    """Return " Misses: true → diagnosed (magnitude m); …" for the first wrong diagnoses."""
    wrong = table[~table.effect_ok.astype(bool)]
    if wrong.empty:
        return ""
    shown = "; ".join(
        f"{row.expected_effect} → {row.diagnosed_effect} (magnitude {row.magnitude:.2f})"
        for row in wrong.head(n_shown).itertuples()
    )
    more = f" and {len(wrong) - n_shown} more" if len(wrong) > n_shown else ""
    return f" Misses: {shown}{more}."


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.0f} %"


def _accuracy(metrics: Mapping[str, Any], name: str) -> str:
    """Return "k/n = r % [low–high %]" of ``<name>_accuracy`` (Wilson 95 %)."""
    rate = metrics["intervals"][f"{name}_accuracy"]
    if not rate["n"]:
        return "– (no case)"
    return (
        f"{rate['k']}/{rate['n']} = {_percent(rate['rate'])} "
        f"[{100 * rate['low']:.0f}–{100 * rate['high']:.0f} %]"
    )


def _pct(value: float | None) -> str:
    return "–" if value is None else f"{value:.0f} %"


def _shrinks_sentence(metrics: Mapping[str, Any]) -> str:
    """Return the caption's headline: the three shrinks' medians over right diagnoses."""
    return (
        f"the effect's own share of the gap (beyond re-fitting the linear parameters) median "
        f"{_pct(metrics['median_own_shrink_pct'])} over {metrics['n_shrinks']} right "
        f"diagnoses (scoring part); raw error {_pct(metrics['median_raw_shrink_pct'])}; excess "
        f"over noise {_pct(metrics['median_excess_shrink_pct'])} "
        f"({metrics['n_excess_clipped']} clipped at 100 %){_refit_clause(metrics)}."
    )


def _refit_clause(metrics: Mapping[str, Any]) -> str:
    refit = metrics.get("median_refit_shrink_pct")
    if refit is None:
        return ""
    return f", of which the linear re-fit alone removes a median {refit:.0f} %"


def _parameter_sentence(metrics: Mapping[str, Any]) -> str:
    """Return the caption's sentence on parameter errors and calibration."""
    error = metrics["median_parameter_error"]
    gap = metrics["max_calibration_gap"]
    return (
        f"Median parameter error {'–' if error is None else f'{100 * error:.0f} %'} "
        f"({metrics['n_parameter_errors']} cases); largest |accuracy − confidence| over "
        f"{len(metrics['reliability'])} confidence bins "
        f"{'–' if gap is None else f'{100 * gap:.0f} points'}."
    )


def gap_benchmark(
    table: pd.DataFrame,
    metrics: Mapping[str, Any],
    checks: Sequence[Check],
    targets: Mapping[str, float],
    no_effect: str = "none",
) -> FigureArtifact:
    """Return the ``gap_benchmark`` artifact: the figure, the benchmark's metrics, its checks.

    Parameters
    ----------
    table : DataFrame
        :func:`dtwin.gapbench.scores.score_cases`; only the paper asset's cases (``family``
        ``"paper"``, or every case without that column) are drawn.
    metrics : mapping
        :func:`dtwin.gapbench.scores.benchmark_metrics`.
    checks : sequence of Check
        :func:`dtwin.gapbench.scores.benchmark_checks`.
    targets : mapping
        :data:`dtwin.gapbench.scores.TARGETS` (``median_own_shrink_pct`` and
        ``median_parameter_error`` are drawn).
    no_effect : str
        The effect name of cases without an effect.
    """
    family = table["family"] if "family" in table.columns else pd.Series("paper", table.index)
    others = int((family != "paper").sum())
    table = table[family == "paper"]
    figure = plot_gap_benchmark(table, metrics, targets, no_effect)
    per_effect = sorted(set(metrics["cases_per_effect"].values()))
    caption = (
        f"{metrics['n_cases']} withheld-effect cases ({'/'.join(map(str, per_effect))} per "
        f"effect): {_shrinks_sentence(metrics)} Module {_accuracy(metrics, 'module')}, effect "
        f"{_accuracy(metrics, 'effect')}, none {_accuracy(metrics, 'none')}, out-of-list → "
        f"unexplained {_accuracy(metrics, 'unexplained')} (Wilson 95 %). "
        f"{_parameter_sentence(metrics)}" + _misses(table)
    ) + _others_sentence(others, bool(arm_groups(metrics)))
    return FigureArtifact(
        "gap_benchmark",
        figure,
        dict(metrics),
        list(checks),
        caption=caption,
        provenance="results/gap/benchmark.csv (every case's diagnosis scored against its key)",
    )
