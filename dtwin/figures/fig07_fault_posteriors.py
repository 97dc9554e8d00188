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

from dtwin.artifacts import Check, FigureArtifact, validity_finite, validity_probabilities
from dtwin.fault_injection import REGIMES
from dtwin.figures._style import R_COLOR, REGIME_COLORS, apply_style, regime_spans
from dtwin.reference.columns import R_RESTART_AGREEMENT_COLUMN
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["fig07_fault_posteriors", "plot_fault_posteriors", "onset_lags"]

#: Tolerance of the R comparison of accuracy, macro-F1 and κ (our noise draws differ from R's).
R_TOLERANCE = 0.05

#: A regime onset is "aligned" when its mapped posterior first exceeds 0.5 within this lag (s).
ONSET_LAG_S = 0.5

#: Onsets the alignment claim covers (the paper concedes Nominal/SensorNoisy are hard to split).
ALIGNED_ONSETS: tuple[str, ...] = ("DynamicsOff", "Drift")


def onset_lags(posteriors: pd.DataFrame) -> dict[str, float | None]:
    """Seconds from each scheduled regime onset until ``p_<regime>`` first exceeds 0.5.

    ``None`` when it never does before the regime ends.
    """
    t = posteriors["t"].to_numpy()
    lags: dict[str, float | None] = {}
    for regime, start, end in regime_spans(t, posteriors["regime"])[1:]:
        inside = (t >= start) & (t < end)
        above = np.flatnonzero(inside & (posteriors[f"p_{regime}"].to_numpy() > 0.5))
        lags[regime] = float(t[above[0]] - start) if above.size else None
    return lags


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


def plot_fault_posteriors(
    posteriors: pd.DataFrame, scenario: Mapping[str, Any], r_scores: Mapping[str, float]
) -> Figure:
    """Draw the mapped posteriors, the schedule and Viterbi strips, the confusion matrix and
    the accuracy of every EM start.

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
    t = posteriors["t"].to_numpy()
    figure = plt.figure(figsize=(14, 7))
    grid = figure.add_gridspec(
        3, 2, width_ratios=[2.6, 1], height_ratios=[0.16, 0.16, 1], hspace=0.12, wspace=0.28
    )
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

    ax_c = figure.add_subplot(grid[0:2, 1])
    ax_c.axis("off")
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
    ax_c.text(0, 0.45, block, va="center", fontsize=9, family="monospace")
    inner = grid[2, 1].subgridspec(2, 1, hspace=0.55, height_ratios=[1.25, 1])
    ax_m = figure.add_subplot(inner[0])
    confusion = pd.DataFrame(scenario["confusion"]).T
    rows = [r for r in confusion.index]
    matrix = confusion.loc[rows, list(REGIMES)].to_numpy(dtype=float)
    ax_m.imshow(matrix, cmap="Blues", aspect="auto")
    short = [r.replace("Sensor", "Sens.").replace("Dynamics", "Dyn.") for r in REGIMES]
    ax_m.set_xticks(range(len(REGIMES)), short, fontsize=7)
    ax_m.set_yticks(
        range(len(rows)),
        [r.replace("Sensor", "Sens.").replace("Dynamics", "Dyn.") for r in rows],
        fontsize=7,
    )
    ax_m.set_xlabel("actual regime")
    ax_m.set_ylabel("predicted")
    ax_m.grid(False)
    for i in range(matrix.shape[0]):
        for j in range(matrix.shape[1]):
            ax_m.text(
                j,
                i,
                f"{matrix[i, j]:.0f}",
                ha="center",
                va="center",
                fontsize=8,
                color="white" if matrix[i, j] > 0.5 * matrix.max() else "black",
            )
    ax_m.set_title("B  Confusion matrix (Viterbi, mapped)", loc="left")
    ax_r = figure.add_subplot(inner[1])
    restarts = pd.DataFrame(scenario["restarts"]).dropna(subset=["accuracy"])
    points = (
        restarts.assign(ll=restarts["log_likelihood"].round(1), acc=restarts["accuracy"].round(4))
        .groupby(["ll", "acc"])
        .size()
        .reset_index(name="n")
    )
    ax_r.scatter(
        points["ll"], points["acc"], color=REGIME_COLORS["Nominal"], s=14 + 10 * points["n"]
    )
    for row in points.itertuples():
        if row.n > 1:
            ax_r.annotate(
                f"×{row.n}",
                (row.ll, row.acc),
                textcoords="offset points",
                xytext=(5, 3),
                fontsize=7,
            )
    ax_r.xaxis.set_major_locator(MaxNLocator(4))
    ax_r.axhline(r_scores["accuracy"], color=R_COLOR, ls="--", lw=1, label="R (best start)")
    ax_r.set_xlabel("log-likelihood of the start")
    ax_r.set_ylabel("accuracy")
    ax_r.set_title(f"C  Every EM start, scored ({len(restarts)} usable)", loc="left")
    ax_r.legend(loc="lower right", fontsize=7)
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
    aligned = {r: lags.get(r) for r in ALIGNED_ONSETS if r in lags}
    probabilities = posteriors[[f"p_{r}" for r in REGIMES]].to_numpy()
    checks = [
        validity_finite("posteriors_finite", "mapped posteriors", probabilities),
        validity_probabilities("mapped_are_probabilities", "mapped posteriors", probabilities),
        Check(
            id="accuracy_like_r",
            kind="claim",
            statement=(
                "paper §4.4: the HMM identifies the regimes accurately; R's code reaches "
                f"accuracy {r_scores['accuracy']:.3f}, macro-F1 {r_scores['macro_f1']:.3f}, "
                f"kappa {r_scores['kappa']:.3f} (read here as: ours within ±{R_TOLERANCE:g} "
                f"of each; our noise draws differ from R's); drift origin '{origin}'"
            ),
            expected={k: f"{v:.4f} ± {R_TOLERANCE:g}" for k, v in r_scores.items()},
            observed=ours,
            reference=dict(r_scores),
            passed=all(abs(ours[k] - r_scores[k]) <= R_TOLERANCE for k in r_scores),
        ),
        Check(
            id="confusions_mostly_nominal_sensornoisy",
            kind="claim",
            statement=(
                "paper §4.4: the difficulties are in telling Nominal from SensorNoisy (read "
                "here as: at least half of the misclassified samples are Nominal <-> "
                "SensorNoisy; R: 149 of 150)"
            ),
            expected=">= 0.5",
            observed=scenario["nominal_sensor_share"],
            passed=bool(scenario["nominal_sensor_share"] >= 0.5),
        ),
        Check(
            id="onsets_align_with_schedule",
            kind="claim",
            statement=(
                "paper Fig. 7 caption: the posterior transitions align with the scheduled "
                f"intervals (read here as: the {' and '.join(ALIGNED_ONSETS)} posteriors exceed "
                f"0.5 within {ONSET_LAG_S:g} s of their onsets)"
            ),
            expected=f"lag <= {ONSET_LAG_S:g} s",
            observed=aligned,
            passed=bool(aligned)
            and all(lag is not None and lag <= ONSET_LAG_S for lag in aligned.values()),
        ),
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
