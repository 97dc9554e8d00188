"""K* across random draws: Fig. 9's BIC claims judged on every draw's own BIC sweep.

The ``bic_draws`` jobs sweep the BIC over K on each of the first draws
(:func:`dtwin.stages.draws.run_draw_bic`); this module judges each draw with Fig. 9's own
criteria (:func:`dtwin.figures.fig09_bic.bracket_checks`, :data:`PAPER_K_MIN`): its K*
(the K of the smallest BIC) per data set, whether the minimum is bracketed, whether the best
log-likelihood is stable in the EM starts (best of the first half vs best of all, every K up
to K* + 2), and the paper's claim "the BIC is smallest at K = 8". It gathers K*'s
distribution across draws for Fig. 12's third panel, the draws aggregate and CLAIMS.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from dtwin.figures.fig09_bic import PAPER_K_MIN, STABLE_LOGLIK, bracket_checks

__all__ = [
    "BIC_CLAIM_PREFIX",
    "judge_draw_bic",
    "k_star_table",
    "k_star_distributions",
    "k_star_detail",
]

#: Claim keys of Fig. 9's K = 8 claim, one per data set: ``<prefix><data set>``.
BIC_CLAIM_PREFIX = "fig09_bic:bic_minimum_at_k8_"


def judge_draw_bic(record: Mapping[str, Any]) -> dict[str, Any]:
    """Judge one draw's BIC sweep with Fig. 9's criteria.

    Parameters
    ----------
    record : mapping
        ``draw``, ``seeds`` and ``bic`` (the rows of ``results/bic_sweep.csv``'s columns for
        this draw), as written by the ``bic_draws`` rule.

    Returns
    -------
    dict
        ``draw``, ``claims`` (``fig09_bic:bic_minimum_at_k8_<data set>`` → K* = 8) and
        ``k_star``: per data set ``k_star``, ``k_last`` (largest K fitted), ``bracketed``,
        ``max_gain`` / ``at_k`` (log-likelihood the second half of the starts gained, at most,
        up to K* + 2), ``stable`` (that gain below :data:`STABLE_LOGLIK`), ``n_starts`` (random
        starts per K; ``max_starts``: at most, after doubling) and ``k4_given`` (the K = 4
        point is the draw's dedicated fit).
    """
    table = pd.DataFrame(record["bic"])
    given_check, bracket, stability = bracket_checks(table)
    given = set(given_check.observed)
    k_star = {}
    for name, where in bracket.observed.items():
        gain = stability.observed[name]
        rows = table[table["dataset"] == name].set_index("K")
        margin = (
            float(rows.loc[PAPER_K_MIN, "bic"] - rows["bic"].min())
            if PAPER_K_MIN in rows.index
            else None
        )
        k_star[name] = {
            "k_star": int(where["k_min"]),
            "k_last": int(where["k_last"]),
            "bracketed": int(where["k_min"]) < int(where["k_last"]) - 1,
            "max_gain": float(gain["max_gain"]),
            "at_k": int(gain["at_k"]),
            "stable": float(gain["max_gain"]) < STABLE_LOGLIK,
            "n_starts": int(rows.loc[rows["source"] == "sweep", "n_starts"].min()),
            "max_starts": int(rows.loc[rows["source"] == "sweep", "n_starts"].max()),
            "k4_given": name in given,
            "margin_k8": margin,
        }
    claims = {f"{BIC_CLAIM_PREFIX}{name}": v["k_star"] == PAPER_K_MIN for name, v in k_star.items()}
    return {"draw": int(record["draw"]), "claims": claims, "k_star": k_star}


def k_star_table(judged: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """Return one row per draw and data set (:func:`judge_draw_bic`'s ``k_star``).

    Columns: ``draw``, ``dataset`` and the ``k_star`` fields (``k_star``, ``k_last``,
    ``bracketed``, ``max_gain``, ``at_k``, ``stable``, ``n_starts``, ``max_starts``, ``k4_given``,
    ``margin_k8``).
    """
    rows = [
        {"draw": record["draw"], "dataset": name, **values}
        for record in judged
        for name, values in record["k_star"].items()
    ]
    return pd.DataFrame(rows)


def k_star_distributions(
    table: pd.DataFrame, main_k_star: Mapping[str, int], main_n_starts: int
) -> dict[str, dict[str, Any]]:
    """Per data set: K*'s counts across draws, its median, draw 0's and the main run's K*.

    Parameters
    ----------
    table : DataFrame
        :func:`k_star_table`.
    main_k_star : mapping
        Data set → K* of the main run's Fig. 9 sweep (``results/bic_sweep.csv``).
    main_n_starts : int
        EM starts per K of that sweep (``bic.n_restarts``).

    Returns
    -------
    dict
        Per data set: ``n`` (draws), ``n_starts`` (per K and draw; ``max_starts`` after
        doubling), ``counts`` (K → draws),
        ``median``, ``draw0``, ``main_run`` (K* with ``main_n_starts`` starts), ``paper``
        (8), ``k_at_paper`` (draws with K* = 8), ``bracketed`` and ``stable`` (draws),
        ``k8_beyond_start_noise`` (draws whose ``margin_k8`` exceeds twice ``max_gain``) and
        ``margin_k8_median``.
    """
    out = {}
    for name, group in table.groupby("dataset", sort=False):
        group = group.sort_values("draw")
        values = group["k_star"].to_numpy(dtype=int)
        counts = pd.Series(values).value_counts().sort_index()
        out[name] = {
            "n": int(len(group)),
            "n_starts": int(group["n_starts"].min()),
            "max_starts": int(group["max_starts"].max()),
            "counts": {str(k): int(c) for k, c in counts.items()},
            "median": float(np.median(values)),
            "draw0": int(values[0]) if int(group["draw"].iloc[0]) == 0 else None,
            "main_run": main_k_star.get(name),
            "main_run_n_starts": int(main_n_starts),
            "paper": PAPER_K_MIN,
            "k_at_paper": int((values == PAPER_K_MIN).sum()),
            "bracketed": int(group["bracketed"].sum()),
            "stable": int(group["stable"].sum()),
            "k8_beyond_start_noise": int((group["margin_k8"] > 2 * group["max_gain"]).sum()),
            "margin_k8_median": float(group["margin_k8"].median()),
        }
    return out


def k_star_detail(dist: Mapping[str, Any]) -> str:
    """Return one line on a data set's K* across draws (CLAIMS.md's draws cell).

    Examples
    --------
    >>> k_star_detail({"n": 3, "n_starts": 4, "counts": {"12": 2, "14": 1}, "bracketed": 3,
    ...                "stable": 1, "k8_beyond_start_noise": 3, "main_run": 14,
    ...                "main_run_n_starts": 20}).split("; ")[:3]  # doctest: +NORMALIZE_WHITESPACE
    ['K* in 3 draws: 12 (2), 14 (1)', 'bracketed in 3',
     'stable (best of 2 vs 4 random starts, doubled where unstable) in 1']
    """
    counts = ", ".join(f"{k} ({c})" for k, c in dist["counts"].items())
    half = max(1, dist["n_starts"] // 2)
    return "; ".join(
        [
            f"K* in {dist['n']} draws: {counts}",
            f"bracketed in {dist['bracketed']}",
            f"stable (best of {half} vs {dist['n_starts']} random starts, doubled where "
            f"unstable) in {dist['stable']}",
            f"BIC(8) − min above twice that gain in {dist['k8_beyond_start_noise']}",
            f"main run K* = {dist['main_run']} ({dist['main_run_n_starts']} starts)",
        ]
    )
