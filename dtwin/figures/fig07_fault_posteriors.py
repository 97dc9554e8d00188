"""Paper Fig. 7: Hungarian-mapped regime posteriors of the fault scenario, schedule overlaid."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dtwin.artifacts import FigureArtifact, validity_finite, validity_probabilities
from dtwin.claim_criteria import regime_spans
from dtwin.fault_claim_criteria import fault_claims, onset_lags
from dtwin.fault_injection import REGIMES
from dtwin.figures._style import (
    OURS_COLOR,
    R_COLOR,
    REGIME_COLORS,
    label_cells,
    new_figure,
    panel_title,
    unitless,
)
from dtwin.reference.columns import R_RESTART_AGREEMENT_COLUMN
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["fig07_fault_posteriors", "plot_fault_posteriors"]


def _strip(ax, t: np.ndarray, labels: np.ndarray, title: str) -> None:
    codes = np.array([REGIMES.index(label) if label in REGIMES else -1 for label in labels])
    colors = [REGIME_COLORS[r] for r in REGIMES]
    masked = np.ma.masked_less(codes, 0)
    step = t[1] - t[0]
    ax.imshow(
        masked[None, :],
        aspect="auto",
        cmap=ListedColormap(colors),
        vmin=-0.5,
        vmax=len(REGIMES) - 0.5,
        extent=(t[0], t[-1] + step, 0, 1),
        interpolation="nearest",
    )
    ax.set_yticks([0.5], [title])
    ax.tick_params(axis="y", length=0)
    ax.grid(False)


def _draw_posteriors(figure: Figure, grid: Any, posteriors: pd.DataFrame) -> None:
    """Panel A: the schedule and mapped Viterbi strips over the stacked mapped posteriors."""
    t = posteriors["t"].to_numpy()
    ax_truth = figure.add_subplot(grid[0])
    _strip(ax_truth, t, posteriors["regime"].to_numpy(), "schedule")
    ax_truth.tick_params(labelbottom=False)
    panel_title(ax_truth, "A", "Hungarian-mapped smoothed posteriors under the fault schedule")
    ax_path = figure.add_subplot(grid[1], sharex=ax_truth)
    _strip(ax_path, t, posteriors["mapped_regime"].to_numpy(), "Viterbi")
    ax_path.tick_params(labelbottom=False)
    ax = figure.add_subplot(grid[2], sharex=ax_truth)
    ax.stackplot(
        t,
        [posteriors[f"p_{r}"].to_numpy() for r in REGIMES],
        colors=[REGIME_COLORS[r] for r in REGIMES],
        labels=list(REGIMES),
        lw=0,
        alpha=0.9,
    )
    for _, start, _ in regime_spans(t, posteriors["regime"])[1:]:
        for axis in (ax_truth, ax_path, ax):
            axis.axvline(start, color="black", lw=0.8, ls="--")
    ax.set_ylim(0, 1)
    ax.set_xlim(t[0], t[-1] + (t[1] - t[0]))
    ax.set_ylabel(r"$\gamma_t(\mathrm{regime})$")
    unitless(ax, "y")  # a probability
    ax.set_xlabel("time (s)")
    ax.grid(False)
    figure.legend(*ax.get_legend_handles_labels(), ncol=4, loc="outside upper right")


def _draw_confusion(
    ax: Any,
    confusion_record: Mapping[str, Any],
    scenario: Mapping[str, Any],
    r_scores: Mapping[str, float],
) -> None:
    """Panel B: the confusion matrix (predicted rows × actual columns), coloured by recall."""
    confusion = pd.DataFrame(confusion_record).T
    rows = [r for r in confusion.index]
    matrix = confusion.loc[rows, list(REGIMES)].to_numpy(dtype=float)
    totals = matrix.sum(axis=0, keepdims=True)
    recall = np.divide(matrix, totals, out=np.zeros_like(matrix), where=totals > 0)
    ax.imshow(recall, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(REGIMES)), list(REGIMES), rotation=25, ha="right")
    ax.set_yticks(range(len(rows)), rows)
    ax.set_xlabel("actual regime")
    ax.set_ylabel("predicted (Viterbi, mapped)")
    ax.grid(False)
    label_cells(ax, matrix, "{:.0f}", recall > 0.5, fontsize=7.5)
    words = ("acc", "F1", "κ")
    keys = ("accuracy", "macro_f1", "kappa")
    ours = ", ".join(f"{w} {scenario[k]:.3f}" for w, k in zip(words, keys, strict=True))
    theirs = ", ".join(f"{w} {r_scores[k]:.3f}" for w, k in zip(words, keys, strict=True))
    panel_title(ax, "B", f"Counts, colour = recall\nours: {ours}\nR:    {theirs}")


def _draw_restarts(ax: Any, restart_records: list, r_accuracy: float) -> None:
    """Panel C: accuracy against log-likelihood of every usable EM start, R's best as a line."""
    restarts = pd.DataFrame(restart_records).dropna(subset=["accuracy"])
    points = (
        restarts.assign(ll=restarts["log_likelihood"].round(1), acc=restarts["accuracy"].round(4))
        .groupby(["ll", "acc"])
        .size()
        .reset_index(name="n")
    )
    ax.scatter(points["ll"], points["acc"], color=OURS_COLOR, s=8 + 6 * points["n"])
    for row in points.itertuples():
        if row.n > 1:
            ax.annotate(
                f"×{row.n}",
                (row.ll, row.acc),
                textcoords="offset points",
                xytext=(4, 2),
                fontsize=7,
            )
    ax.xaxis.set_major_locator(MaxNLocator(4))
    ax.axhline(r_accuracy, color=R_COLOR, ls="--", lw=0.8)
    ax.annotate(
        "R's best start, on R's data",
        (0.0, r_accuracy),
        xycoords=("axes fraction", "data"),
        xytext=(2, 2),
        textcoords="offset points",
        fontsize=7,
        color="#555555",
        va="bottom",
    )
    low = min(float(points["acc"].min()), r_accuracy)
    ax.set_ylim(low - 0.05, 1.0)
    ax.set_xlabel("log-likelihood of the start")
    ax.set_ylabel("accuracy")
    unitless(ax, "xy")
    panel_title(ax, "C", f"Every EM start, scored ({len(restarts)} usable)")


def plot_fault_posteriors(
    posteriors: pd.DataFrame, scenario: Mapping[str, Any], r_scores: Mapping[str, float]
) -> Figure:
    """Draw paper Fig. 7 and its extra panels.

    The mapped posteriors, the schedule and Viterbi strips, the confusion matrix and the
    accuracy of every EM start.

    Parameters
    ----------
    posteriors : DataFrame
        ``t`` (s), ``regime``, ``mapped_regime``, ``p_<regime>`` per regime.
    scenario : mapping
        The configured drift origin's entry of the fault summary (``accuracy``, ``macro_f1``,
        ``kappa``, ``confusion``, ``restarts``).
    r_scores : mapping
        R's ``accuracy``, ``macro_f1``, ``kappa``.
    """
    figure = new_figure(5.6)
    top, bottom = figure.add_gridspec(2, 1, height_ratios=[1, 1.25])
    _draw_posteriors(figure, top.subgridspec(3, 1, height_ratios=[0.12, 0.12, 1]), posteriors)
    lower = bottom.subgridspec(1, 2, width_ratios=[1, 1])
    _draw_confusion(figure.add_subplot(lower[0]), scenario["confusion"], scenario, r_scores)
    _draw_restarts(figure.add_subplot(lower[1]), scenario["restarts"], r_scores["accuracy"])
    return figure


def fig07_fault_posteriors(
    posteriors: pd.DataFrame,
    summary: Mapping[str, Any],
    r_scores: Mapping[str, float],
    r_multistart: pd.DataFrame,
    crosscheck: CrosscheckResult,
) -> FigureArtifact:
    """Paper Fig. 7 with accuracy, macro-F1, κ for both drift origins and over the EM starts.

    Parameters
    ----------
    posteriors : DataFrame
        ``results/faults/posteriors.csv``.
    summary : mapping
        ``results/faults/summary.json``.
    r_scores : mapping
        R's ``accuracy``, ``macro_f1``, ``kappa``
        (:func:`dtwin.reference.loaders.load_r_classification`).
    r_multistart : DataFrame
        ``multistart_restarts_K4.csv`` as R wrote it (reported as is).
    crosscheck : CrosscheckResult
        :func:`dtwin.reference.hungarian_crosscheck.crosscheck_hungarian`.
    """
    origin = summary["drift_origin"]
    scenario = summary["origins"][origin]
    r_scores = dict(r_scores)
    figure = plot_fault_posteriors(posteriors, scenario, r_scores)
    ours = {key: scenario[key] for key in r_scores}
    lags = onset_lags(posteriors)
    probabilities = posteriors[[f"p_{r}" for r in REGIMES]].to_numpy()
    checks = [
        validity_finite("posteriors_finite", "mapped posteriors", probabilities),
        validity_probabilities("mapped_are_probabilities", "mapped posteriors", probabilities),
        *fault_claims(posteriors, scenario, r_scores, origin),
        *crosscheck.checks,
    ]
    per_origin = {
        name: {
            key: entry[key]
            for key in (
                "accuracy",
                "macro_f1",
                "kappa",
                "nominal_sensor_share",
                "mapping",
                "confusion",
                "per_class",
                "restart_accuracy",
            )
        }
        | {"log_likelihood": entry["model"]["log_likelihood"]}
        for name, entry in summary["origins"].items()
    }
    metrics = {
        "drift_origin": origin,
        "n_samples": len(posteriors),
        "scores": ours,
        "r_scores": r_scores,
        "by_drift_origin": per_origin,
        "onset_lag_s": lags,
        "restarts": scenario["restarts"],
        "r_restarts": r_multistart.to_dict(orient="records"),
        "r_restart_agreement_pct": {
            "min": float(r_multistart[R_RESTART_AGREEMENT_COLUMN].min()),
            "max": float(r_multistart[R_RESTART_AGREEMENT_COLUMN].max()),
        },
        "model": {
            key: scenario["model"][key]
            for key in ("log_likelihood", "bic", "n_iter", "converged", "transmat", "means_z")
        },
        "crosscheck_r": crosscheck.metrics,
    }
    return FigureArtifact(
        "fig07_fault_posteriors",
        figure,
        metrics,
        checks,
        paper_figure="Fig. 7",
        caption=(
            f"Accuracy {ours['accuracy']:.3f} vs R's {r_scores['accuracy']:.3f}, κ "
            f"{ours['kappa']:.3f} vs {r_scores['kappa']:.3f}: within the draw (our noise "
            "comes from numpy); on R's Viterbi path our mapping gives R's confusion exactly."
        ),
        provenance="results/faults/posteriors.csv, summary.json (fault_regimes rule); "
        "R's classification scores and multistart table",
    )
