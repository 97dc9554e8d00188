"""Paper Fig. 9: BIC against the number of HMM states K, nominal residuals and fault features."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from dtwin.artifacts import Check, FigureArtifact, validity_finite
from dtwin.figures._style import PHYSICS_COLOR, R_COLOR, apply_style
from dtwin.reference.crosscheck_result import CrosscheckResult

__all__ = ["fig09_bic", "plot_bic", "bracket_checks", "start_stability"]

#: K at which the paper (and both R experiments) find the BIC minimum (§5, Fig. 9).
PAPER_K_MIN = 8

#: Titles of the two data sets (r_notes.md §6 (a) and (b)).
TITLES = {
    "nominal_residuals": "A  Nominal run: six z-scored residuals",
    "fault_features": "B  Fault scenario: ten z-scored features",
}


#: Curves whose small-K values dwarf the rest (range > this × the range for K >= 4) are drawn
#: on a log axis when all values are positive.
LOG_SCALE_RATIO = 2.5


def _needs_log_scale(curves) -> bool:
    values = pd.concat([c["bic"] for _, c, _, _ in curves])
    tail = pd.concat([c.loc[c["K"] >= 4, "bic"] for _, c, _, _ in curves])
    if tail.empty or values.size == tail.size or values.min() <= 0:
        return False
    return bool((values.max() - values.min()) > LOG_SCALE_RATIO * (tail.max() - tail.min()))


def _draw(ax, curves) -> None:
    """Plot each curve (``(who, table with K and bic, colour, label)``), star its minimum."""
    for who, curve, color, label in curves:
        style = "o-" if who == "ours" else "s--"
        ax.plot(
            curve["K"],
            curve["bic"],
            style,
            color=color,
            lw=2 if who == "ours" else 1.3,
            ms=6 if who == "ours" else 5,
            label=label,
        )
        best = curve.loc[curve["bic"].idxmin()]
        ax.plot(best["K"], best["bic"], "*", color=color, ms=15)
        ax.annotate(
            f"{'min' if who == 'ours' else 'R min'} K={int(best['K'])}",
            (best["K"], best["bic"]),
            textcoords="offset points",
            xytext=(-12, 0) if who == "ours" else (0, 11),
            ha="right" if who == "ours" else "center",
            va="center" if who == "ours" else "bottom",
            color=color,
            fontsize=8,
        )
    ks = sorted(set().union(*(set(c["K"]) for _, c, _, _ in curves)))
    ax.set_xticks(ks)


def plot_bic(table: pd.DataFrame, r_tables: Mapping[str, pd.DataFrame], n_restarts: int) -> Figure:
    """Draw BIC against K for each data set: ours (best of ``n_restarts`` starts) and R's.

    Parameters
    ----------
    table : DataFrame
        Our sweep: ``dataset``, ``K``, ``bic``.
    r_tables : mapping
        :func:`dtwin.reference.loaders.load_r_bic`.
    n_restarts : int
        Starts per K of our sweep (for the legend).
    """
    apply_style()
    datasets = list(dict.fromkeys(table["dataset"]))
    figure, axes = plt.subplots(1, len(datasets), figsize=(6 * len(datasets), 4.6), squeeze=False)
    r_label = {
        "nominal_residuals": "R, BIC_vs_K.R (1 start per K)",
        "fault_features": "R, CovarianceAnalysis (best of 5)",
    }
    for ax, name in zip(axes[0], datasets, strict=True):
        ours = table[table["dataset"] == name]
        r = r_tables.get(name)
        curves = [("ours", ours, PHYSICS_COLOR, f"ours (best of {n_restarts} starts)")]
        if r is not None:
            curves.append(("R", r, R_COLOR, r_label.get(name, "R")))
        _draw(ax, curves)
        if _needs_log_scale(curves):
            ax.set_yscale("log")
            ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            ax.yaxis.set_major_formatter(ScalarFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_ylabel("BIC (log scale)")
        ax.set_title(TITLES.get(name, name), loc="left")
        ax.set_xlabel("number of states K")
        if ax.get_yscale() != "log":
            ax.set_ylabel("BIC = −2 log L + p log n")
        ax.legend(loc="upper right", fontsize=8)
    figure.suptitle("Model selection: BIC against the number of HMM states (paper Fig. 9)")
    figure.tight_layout()
    return figure


def start_stability(table: pd.DataFrame) -> dict[str, Any]:
    """Per data set: log-likelihood gained by the second half of the starts, per K and at most.

    A gain near 0 means doubling the EM starts no longer finds a better optimum.
    """
    if "log_likelihood_half" not in table:
        return {}
    out = {}
    for name, group in table.groupby("dataset", sort=False):
        gain = group["log_likelihood"] - group["log_likelihood_half"]
        out[name] = {
            "n_starts": int(group["n_starts"].max()),
            "gain_by_k": dict(zip(group["K"].astype(int), gain.round(6), strict=True)),
            "max_gain": float(gain.max()),
        }
    return out


def bracket_checks(table: pd.DataFrame) -> list[Check]:
    """Return the checks: K = 4 is the dedicated fit (validity), the minimum is bracketed."""
    if "source" not in table:
        return []
    given = table[table["source"] == "given"]
    minima = table.loc[table.groupby("dataset", sort=False)["bic"].idxmin(), ["dataset", "K"]]
    last = table.groupby("dataset", sort=False)["K"].max()
    bracketed = {
        row.dataset: int(row.K) < int(last[row.dataset]) - 1 for row in minima.itertuples()
    }
    return [
        Check(
            id="k4_point_is_the_dedicated_fit",
            kind="validity",
            statement="at K = hmm.n_states the BIC curve uses the dedicated fit of Figs. 4 and 7 "
            "(one fit per data set: the figures and the curve agree exactly)",
            expected="one given row per data set",
            observed=dict(zip(given["dataset"], given["K"].astype(int), strict=True)),
            passed=sorted(given["dataset"]) == sorted(table["dataset"].unique()),
        ),
        Check(
            id="bic_minimum_bracketed",
            kind="claim",
            statement="project target: the sweep brackets the BIC minimum on both data sets "
            "(K extended until the BIC rose twice in a row, at most to bic.k_max)",
            expected="minimum below the last two K fitted",
            observed={
                name: {"k_min": int(k), "k_last": int(last[name])}
                for name, k in zip(minima["dataset"], minima["K"], strict=True)
            },
            passed=all(bracketed.values()),
        ),
        _stability_check(table),
    ]


#: The best log-likelihood is "stable" when doubling the EM starts gains less than this.
STABLE_LOGLIK = 1.0


def _stability_check(table: pd.DataFrame) -> Check:
    """Project target: the second half of the starts finds nothing better up to K* + 2."""
    worst = {}
    for name, group in table.groupby("dataset", sort=False):
        k_star = int(group.loc[group["bic"].idxmin(), "K"])
        near = group[group["K"] <= k_star + 2]
        gain = near["log_likelihood"] - near["log_likelihood_half"]
        worst[name] = {
            "max_gain": round(float(gain.max()), 3),
            "at_k": int(near.loc[gain.idxmax(), "K"]),
        }
    n_starts = int(table["n_starts"].max())
    return Check(
        id="best_loglik_stable_in_starts",
        kind="claim",
        statement=f"project target: the best log-likelihood is stable in the EM starts (best of "
        f"{n_starts // 2} vs best of {n_starts}, every K up to K* + 2, both data sets)",
        expected=f"gain < {STABLE_LOGLIK:g} log-likelihood units",
        observed=worst,
        passed=all(w["max_gain"] < STABLE_LOGLIK for w in worst.values()),
    )


def fig09_bic(
    table: pd.DataFrame,
    r_tables: Mapping[str, pd.DataFrame],
    crosscheck: CrosscheckResult,
    bic: Mapping[str, Any],
) -> FigureArtifact:
    """Paper Fig. 9 with the BIC minima beside the paper's K = 8 and a formula crosscheck.

    Parameters
    ----------
    table : DataFrame
        ``results/bic_sweep.csv``.
    r_tables : mapping of str to DataFrame
        R's BIC by K per data set (:func:`dtwin.reference.loaders.load_r_bic`).
    crosscheck : CrosscheckResult
        :func:`dtwin.reference.bic_crosscheck.crosscheck_bic_formula`.
    bic : mapping
        The ``bic`` config section (``n_restarts`` is reported).
    """
    figure = plot_bic(table, r_tables, bic["n_restarts"])
    minima = {
        name: int(group.loc[group["bic"].idxmin(), "K"])
        for name, group in table.groupby("dataset", sort=False)
    }
    r_minima = {name: int(r.loc[r["bic"].idxmin(), "K"]) for name, r in r_tables.items()}
    r_min_values = {name: float(r["bic"].min()) for name, r in r_tables.items()}
    checks = [
        validity_finite("bic_finite", "BIC values", table[["log_likelihood", "bic"]]),
        Check(
            id="every_k_fitted",
            kind="validity",
            statement="every K of the sweep has at least one usable EM start",
            expected=">= 1 usable start per K",
            observed=dict(
                zip(
                    table["dataset"] + " K=" + table["K"].astype(str),
                    table["n_usable"],
                    strict=True,
                )
            ),
            passed=bool((table["n_usable"] >= 1).all()),
        ),
        *crosscheck.checks,
        *bracket_checks(table),
    ]
    for name, k_min in minima.items():
        checks.append(
            Check(
                id=f"bic_minimum_at_k8_{name}",
                kind="claim",
                statement=(
                    f"paper §5 / Fig. 9: the BIC is smallest at K = {PAPER_K_MIN} "
                    f"({name.replace('_', ' ')}; R: minimum "
                    f"{r_min_values.get(name, float('nan')):.2f} at K = {r_minima.get(name)})"
                ),
                expected=PAPER_K_MIN,
                observed=k_min,
                passed=k_min == PAPER_K_MIN,
                reference=r_minima.get(name),
            )
        )
    metrics = {
        "ks": sorted(set(table["K"].tolist())),
        "n_restarts": bic["n_restarts"],
        "bic_minimum_k": minima,
        "r_bic_minimum_k": r_minima,
        "r_bic_minimum": r_min_values,
        "bic_minimum": {
            name: float(group["bic"].min()) for name, group in table.groupby("dataset", sort=False)
        },
        "sweep": table.to_dict(orient="records"),
        "r_sweep": {name: r.to_dict(orient="records") for name, r in r_tables.items()},
        "formula_max_abs_deviation": crosscheck.metrics,
        "best_of_half_vs_all_starts": start_stability(table),
        "still_decreasing_at_max_k": {
            name: bool(np.diff(group.sort_values("K")["bic"].to_numpy())[-1] < 0)
            for name, group in table.groupby("dataset", sort=False)
        },
    }
    return FigureArtifact("fig09_bic", figure, metrics, checks)
