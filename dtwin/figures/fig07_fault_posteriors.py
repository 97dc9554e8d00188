"""Paper Fig. 7: Hungarian-mapped regime posteriors of the fault scenario, schedule overlaid."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dtwin.artifacts import FigureArtifact, validity_finite, validity_probabilities
from dtwin.fault_injection import REGIMES
from dtwin.figures._fig07_claims import fault_claims, onset_lags
from dtwin.figures._style import R_COLOR, REGIME_COLORS, apply_style, regime_spans
from dtwin.reference.columns import R_RESTART_AGREEMENT_COLUMN
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["fig07_fault_posteriors", "plot_fault_posteriors", "onset_lags"]


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
    ax_truth = figure.add_subplot(grid[0, 0])
    _strip(ax_truth, t, posteriors["regime"].to_numpy(), "schedule")
    ax_truth.tick_params(labelbottom=False)
    ax_truth.set_title(
        "A  Hungarian-mapped smoothed posteriors with the fault schedule (paper Fig. 7)",
        loc="left",
    )
    ax_path = figure.add_subplot(grid[1, 0], sharex=ax_truth)
    _strip(ax_path, t, posteriors["mapped_regime"].to_numpy(), "Viterbi, mapped")
    ax_path.tick_params(labelbottom=False)
    ax = figure.add_subplot(grid[2, 0], sharex=ax_truth)
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
            axis.axvline(start, color="black", lw=1, ls="--")
    ax.set_ylim(0, 1)
    ax.set_xlim(t[0], t[-1] + (t[1] - t[0]))
    ax.set_ylabel("γ(regime) = Σ mapped states' posteriors")
    ax.set_xlabel("time (s)")
    ax.grid(False)
    ax.legend(ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)


def _draw_scores(ax: Any, scenario: Mapping[str, Any], r_scores: Mapping[str, float]) -> None:
    """Our and R's accuracy, macro-F1 and κ as a small monospace table."""
    ax.axis("off")
    block = "\n".join(
        [
            f"{'':6}{'accuracy':>9}{'macro-F1':>10}{'kappa':>8}",
            *(
                f"{who:6}{scores['accuracy']:>9.3f}{scores['macro_f1']:>10.3f}"
                f"{scores['kappa']:>8.3f}"
                for who, scores in (("ours", scenario), ("R", r_scores))
            ),
        ]
    )
    ax.text(0, 0.45, block, va="center", fontsize=9, family="monospace")


def _short(regime: str) -> str:
    return regime.replace("Sensor", "Sens.").replace("Dynamics", "Dyn.")


def _draw_confusion(ax: Any, confusion_record: Mapping[str, Any]) -> None:
    """Panel B: the confusion matrix (predicted rows × actual columns), counts annotated."""
    confusion = pd.DataFrame(confusion_record).T
    rows = [r for r in confusion.index]
    matrix = confusion.loc[rows, list(REGIMES)].to_numpy(dtype=float)
    ax.imshow(matrix, cmap="Blues", aspect="auto")
    ax.set_xticks(range(len(REGIMES)), [_short(r) for r in REGIMES], fontsize=7)
    ax.set_yticks(range(len(rows)), [_short(r) for r in rows], fontsize=7)
    ax.set_xlabel("actual regime")
    ax.set_ylabel("predicted")
    ax.grid(False)
    for i in range(matrix.shape[0]):
        for j in range(matrix.shape[1]):
            ax.text(
                j,
                i,
                f"{matrix[i, j]:.0f}",
                ha="center",
                va="center",
                fontsize=8,
                color="white" if matrix[i, j] > 0.5 * matrix.max() else "black",
            )
    ax.set_title("B  Confusion matrix (Viterbi, mapped)", loc="left")


def _draw_restarts(ax: Any, restart_records: list, r_accuracy: float) -> None:
    """Panel C: accuracy against log-likelihood of every usable EM start, R's best as a line."""
    restarts = pd.DataFrame(restart_records).dropna(subset=["accuracy"])
    points = (
        restarts.assign(ll=restarts["log_likelihood"].round(1), acc=restarts["accuracy"].round(4))
        .groupby(["ll", "acc"])
        .size()
        .reset_index(name="n")
    )
    ax.scatter(points["ll"], points["acc"], color=REGIME_COLORS["Nominal"], s=14 + 10 * points["n"])
    for row in points.itertuples():
        if row.n > 1:
            ax.annotate(
                f"×{row.n}",
                (row.ll, row.acc),
                textcoords="offset points",
                xytext=(5, 3),
                fontsize=7,
            )
    ax.xaxis.set_major_locator(MaxNLocator(4))
    ax.axhline(r_accuracy, color=R_COLOR, ls="--", lw=1, label="R (best start)")
    ax.set_xlabel("log-likelihood of the start")
    ax.set_ylabel("accuracy")
    ax.set_title(f"C  Every EM start, scored ({len(restarts)} usable)", loc="left")
    ax.legend(loc="lower right", fontsize=7)


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
    apply_style()
    figure = plt.figure(figsize=(14, 7))
    grid = figure.add_gridspec(
        3, 2, width_ratios=[2.6, 1], height_ratios=[0.16, 0.16, 1], hspace=0.12, wspace=0.28
    )
    _draw_posteriors(figure, grid, posteriors)
    _draw_scores(figure.add_subplot(grid[0:2, 1]), scenario, r_scores)
    inner = grid[2, 1].subgridspec(2, 1, hspace=0.55, height_ratios=[1.25, 1])
    _draw_confusion(figure.add_subplot(inner[0]), scenario["confusion"])
    _draw_restarts(figure.add_subplot(inner[1]), scenario["restarts"], r_scores["accuracy"])
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
    return FigureArtifact("fig07_fault_posteriors", figure, metrics, checks)
