"""One page of truth: every artifact's checks gathered into ``CLAIMS.md`` and ``claims.json``.

Reads the artifact JSONs (``{"artifact", "files", "metrics", "checks"}``, see
:mod:`dtwin.artifacts`) and lays their checks out as four tables: the paper's claims (the
paper's statement, R's number, ours, reproduced or not and why, and in how many random draws
the claim holds), the project's own targets, the crosschecks against the authors' R code,
and the validity checks. A claim that does not reproduce is reported, never hidden; only a
failed validity check is an error.

A ``claim`` check is the *paper's* when its artifact is a paper artifact and its statement
quotes the paper (starts with ``paper``). The project's own targets (the gap benchmark's, the
sweep's optimiser expectations, ...) are ``target`` checks in their artifact's JSON; a
``claim`` that does not quote the paper is counted as a target too. Every row is an
:class:`dtwin.artifacts.Check` with its artifact (:func:`check_row`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dtwin._validation import DtwinValueError
from dtwin.artifacts import REPLICATES_METRIC, Check
from dtwin.proportions import wilson_interval

__all__ = ["ClaimsSummary", "check_row", "summarise_claims", "claims_markdown"]


#: The artifact whose metrics give every paper claim's verdicts across random draws.
DRAWS_ARTIFACT = "fig12_claims_across_draws"

#: Where a reader gets more than the default single replicate of the sweep.
MORE_REPLICATES = "more: sensitivity.n_replicates, e.g. config/draws_200.yaml"

#: The gap benchmark's targets are defined for at least this many cases per effect.
GAP_FULL_CASES_PER_EFFECT = 10


@dataclass(frozen=True)
class ClaimsSummary:
    """Checks of every artifact, grouped by kind, with counts.

    Attributes
    ----------
    rows : list of dict
        One per check: ``artifact``, ``id``, ``kind`` (``claim`` for the paper's claims,
        ``target`` for the project's own, ``crosscheck``, ``validity``), ``statement``,
        ``expected``, ``observed``, ``reference``, ``passed``, ``note`` and ``draws``
        (``{k, n, low, high, draw0}`` across random draws, or across the replicates of
        Fig. 11's sweep with ``unit: "replicates"``; None when not rerun).
    counts : dict
        ``{kind: {"passed": n, "failed": n}}``.
    """

    rows: list[dict[str, Any]]
    counts: dict[str, dict[str, int]]

    def to_json(self) -> dict[str, Any]:
        """Return the content of ``claims.json``."""
        return {"counts": self.counts, "checks": self.rows}


def check_row(artifact: str, check: Check) -> dict[str, Any]:
    """Return one row of ``claims.json``: ``check``'s fields, its ``artifact``, no ``draws`` yet.

    Examples
    --------
    >>> row = check_row("figA", Check("c1", "claim", "paper §1: x", "> 1", 2.0, True))
    >>> list(row)[:3], row["draws"]
    (['artifact', 'id', 'kind'], None)
    """
    return {
        "artifact": artifact,
        "id": check.id,
        "kind": check.kind,
        "statement": check.statement,
        "expected": check.expected,
        "observed": check.observed,
        "reference": check.reference,
        "passed": bool(check.passed),
        "note": check.note,
        "draws": None,
    }


def _row(payload: Mapping[str, Any], check: Mapping[str, Any], project: Sequence[str]) -> dict:
    """Return the row of one JSON check; a claim that does not quote the paper is a target."""
    kind = check["kind"]
    is_paper = payload["artifact"] not in project and str(check["statement"]).startswith("paper")
    if kind == "claim" and not is_paper:
        kind = "target"
    parsed = Check(
        id=check["id"],
        kind=kind,
        statement=check["statement"],
        expected=check.get("expected"),
        observed=check.get("observed"),
        passed=bool(check["passed"]),
        reference=check.get("reference"),
        note=check.get("note"),
    )
    return check_row(payload["artifact"], parsed)


def _attach_draws(rows: list[dict[str, Any]], draws: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Give each paper claim its verdicts across draws; return validity rows for mismatches.

    Draw 0 is the main run, so its verdict must equal the figure's own, unless its entry says
    ``draw0_is_main_run: false`` (Fig. 9's K* per draw with fewer EM starts than the figure;
    Fig. 11 with several replicates, whose claims are judged on the mean over replicates).
    """
    mismatched = []
    for row in rows:
        entry = draws.get(f"{row['artifact']}:{row['id']}")
        if row["kind"] == "claim" and entry is not None:
            row["draws"] = dict(entry)
            same_run = entry.get("draw0_is_main_run", True)  # False: fewer EM starts per draw
            if same_run and bool(entry["draw0"]) != row["passed"]:
                mismatched.append(f"{row['artifact']}:{row['id']}")
    check = Check(
        id="draw0_verdicts_equal_the_figures",
        kind="validity",
        statement="draw 0 (the configured seeds) gives every claim the figure's verdict "
        "(Fig. 11: replicate 0 of a one-replicate sweep)",
        expected="0 claims that differ",
        observed=mismatched or 0,
        passed=not mismatched,
    )
    return [check_row(DRAWS_ARTIFACT, check)]


#: The causes a failed paper claim or crosscheck names in its note.
CAUSES: tuple[str, ...] = ("draw", "optimiser", "method")


def _cause_check(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Return the validity row: every failed paper claim and crosscheck names its cause.

    The note of each must contain one of :data:`CAUSES` (the draw, the optimiser or the
    method); the row lists those that do not.
    """
    silent = [
        f"{row['artifact']}:{row['id']}"
        for row in rows
        if row["kind"] in ("claim", "crosscheck")
        and not row["passed"]
        and not any(cause in (row["note"] or "") for cause in CAUSES)
    ]
    check = Check(
        id="every_failed_claim_names_its_cause",
        kind="validity",
        statement="every failed paper claim and crosscheck has a note naming its cause: "
        + ", ".join(CAUSES),
        expected="0 without a cause",
        observed=silent or 0,
        passed=not silent,
    )
    return check_row("claims", check)


def _replicate_entries(payload: Mapping[str, Any], level: float) -> dict[str, dict[str, Any]]:
    """Return the draws entries of an artifact that judged its claims per replicate.

    Reads the payload's ``metrics[REPLICATES_METRIC]`` (none: ``{}``) and gives each claim
    ``k`` of ``n`` replicates with its Wilson interval at ``level``, ``draw0`` (replicate 0's
    verdict), ``draw0_is_main_run`` (``replicate0_is_figure``) and ``unit: "replicates"``.

    Raises
    ------
    DtwinValueError
        If a claim lists no verdict or the block lacks ``verdicts``.
    """
    block = (payload.get("metrics") or {}).get(REPLICATES_METRIC)
    if not block:
        return {}
    artifact = payload["artifact"]
    if not isinstance(block, Mapping) or not isinstance(block.get("verdicts"), Mapping):
        raise DtwinValueError(f"{artifact}: metrics.{REPLICATES_METRIC} has no 'verdicts' mapping")
    entries = {}
    for check_id, verdicts in block["verdicts"].items():
        if not verdicts:
            raise DtwinValueError(
                f"{artifact}: metrics.{REPLICATES_METRIC} lists no replicate for {check_id}"
            )
        k, n = sum(bool(v) for v in verdicts), len(verdicts)
        low, high = wilson_interval(k, n, level)
        entries[f"{artifact}:{check_id}"] = {
            "k": k,
            "n": n,
            "share": k / n,
            "low": low,
            "high": high,
            "draw0": bool(verdicts[0]),
            "draw0_is_main_run": bool(block.get("replicate0_is_figure", n == 1)),
            "unit": "replicates",
        }
    return entries


def _target_counts(metrics: Mapping[str, Any], name: str) -> tuple[int, int]:
    """Return (k, n) of gap target ``name`` as the benchmark counted them, (0, 0) if none.

    From the ``gap_benchmark`` metrics' ``intervals`` (:func:`dtwin.gapbench.scores.
    benchmark_metrics`); a ``rig_`` target's from the rig family's (``metrics["rig"]``).
    """
    if name.startswith("rig_"):
        metrics, name = metrics.get("rig") or {}, name.removeprefix("rig_")
    interval = (metrics.get("intervals") or {}).get(name) or {}
    return int(interval.get("k", 0)), int(interval.get("n", 0))


def _attach_gap_cases(rows: list[dict[str, Any]], metrics: Mapping[str, Any], level: float) -> None:
    """Give the gap targets the number of cases per effect, an interval and 'indicative'."""
    per_effect = metrics.get("cases_per_effect") or {}
    fewest = min(per_effect.values()) if per_effect else 0
    for row in rows:
        if row["artifact"] != "gap_benchmark" or row["kind"] != "target":
            continue
        cases = {"cases_per_effect": fewest}
        k, n = _target_counts(metrics, row["id"].removeprefix("target_"))
        if n:
            cases.update(k=k, n=n)
            cases["low"], cases["high"] = wilson_interval(k, n, level)
        row["cases"] = cases
        if fewest < GAP_FULL_CASES_PER_EFFECT:
            row["note"] = (
                f"indicative: {fewest} cases per effect (the target is defined for >= "
                f"{GAP_FULL_CASES_PER_EFFECT}; config/gap_full.yaml)"
            )


def summarise_claims(
    payloads: Sequence[Mapping[str, Any]],
    project: Sequence[str] = (),
    level: float = 0.95,
) -> ClaimsSummary:
    """Gather the checks of artifact payloads (parsed JSON) into a :class:`ClaimsSummary`.

    Parameters
    ----------
    payloads : sequence of mapping
        Parsed artifact JSONs.
    project : sequence of str, default ()
        The project's own artifacts (``workflow/artifacts.yaml``: ``project``); their claims
        are targets. The :data:`DRAWS_ARTIFACT` payload, if given, adds the draws column; a
        payload with ``metrics[REPLICATES_METRIC]`` (Fig. 11) adds its claims' verdicts
        across its replicates to the same column.
    level : float, default 0.95
        Level of the Wilson intervals of the gap targets and of the claims across replicates
        (those across draws come with their own, ``draws.interval``).

    Raises
    ------
    DtwinValueError
        If a payload lacks ``artifact`` or ``checks``.
    """
    rows: list[dict[str, Any]] = []
    draws: dict[str, Any] = {}
    has_draws = False
    gap_metrics: Mapping[str, Any] = {}
    for payload in payloads:
        if "artifact" not in payload or "checks" not in payload:
            raise DtwinValueError("an artifact JSON must have 'artifact' and 'checks' keys")
        rows += [_row(payload, check, project) for check in payload["checks"]]
        if payload["artifact"] == DRAWS_ARTIFACT:
            draws.update(payload.get("metrics", {}).get("claims", {}))
            has_draws = True
        draws.update(_replicate_entries(payload, level))
        if payload["artifact"] == "gap_benchmark":
            gap_metrics = payload.get("metrics", {})
    if has_draws or draws:
        rows += _attach_draws(rows, draws)
    if gap_metrics:
        _attach_gap_cases(rows, gap_metrics, level)
    rows.append(_cause_check(rows))
    counts: dict[str, dict[str, int]] = {}
    for row in rows:
        tally = counts.setdefault(row["kind"], {"passed": 0, "failed": 0})
        tally["passed" if row["passed"] else "failed"] += 1
    return ClaimsSummary(rows=rows, counts=counts)


def _number(value: float) -> str:
    """Return a float as the checks read it: 4 significant digits, 3 decimals in [1, 1e7).

    A log-likelihood of -2115.8521 against a threshold of -2115.852 - 0.01 must not print as
    -2116 (which reads like a failure).
    """
    if value != value or value in (float("inf"), float("-inf")):
        return str(value)
    if 1 <= abs(value) < 1e7:
        return f"{value:.3f}".rstrip("0").rstrip(".")
    return f"{value:.4g}"


def _cell(value: Any, width: int = 90) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        text = _number(value)
    elif isinstance(value, (dict, list)):
        text = json.dumps(value, separators=(", ", ": "), default=str)
        text = _round_numbers(text)
    else:
        text = str(value)
    text = text.replace("|", "\\|").replace("\n", " ")
    return text if len(text) <= width else text[: width - 1] + "…"


def _round_numbers(text: str) -> str:
    return re.sub(r"-?\d+\.\d{4,}(e-?\d+)?", lambda m: _number(float(m.group(0))), text)


def _draw_cause(row: Mapping[str, Any]) -> str:
    """One clause on what the draws say about a failed claim ('' without draws)."""
    entry = row.get("draws")
    if not entry:
        return ""
    k, n = entry["k"], entry["n"]
    if entry.get("unit") == "replicates":
        if n == 1:
            return ""  # the main run's single replicate adds nothing to the verdict
        if k == 0:
            return f" (fails in all {n} sweep replicates: not the draw)"
        return f" (holds in {k} of {n} sweep replicates: depends on the draw)"
    if k == 0:
        return f" (fails in all {n} random draws: not the draw)"
    return f" (holds in {k} of {n} random draws: depends on the draw)"


def _reason(row: Mapping[str, Any]) -> str:
    if row["passed"]:
        return "yes" if not row["note"] else f"yes — {row['note']}"
    reason = (
        row["note"]
        or f"observed {_cell(row['observed'], 60)}; expected {_cell(row['expected'], 60)}"
    )
    return f"**no** — {reason}{_draw_cause(row)}"


def _draws_cell(row: Mapping[str, Any]) -> str:
    entry = row.get("draws")
    if not entry:
        return "– (not rerun across draws)"
    k, n = entry["k"], entry["n"]
    if entry.get("unit") == "replicates" and n == 1:
        return f"{k} of 1 sweep replicate (the main run; {MORE_REPLICATES})"
    unit = " sweep replicates" if entry.get("unit") == "replicates" else ""
    cell = f"{k} of {n}{unit} [{entry['low']:.2f}, {entry['high']:.2f}]"
    return cell + (f"; {_cell(entry['detail'], 200)}" if entry.get("detail") else "")


def _cases_cell(row: Mapping[str, Any]) -> str:
    cases = row.get("cases")
    if not cases:
        return "–"
    text = f"{cases['cases_per_effect']} per effect"
    if "n" in cases:
        text += f"; {cases['k']} of {cases['n']} [{cases['low']:.2f}, {cases['high']:.2f}]"
    return text


_SECTIONS = (
    (
        "claim",
        "Claims of the paper",
        (
            "artifact",
            "claim",
            "expected",
            "R's code",
            "ours",
            "reproduced",
            "holds in k of N draws (Fig. 11: sweep replicates) [95 % interval]",
        ),
    ),
    (
        "target",
        "The project's own targets",
        ("artifact", "target", "expected", "ours", "cases [95 % interval]", "met"),
    ),
    (
        "crosscheck",
        "Crosschecks against the authors' R code",
        ("artifact", "check", "expected", "observed", "agrees"),
    ),
    ("validity", "Validity checks", ("artifact", "check", "observed", "passed")),
)


def _cells(kind: str, row: Mapping[str, Any]) -> list[str]:
    if kind == "claim":
        return [
            row["artifact"],
            _cell(row["statement"], 140),
            _cell(row["expected"]),
            _cell(row["reference"]),
            _cell(row["observed"]),
            _reason(row),
            _draws_cell(row),
        ]
    if kind == "target":
        return [
            row["artifact"],
            _cell(row["statement"], 140),
            _cell(row["expected"]),
            _cell(row["observed"]),
            _cases_cell(row),
            _reason(row),
        ]
    if kind == "crosscheck":
        return [
            row["artifact"],
            _cell(row["statement"], 140),
            _cell(row["expected"]),
            _cell(row["observed"]),
            _reason(row),
        ]
    return [row["artifact"], row["id"], _cell(row["observed"], 60), _reason(row)]


def claims_markdown(summary: ClaimsSummary) -> str:
    """Render ``CLAIMS.md``: the paper's claims, the project's targets, crosschecks, validity."""
    claims = summary.counts.get("claim", {"passed": 0, "failed": 0})
    lines = [
        "# Paper claims vs this reproduction",
        "",
        f"**The paper's claims: {claims['passed']} of {claims['passed'] + claims['failed']} "
        "reproduced on our main run.** The project's own targets, the crosschecks and the "
        "validity checks are counted apart below.",
        "",
        "Generated by the `claims` rule from every artifact's JSON in `paper_figures/`. "
        "A claim is a statement of the paper, checked on our own run (numpy's random stream "
        "differs from R's, so numbers agree in kind, not digit by digit) and on N random "
        "draws of the single-draw pipeline (Fig. 12; draw 0 is the main run), Fig. 11's "
        "sweep claims on each replicate of the sweep alone (`sensitivity.n_replicates`, 1 by "
        "default as in R; replicate 0 is the main run's seeds); a crosscheck "
        "runs our code on the R code's own signals, where agreement can be exact; validity "
        "checks say an artifact is sound.",
        "",
        "| kind | passed | failed |",
        "|---|---|---|",
    ]
    names = {"claim": "paper's claims", "target": "project's own targets"}
    for kind, _, _ in _SECTIONS:
        tally = summary.counts.get(kind, {"passed": 0, "failed": 0})
        lines.append(f"| {names.get(kind, kind)} | {tally['passed']} | {tally['failed']} |")
    for kind, title, header in _SECTIONS:
        lines += [
            "",
            f"## {title}",
            "",
            "| " + " | ".join(header) + " |",
            "|" + "---|" * len(header),
        ]
        for row in (r for r in summary.rows if r["kind"] == kind):
            lines.append("| " + " | ".join(_cells(kind, row)) + " |")
    return "\n".join(lines) + "\n"
