"""Fig. 12 (this project): the paper's single-draw claims across random draws.

The paper judges each claim on one random draw (R: seed 11). The ``claims_draws`` jobs rerun
that draw N times with derived seeds (:mod:`dtwin.stages.draws`; draw 0 is the main run) and
judge every claim on each (:mod:`dtwin.stages.draw_claims`). This module gathers the draws:
for every claim the number of draws in which it holds with a Wilson interval
(:func:`dtwin.proportions.wilson_interval`), the distribution of the headline numbers beside R's
draw, and — the one panel that explains the e1/e4 result — the plant correction's dRMSE of
e1 and e4 against the DynamicsOff window's mean of x. The ``bic_draws`` jobs sweep the BIC
over K on the first draws; their K* per data set judges Fig. 9's two claims on each draw
(:mod:`dtwin.figures._draw_bic`) and its distribution is the third panel.

Plain matplotlib, drawn at the shared print size (:mod:`dtwin.figures._style`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dtwin._validation import DtwinValueError
from dtwin.artifacts import Check, FigureArtifact
from dtwin.claim_criteria import dynamics_off_window
from dtwin.figures._style import new_figure, panel_title, unitless
from dtwin.proportions import wilson_interval

__all__ = [
    "HEADLINE_NUMBERS",
    "r_draw_values",
    "collect_draws",
    "claims_across_draws",
    "numbers_table",
    "number_distributions",
    "plot_claims_across_draws",
    "BicDraws",
    "bic_across_draws",
    "fig12_claims_across_draws",
]

#: Headline numbers whose distribution across draws is reported (columns of numbers_table).
HEADLINE_NUMBERS: tuple[str, ...] = (
    "accuracy",
    "macro_f1",
    "kappa",
    "nominal_sensor_share",
    "drmse_pct_e0",
    "drmse_pct_e1",
    "drmse_pct_e2a",
    "drmse_pct_e2b",
    "drmse_pct_e3",
    "drmse_pct_e4",
    "lag1_e1",
    "lag1_e4",
    "min_self_transition",
    "rmse_ratio_e1",
    "dynamics_off_mean_x",
    "dynamics_off_mean_e1",
    "dynamics_off_e1_mean_share",
    "share_DynamicsOff_ReidentifyPlant",
    "share_Drift_BiasCorrect",
)


def r_draw_values(
    r_physics: pd.DataFrame,
    r_residuals: pd.DataFrame,
    r_metrics: pd.DataFrame,
    r_scores: Mapping[str, float],
    r_numbers: Mapping[str, Any],
) -> dict[str, float]:
    """Return R's seed-11 draw named as :data:`HEADLINE_NUMBERS` (the numbers R publishes).

    Parameters
    ----------
    r_physics : DataFrame
        R's physics (``x`` in m), :func:`dtwin.reference.loaders.load_r_faulted_twin`.
    r_residuals : DataFrame
        R's faulted residuals (``regime``, ``e1`` in m),
        :func:`dtwin.reference.loaders.load_r_fault_scenario`.
    r_metrics : DataFrame
        R's correction table (``channel``, ``drmse_pct``).
    r_scores : mapping
        R's ``accuracy``, ``macro_f1``, ``kappa``.
    r_numbers : mapping
        ``config/reference/r_numbers.yaml`` (``nominal_lag1_acf``).
    """
    window = dynamics_off_window(
        r_physics["x"].to_numpy(),
        r_residuals["e1"].to_numpy(),
        r_residuals["regime"].to_numpy(dtype=str),
    )
    values = {key: float(r_scores[key]) for key in ("accuracy", "macro_f1", "kappa")}
    values.update(
        {
            f"drmse_pct_{c}": float(v)
            for c, v in zip(r_metrics["channel"], r_metrics["drmse_pct"], strict=True)
        }
    )
    values.update({f"lag1_{e}": float(r_numbers["nominal_lag1_acf"][e]) for e in ("e1", "e4")})
    values.update({f"dynamics_off_{k}": v for k, v in window.items()})
    return values


def collect_draws(
    chunks: Sequence[Mapping[str, Any]], n_draws: int, rule: str = "claims_draws"
) -> list[dict[str, Any]]:
    """Return the draw records of all chunks, in draw order, checking that none is missing.

    Parameters
    ----------
    chunks : sequence of mapping
        Parsed ``results/draws/chunk<c>.json`` files, each ``{"draws": [record, ...]}``.
    n_draws : int
        Draws expected: 0 … n_draws − 1, each exactly once.
    rule : str, default "claims_draws"
        The rule that writes the chunks (named in the error).

    Raises
    ------
    DtwinValueError
        Naming the missing or repeated draws.
    """
    records = [record for chunk in chunks for record in chunk["draws"]]
    seen = [int(record["draw"]) for record in records]
    missing = sorted(set(range(n_draws)) - set(seen))
    repeated = sorted({d for d in seen if seen.count(d) > 1})
    if missing or repeated or len(seen) != n_draws:
        raise DtwinValueError(
            f"{rule}: expected draws 0..{n_draws - 1} once each; missing "
            f"{missing or 'none'}, repeated {repeated or 'none'}, extra "
            f"{sorted(set(seen) - set(range(n_draws))) or 'none'} (rerun {rule})"
        )
    return sorted(records, key=lambda record: int(record["draw"]))


def claims_across_draws(records: Sequence[Mapping[str, Any]], level: float) -> pd.DataFrame:
    """Return, per claim, in how many draws it holds with a Wilson interval.

    Returns
    -------
    DataFrame
        Columns ``claim`` (``<artifact>:<id>``), ``k`` (draws in which it holds), ``n``,
        ``share``, ``low``, ``high`` (Wilson interval at ``level``), ``draw0`` (the verdict
        of draw 0, the main run).
    """
    keys = sorted(records[0]["claims"], key=lambda key: key.split(":")[0])
    rows = []
    for key in keys:
        verdicts = [bool(record["claims"][key]) for record in records]
        k, n = int(sum(verdicts)), len(verdicts)
        low, high = wilson_interval(k, n, level)
        rows.append(
            {
                "claim": key,
                "k": k,
                "n": n,
                "share": k / n,
                "low": low,
                "high": high,
                "draw0": verdicts[0],
            }
        )
    return pd.DataFrame(rows)


def numbers_table(records: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """Return one row per draw: ``draw``, the three seeds and :data:`HEADLINE_NUMBERS`."""
    rows = []
    for record in records:
        numbers = record["numbers"]
        row = {"draw": int(record["draw"]), **{f"seed_{k}": v for k, v in record["seeds"].items()}}
        for key in ("accuracy", "macro_f1", "kappa", "nominal_sensor_share", "lag1_e1", "lag1_e4"):
            row[key] = numbers[key]
        for key in ("min_self_transition", "rmse_ratio_e1"):
            row[key] = numbers[key]
        row.update({f"drmse_pct_{e}": v for e, v in numbers["drmse_pct"].items()})
        row.update({f"dynamics_off_{k}": v for k, v in numbers["dynamics_off"].items()})
        row.update({f"share_{k.replace(':', '_')}": v for k, v in numbers["action_shares"].items()})
        rows.append(row)
    return pd.DataFrame(rows)


def number_distributions(
    table: pd.DataFrame, r_values: Mapping[str, float]
) -> dict[str, dict[str, Any]]:
    """Per headline number: quantiles across draws, draw 0's value, R's and R's rank.

    ``r_rank`` is the share of draws whose value is below R's (None without an R value).
    """
    out = {}
    for name in HEADLINE_NUMBERS:
        values = table[name].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        if finite.size == 0:
            continue
        q = np.quantile(finite, [0.0, 0.05, 0.5, 0.95, 1.0])
        r_value = r_values.get(name)
        out[name] = {
            "n": int(finite.size),
            "min": q[0],
            "p5": q[1],
            "median": q[2],
            "p95": q[3],
            "max": q[4],
            "draw0": float(values[0]),
            "r": r_value,
            "r_rank": None if r_value is None else float(np.mean(finite < r_value)),
        }
    return out


def _label(claim: str) -> str:
    """Return a tick label: ``fig05_x:lowered_in_m1`` → ``Fig. 5: lowered in m1``."""
    artifact, check = claim.split(":", 1)
    number = artifact[3:5] if artifact.startswith("fig") else ""
    head = f"Fig. {int(number)}" if number.isdigit() else artifact
    return f"{head}: {check.replace('_', ' ')}"


def _claims_panel(ax: plt.Axes, claims: pd.DataFrame) -> None:
    y = np.arange(len(claims))[::-1]
    share = claims["share"].to_numpy()
    err = np.vstack([share - claims["low"].to_numpy(), claims["high"].to_numpy() - share])
    err = np.clip(err, 0.0, None)  # a Wilson bound may pass k/n by round-off (k = 0 or n)
    ax.errorbar(share, y, xerr=err, fmt="none", ecolor="#0b2545", elinewidth=1, capsize=2)
    held = claims["draw0"].to_numpy()
    ax.scatter(share[held], y[held], color="#0b2545", s=16, zorder=3, label="holds in draw 0")
    ax.scatter(
        share[~held], y[~held], facecolor="white", edgecolor="#b3001b", s=16, zorder=3,
        label="fails in draw 0 (main run)",
    )  # fmt: skip
    ax.set_yticks(y, [_label(c) for c in claims["claim"]])
    ax.tick_params(axis="y", labelsize=7)
    ax.set_xlim(-0.02, 1.02)
    sizes = list(dict.fromkeys(int(n) for n in claims["n"]))  # Fig. 9's K* may use fewer draws
    ax.set_xlabel(f"share of the {' or '.join(map(str, sizes))} draws (95 % Wilson)")
    ax.axvline(0.5, color="#8c8c8c", lw=0.6, ls=":")
    ax.legend(loc="lower right", fontsize=7, frameon=False)
    panel_title(ax, "a", "claims across draws")


def _explanation_panel(ax: plt.Axes, table: pd.DataFrame, r_values: Mapping[str, float]) -> None:
    mean_x = table["dynamics_off_mean_x"].to_numpy(dtype=float)
    for channel, color, marker in (("e1", "#D55E00", "o"), ("e4", "#0072B2", "s")):
        values = table[f"drmse_pct_{channel}"].to_numpy(dtype=float)
        ax.scatter(mean_x, values, s=12, color=color, marker=marker, alpha=0.7, label=channel)
        ax.scatter(mean_x[:1], values[:1], s=60, facecolor="none", edgecolor=color, lw=1.2)
        r_value = r_values.get(f"drmse_pct_{channel}")
        if r_value is not None and "dynamics_off_mean_x" in r_values:
            ax.scatter(
                [r_values["dynamics_off_mean_x"]], [r_value], marker="*", s=110, color=color,
                edgecolor="black", lw=0.6, zorder=4,
            )  # fmt: skip
    ax.axhline(0, color="#8c8c8c", lw=0.6)
    ax.set_xlabel(r"DynamicsOff mean of $x$ (m)")
    ax.set_ylabel(r"$\Delta$RMSE of the correction (%)")
    panel_title(ax, "b", r"$e_1$, $e_4$: ★ R's draw, ○ draw 0")
    ax.legend(fontsize=7, frameon=False)


#: Colour and bar offset of each data set in the K* panel.
_K_STAR_STYLE = {"nominal_residuals": ("#0072B2", -0.2), "fault_features": ("#D55E00", 0.2)}


def _k_star_panel(ax: plt.Axes, k_star: Mapping[str, Mapping[str, Any]]) -> None:
    """Bars: draws per K* and data set; ★ the main run's K* (more starts); line: paper's K."""
    top = 1
    for name, dist in k_star.items():
        color, offset = _K_STAR_STYLE.get(name, ("#555555", 0.0))
        ks = np.array([int(k) for k in dist["counts"]])
        counts = np.array(list(dist["counts"].values()))
        label = f"{name.replace('_', ' ')} (n = {dist['n']})"
        ax.bar(ks + offset, counts, width=0.4, color=color, alpha=0.8, label=label)
        top = max(top, int(counts.max()) if counts.size else 1)
        if dist.get("main_run") is not None:
            ax.plot([dist["main_run"] + offset], [0], "*", color=color, ms=9, mec="black", mew=0.5,
                    clip_on=False, zorder=4)  # fmt: skip
    paper = next(iter(k_star.values()))["paper"]
    ax.axvline(paper, color="#8c8c8c", lw=0.8, ls="--", label=f"paper's K = {paper}")
    starts = sorted({d["n_starts"] for d in k_star.values()})
    ax.set_xlabel(f"K* (BIC minimum; {'/'.join(map(str, starts))} EM starts per K)")
    ax.set_ylabel("draws")
    ax.set_ylim(0, top * 1.7)
    unitless(ax, "xy")
    ax.legend(fontsize=7, frameon=False, loc="upper left")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    panel_title(ax, "c", "K* per draw; ★ Fig. 9")


def plot_claims_across_draws(
    claims: pd.DataFrame,
    table: pd.DataFrame,
    r_values: Mapping[str, float],
    k_star: Mapping[str, Mapping[str, Any]] | None = None,
) -> Figure:
    """Draw the claims' shares across draws (left), the e1/e4 explanation and K* (right).

    Parameters
    ----------
    claims : DataFrame
        :func:`claims_across_draws`.
    table : DataFrame
        :func:`numbers_table`.
    r_values : mapping
        R's draw: ``dynamics_off_mean_x`` (m), ``drmse_pct_e1``, ``drmse_pct_e4`` (%).
    k_star : mapping, optional
        :func:`dtwin.figures._draw_bic.k_star_distributions` (no third panel without it).
    """
    if not k_star:
        figure = new_figure(4.6)
        ax_claims, ax_e1 = figure.subplots(1, 2, width_ratios=[1.1, 1.0])
    else:
        figure = new_figure(6.0)
        grid = figure.add_gridspec(2, 2, width_ratios=[1.1, 1.0])
        ax_claims = figure.add_subplot(grid[:, 0])
        ax_e1 = figure.add_subplot(grid[0, 1])
        _k_star_panel(figure.add_subplot(grid[1, 1]), k_star)
    _claims_panel(ax_claims, claims)
    _explanation_panel(ax_e1, table, r_values)
    return figure


def _explanation_metrics(table: pd.DataFrame, r_values: Mapping[str, float]) -> dict[str, Any]:
    """Rank correlation of dRMSE_e1 with |mean x| and where R's draw falls."""
    abs_x = np.abs(table["dynamics_off_mean_x"].to_numpy(dtype=float))
    drmse = table["drmse_pct_e1"].to_numpy(dtype=float)
    keep = np.isfinite(abs_x) & np.isfinite(drmse)
    rho = None
    if keep.sum() > 2:
        ranks = pd.DataFrame({"x": abs_x[keep], "d": drmse[keep]}).rank()
        rho = float(ranks["x"].corr(ranks["d"]))
    r_x = r_values.get("dynamics_off_mean_x")
    return {
        "spearman_abs_mean_x_vs_drmse_e1": rho,
        "r_abs_mean_x": None if r_x is None else abs(r_x),
        "share_of_draws_with_abs_mean_x_at_least_r": (
            None if r_x is None or not keep.any() else float(np.mean(abs_x[keep] >= abs(r_x)))
        ),
    }


@dataclass(frozen=True)
class BicDraws:
    """The BIC sweeps of the first draws (K* across draws) and the main run's sweep.

    Attributes
    ----------
    chunks : sequence of mapping
        Parsed ``results/draws/bic/chunk<c>.json`` files (``{"draws": [record, ...]}``).
    n_draws : int
        Draws expected: 0 … n_draws − 1 (``min(draws.bic.n_draws, draws.n_draws)``).
    main_table : DataFrame or None
        ``results/bic_sweep.csv`` (the main run's Fig. 9 sweep).
    main_n_restarts : int
        ``bic.n_restarts``: EM starts per K of the main sweep.
    """

    chunks: Sequence[Mapping[str, Any]] = ()
    n_draws: int = 0
    main_table: pd.DataFrame | None = None
    main_n_restarts: int = 0


def bic_across_draws(
    bic: BicDraws, level: float
) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Fig. 9's K = 8 claims across draws, one row per draw and data set, K*'s distribution.

    Returns
    -------
    (claims, k_star, distributions)
        :func:`claims_across_draws` of the two claims, with ``draw0_is_main_run`` (draw 0's
        sweep had the main run's starts, so its verdict must be Fig. 9's);
        :func:`dtwin.figures._draw_bic.k_star_table`;
        :func:`dtwin.figures._draw_bic.k_star_distributions`.
    """
    from dtwin.figures._draw_bic import judge_draw_bic, k_star_distributions, k_star_table

    records = [judge_draw_bic(r) for r in collect_draws(bic.chunks, bic.n_draws, "bic_draws")]
    table = k_star_table(records)
    main = bic.main_table
    main_k = (
        {}
        if main is None
        else {n: int(g.loc[g["bic"].idxmin(), "K"]) for n, g in main.groupby("dataset", sort=False)}
    )
    claims = claims_across_draws(records, level)
    claims["draw0_is_main_run"] = bool(table["n_starts"].max() == bic.main_n_restarts)
    return claims, table, k_star_distributions(table, main_k, bic.main_n_restarts)


def _claims_metrics(claims: pd.DataFrame, k_star: Mapping[str, Any]) -> dict[str, Any]:
    """Per claim ``k``, ``n``, ``share``, ``low``, ``high``, ``draw0`` (and K*'s line)."""
    from dtwin.figures._draw_bic import BIC_CLAIM_PREFIX, k_star_detail

    out = {}
    for row in claims.to_dict(orient="records"):
        entry = {k: row[k] for k in ("k", "n", "share", "low", "high", "draw0")}
        if row["claim"].startswith(BIC_CLAIM_PREFIX):
            name = row["claim"].removeprefix(BIC_CLAIM_PREFIX)
            entry["draw0_is_main_run"] = bool(row["draw0_is_main_run"])
            entry["detail"] = k_star_detail(k_star[name])
        out[row["claim"]] = entry
    return out


def fig12_claims_across_draws(
    chunks: Sequence[Mapping[str, Any]],
    n_draws: int,
    level: float,
    r_values: Mapping[str, float],
    bic: BicDraws | None = None,
) -> tuple[FigureArtifact, pd.DataFrame, pd.DataFrame]:
    """Fig. 12 and the per-draw tables from the ``claims_draws`` and ``bic_draws`` chunks.

    Parameters
    ----------
    chunks : sequence of mapping
        Parsed chunk files (see :func:`collect_draws`).
    n_draws : int
        Number of draws (``draws.n_draws``).
    level : float
        Level of the Wilson intervals (``draws.interval``).
    r_values : mapping
        R's draw, named as :data:`HEADLINE_NUMBERS` (those that are known).
    bic : BicDraws, optional
        The draws' BIC sweeps (K* across draws; none without it or with ``n_draws = 0``).

    Returns
    -------
    (FigureArtifact, DataFrame, DataFrame)
        The artifact (metrics ``claims``: per claim ``k``, ``n``, ``low``, ``high``,
        ``draw0``; ``numbers``: :func:`number_distributions`; ``e1_explanation``;
        ``k_star``), :func:`numbers_table` and the K* table
        (:func:`dtwin.figures._draw_bic.k_star_table`, empty without BIC sweeps).
    """
    if not 0 < level < 1:
        raise DtwinValueError(f"draws.interval must be in (0, 1) (got {level!r})")
    records = collect_draws(chunks, n_draws)
    claims = claims_across_draws(records, level)
    table = numbers_table(records)
    k_table, k_star, all_claims = pd.DataFrame(), {}, claims
    if bic is not None and bic.n_draws > 0:
        bic_claims, k_table, k_star = bic_across_draws(bic, level)
        all_claims = claims_across_draws_sorted(claims, bic_claims)
    figure = plot_claims_across_draws(all_claims, table, r_values, k_star)
    metrics = {
        "n_draws": n_draws,
        "interval": level,
        "claims": _claims_metrics(all_claims, k_star),
        "numbers": number_distributions(table, r_values),
        "e1_explanation": _explanation_metrics(table, r_values),
        "k_star": k_star,
        "r_draw": dict(r_values),
    }
    checks = [_judged_check(records, claims, n_draws), *_bic_checks(k_table)]
    artifact = FigureArtifact(
        "fig12_claims_across_draws",
        figure,
        metrics,
        checks,
        paper_figure=None,
        caption=_caption(k_star),
        provenance="results/draws/chunk*.json (claims_draws rule), results/draws/bic/chunk*"
        ".json (bic_draws rule), results/bic_sweep.csv; R's seed-11 tables",
    )
    return artifact, table, k_table


def claims_across_draws_sorted(*parts: pd.DataFrame) -> pd.DataFrame:
    """Concatenate claim tables and order them by figure (as :func:`claims_across_draws`)."""
    joined = pd.concat(parts, ignore_index=True)
    order = joined["claim"].str.split(":").str[0]
    return joined.iloc[np.argsort(order.to_numpy(), kind="stable")].reset_index(drop=True)


def _judged_check(
    records: Sequence[Mapping[str, Any]], claims: pd.DataFrame, n_draws: int
) -> Check:
    verdicts_are_bool = all(
        isinstance(v, bool) for record in records for v in record["claims"].values()
    )
    return Check(
        id="every_draw_judged_on_every_claim",
        kind="validity",
        statement="every draw has a verdict on the same claims",
        expected=f"{n_draws} draws x {len(claims)} claims",
        observed=sum(len(record["claims"]) for record in records),
        passed=verdicts_are_bool
        and all(sorted(r["claims"]) == sorted(claims["claim"]) for r in records),
    )


def _bic_checks(k_table: pd.DataFrame) -> list[Check]:
    """Return the validity check that every draw's sweep has its dedicated fit at K = 4."""
    if k_table.empty:
        return []
    missing = k_table.loc[~k_table["k4_given"], ["draw", "dataset"]]
    return [
        Check(
            id="bic_draws_k4_point_is_the_dedicated_fit",
            kind="validity",
            statement="in every draw's BIC sweep the K = hmm.n_states point is that draw's "
            "dedicated fit (Figs. 4 and 7 of the draw), on both data sets",
            expected="0 draws without it",
            observed=missing.to_dict(orient="records") or 0,
            passed=missing.empty,
        )
    ]


def _caption(k_star: Mapping[str, Any]) -> str:
    """Return the caption; with BIC sweeps, K*'s median per data set across draws."""
    head = (
        "Not in the paper (it judged one draw): the share of random draws in which each "
        "single-draw claim of Figs. 2-10 holds, with 95 % Wilson intervals; the e1/e4 "
        "correction gain follows the DynamicsOff window's mean of x, large in R's draw"
    )
    if not k_star:
        return head
    medians = ", ".join(f"{name.replace('_', ' ')} {d['median']:g}" for name, d in k_star.items())
    n_starts = next(iter(k_star.values()))["n_starts"]
    never = all(d["k_at_paper"] == 0 for d in k_star.values())
    return (
        f"{head}; K* (the BIC minimum) across draws: median {medians} with {n_starts} EM "
        "starts per K and draw (doubled where unstable)"
        + (", never the paper's 8" if never else "")
    )
