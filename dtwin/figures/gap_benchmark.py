"""The gap diagnoser's benchmark figure (not a paper figure; docs/gap.md §Benchmark).

One function per panel, so a panel (a rig family, say) can be added without touching the
others: :func:`draw_confusion` (true effect × diagnosed effect, coloured by the share of the
row), :func:`draw_shrinks` (the held-out excess gap each right diagnosis removes, one dot per
case, on the confusion matrix's rows) and :func:`draw_accuracy` (effect accuracy per magnitude
bin with Wilson intervals and the number of cases). The scoring itself is
:mod:`dtwin.gap.benchmark`'s; this module only draws its table.
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
    "MAGNITUDE_BINS",
    "wilson_interval",
    "draw_confusion",
    "draw_shrinks",
    "draw_accuracy",
    "plot_gap_benchmark",
    "gap_benchmark",
]

#: Edges of the effect-magnitude bins (0 = barely above the noise, 1 = strong).
MAGNITUDE_BINS: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a proportion (95 % for ``z`` = 1.96); (nan, nan) when n = 0.

    Examples
    --------
    >>> [round(v, 3) for v in wilson_interval(3, 3)]
    [0.438, 1.0]
    """
    if n == 0:
        return float("nan"), float("nan")
    p = successes / n
    denominator = 1 + z**2 / n
    centre = (p + z**2 / (2 * n)) / denominator
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / denominator
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


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
    """Panel B: each right in-list diagnosis's held-out excess-gap shrink, on its matrix row."""
    rows = {effect: i for i, effect in enumerate(_rows(table))}
    right = table[table.in_list & table.effect_ok]
    shrink = pd.to_numeric(right.shrink_pct, errors="coerce")
    y = right.expected_effect.map(rows).to_numpy(dtype=float)
    ax.scatter(shrink, y, s=10, color=OURS_COLOR, alpha=0.8, lw=0, zorder=3)
    ax.axvline(target_pct, color=R_COLOR, ls="--", lw=0.8)
    ax.annotate(
        f"target {target_pct:g} %",
        (target_pct, 0),
        xycoords=("data", "axes fraction"),
        xytext=(-2, 2),
        textcoords="offset points",
        ha="right",
        va="bottom",
        fontsize=7,
        color="#555555",
    )
    ax.tick_params(labelleft=False)
    ax.set_xlabel("excess gap removed,\nheld out (%)")
    ax.grid(axis="y", alpha=0.15)
    panel_title(ax, "B", "Gap removed")


def draw_accuracy(ax: Axes, table: pd.DataFrame, no_effect: str = "none") -> None:
    """Panel C: effect accuracy per magnitude bin, Wilson 95 % intervals, n per bin."""
    scored = table[table.expected_effect != no_effect]
    bins = pd.cut(scored.magnitude, list(MAGNITUDE_BINS), include_lowest=True)
    centres = (np.asarray(MAGNITUDE_BINS[:-1]) + np.asarray(MAGNITUDE_BINS[1:])) / 2
    grouped = scored.groupby(bins, observed=False).effect_ok
    k, n = grouped.sum().to_numpy(dtype=int), grouped.size().to_numpy(dtype=int)
    rate = np.divide(k, n, out=np.full(len(n), np.nan), where=n > 0)
    intervals = np.array([wilson_interval(int(a), int(b)) for a, b in zip(k, n, strict=True)])
    ax.errorbar(
        centres,
        rate,
        yerr=[rate - intervals[:, 0], intervals[:, 1] - rate],
        fmt="o-",
        color=OURS_COLOR,
        ms=3.5,
        lw=1.0,
        capsize=2,
    )
    for x, count in zip(centres, n, strict=True):
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
    low = np.nanmin(intervals[:, 0]) if np.isfinite(intervals).any() else 0.5
    ax.set_ylim(min(0.5, float(low) - 0.05) - 0.08, 1.03)
    ax.set_xlim(0, 1)
    ax.set_xticks(MAGNITUDE_BINS)
    ax.set_xlabel("effect magnitude\n(0 noise level, 1 strong)")
    ax.set_ylabel("effect accuracy")
    unitless(ax)
    panel_title(ax, "C", "By magnitude")


def plot_gap_benchmark(table: pd.DataFrame, target_pct: float, no_effect: str = "none") -> Figure:
    """Draw the benchmark: confusion matrix and shrinks on shared rows, accuracy by magnitude.

    Parameters
    ----------
    table : DataFrame
        :func:`dtwin.gap.benchmark.score_cases` (one row per case).
    target_pct : float
        The median-shrink target of docs/gap.md §Targets, %.
    no_effect : str
        The effect name of cases without an effect (left out of panel C).
    """
    figure = new_figure(4.4)
    grid = figure.add_gridspec(1, 3, width_ratios=[1.5, 0.75, 1.0])
    ax_matrix = figure.add_subplot(grid[0])
    draw_confusion(ax_matrix, table)
    draw_shrinks(figure.add_subplot(grid[1], sharey=ax_matrix), table, target_pct)
    draw_accuracy(figure.add_subplot(grid[2]), table, no_effect)
    return figure


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
        :func:`dtwin.gap.benchmark.score_cases`; only the paper asset's cases (``family``
        ``"paper"``, or every case without that column) are drawn.
    metrics : mapping
        :func:`dtwin.gap.benchmark.benchmark_metrics`.
    checks : sequence of Check
        :func:`dtwin.gap.benchmark.benchmark_checks`.
    targets : mapping
        :data:`dtwin.gap.benchmark.TARGETS` (``median_shrink_pct`` is drawn).
    no_effect : str
        The effect name of cases without an effect.
    """
    family = table["family"] if "family" in table.columns else pd.Series("paper", table.index)
    others = int((family != "paper").sum())
    table = table[family == "paper"]
    figure = plot_gap_benchmark(table, targets["median_shrink_pct"], no_effect)
    per_effect = sorted(set(metrics["cases_per_effect"].values()))
    caption = (
        f"{metrics['n_cases']} withheld-effect cases ({'/'.join(map(str, per_effect))} per "
        f"effect): module {_percent(metrics['module_accuracy'])}, effect "
        f"{_percent(metrics['effect_accuracy'])}, none {_percent(metrics['none_accuracy'])}, "
        f"out-of-list → unexplained {_percent(metrics['unexplained_accuracy'])}, median "
        f"excess gap removed {metrics['median_shrink_pct'] or 0:.0f} %." + _misses(table)
    ) + (f" {others} cases of other families are in the JSON only." if others else "")
    return FigureArtifact(
        "gap_benchmark",
        figure,
        dict(metrics),
        list(checks),
        caption=caption,
        provenance="results/gap/benchmark.csv (every case's diagnosis scored against its key)",
    )
