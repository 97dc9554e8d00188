"""CLAIMS.md gathers every check, reports failed claims with a reason, never hides them."""

from __future__ import annotations

import pytest

from dtwin._validation import DtwinValueError
from dtwin.claims import claims_markdown, summarise_claims

PAYLOADS = [
    {
        "artifact": "figA",
        "checks": [
            {
                "id": "c1",
                "kind": "claim",
                "statement": "paper §1: x is big",
                "expected": "> 1",
                "observed": 0.5,
                "passed": False,
                "reference": 2.0,
            },
            {
                "id": "v1",
                "kind": "validity",
                "statement": "finite",
                "expected": 0,
                "observed": 0,
                "passed": True,
            },
        ],
    },
    {
        "artifact": "figB",
        "checks": [
            {
                "id": "x1",
                "kind": "crosscheck",
                "statement": "matches R",
                "expected": "<= 1e-6",
                "observed": {"M0": 1.23456789e-9},
                "passed": True,
            },
        ],
    },
]


def test_counts_and_rows():
    summary = summarise_claims(PAYLOADS)
    # the failed claim c1 has no note: the cause check fails
    assert summary.counts == {
        "claim": {"passed": 0, "failed": 1},
        "validity": {"passed": 1, "failed": 1},
        "crosscheck": {"passed": 1, "failed": 0},
    }
    assert [row["artifact"] for row in summary.rows] == ["figA", "figA", "figB", "claims"]
    assert summary.rows[-1]["observed"] == ["figA:c1"]


@pytest.mark.parametrize(
    ("note", "passed"),
    [("optimiser: a low optimum", True), ("draw: seed 11 only", True), ("unclear", False)],
)
def test_a_failed_claim_must_name_its_cause(note, passed):
    payload = {"artifact": "figA", "checks": [{**PAYLOADS[0]["checks"][0], "note": note}]}
    row = summarise_claims([payload]).rows[-1]
    assert row["id"] == "every_failed_claim_names_its_cause" and row["passed"] is passed


def test_markdown_reports_a_failed_claim_with_its_reason_and_r_number():
    text = claims_markdown(summarise_claims(PAYLOADS))
    claim_line = next(line for line in text.splitlines() if "x is big" in line)
    assert "**no**" in claim_line and "observed 0.5" in claim_line and "| 2 |" in claim_line
    assert text.index("## Claims") < text.index("## Crosschecks") < text.index("## Validity")
    assert "1.235e-09" in text


def test_malformed_payload_is_rejected():
    with pytest.raises(DtwinValueError, match="artifact"):
        summarise_claims([{"checks": []}])


def _claim(artifact, check_id, statement, passed, **extra):
    return {
        "artifact": artifact,
        "checks": [
            {
                "id": check_id,
                "kind": "claim",
                "statement": statement,
                "expected": 1,
                "observed": 1,
                "passed": passed,
            }
        ],
        **extra,
    }


def test_headline_counts_the_papers_claims_only_and_lists_targets_apart():
    payloads = [
        _claim("figA", "p", "paper §2: a claim of the paper", True),
        _claim("figA", "own", "r_notes.md: our expectation of the optimiser", False),
        _claim("gap_benchmark", "target_x", "docs/gap.md target: x >= 1", True),
    ]
    summary = summarise_claims(payloads, project=["gap_benchmark"])
    assert summary.counts["claim"] == {"passed": 1, "failed": 0}
    assert summary.counts["target"] == {"passed": 1, "failed": 1}
    text = claims_markdown(summary)
    assert "The paper's claims: 1 of 1 reproduced" in text
    assert text.index("## Claims of the paper") < text.index("## The project's own targets")


def test_draws_column_and_a_draw0_that_disagrees_with_the_figure():
    draws = {
        "artifact": "fig12_claims_across_draws",
        "checks": [],
        "metrics": {
            "claims": {
                "figA:p": {
                    "k": 7,
                    "n": 20,
                    "share": 0.35,
                    "low": 0.18,
                    "high": 0.57,
                    "draw0": False,
                }
            }
        },
    }
    summary = summarise_claims([_claim("figA", "p", "paper: c", True), draws])
    failed = summarise_claims([_claim("figA", "p", "paper: c", False), draws])
    assert "holds in 7 of 20 random draws: depends on the draw" in claims_markdown(failed)
    text = claims_markdown(summary)
    assert "| 7 of 20 [0.18, 0.57] |" in text
    check = next(r for r in summary.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["passed"] is False and check["observed"] == ["figA:p"]


def test_a_draw0_with_fewer_em_starts_is_not_compared_and_its_detail_is_shown():
    entry = {"k": 0, "n": 10, "share": 0.0, "low": 0.0, "high": 0.28, "draw0": True}
    draws = {
        "artifact": "fig12_claims_across_draws",
        "checks": [],
        "metrics": {
            "claims": {
                "figA:p": {**entry, "draw0_is_main_run": False, "detail": "K* in 10 draws: 12 (10)"}
            }
        },
    }
    summary = summarise_claims([_claim("figA", "p", "paper: c", False), draws])
    check = next(r for r in summary.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["passed"] is True
    assert "| 0 of 10 [0.00, 0.28]; K* in 10 draws: 12 (10) |" in claims_markdown(summary)
    draws["metrics"]["claims"]["figA:p"]["draw0_is_main_run"] = True
    summary = summarise_claims([_claim("figA", "p", "paper: c", False), draws])
    check = next(r for r in summary.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["passed"] is False


def test_gap_targets_below_ten_cases_per_effect_are_marked_indicative():
    """The (k, n) of a gap target are those the benchmark counted (its metrics' intervals)."""
    rate = {"k": 1, "n": 2, "rate": 0.5, "low": 0.09, "high": 0.91}
    metrics = {
        "cases_per_effect": {"none": 2, "friction": 2},
        "intervals": {"none_accuracy": rate},
        "rig": {"intervals": {"module_accuracy": {**rate, "k": 3, "n": 4}}},
    }
    payload = _claim(
        "gap_benchmark",
        "target_none_accuracy",
        "docs/gap.md target: none_accuracy >= 0.9",
        False,
        metrics=metrics,
    )
    rig = _claim("gap_benchmark", "target_rig_module_accuracy", "rig target", False)["checks"]
    payload["checks"] += rig
    payload["checks"][0]["observed"] = 0.5
    summary = summarise_claims([payload], project=["gap_benchmark"])
    paper, rig_row = summary.rows[:2]
    assert paper["cases"]["k"] == 1 and paper["cases"]["n"] == 2
    assert rig_row["cases"]["k"] == 3 and rig_row["cases"]["n"] == 4
    assert "indicative: 2 cases per effect" in paper["note"]


def test_a_log_likelihood_prints_with_the_decimals_its_threshold_uses():
    payload = {
        "artifact": "figC",
        "checks": [
            {
                "id": "ll",
                "kind": "crosscheck",
                "statement": "reaches R",
                "expected": ">= -2115.852 - 0.01",
                "observed": -2115.8521234,
                "passed": True,
            }
        ],
    }
    assert "| -2115.852 |" in claims_markdown(summarise_claims([payload]))


def _sweep_payload(passed: bool, verdicts: list[bool], replicate0_is_figure: bool) -> dict:
    return _claim(
        "fig11_sensitivity",
        "all_positive",
        "paper §5: positive reductions in every configuration",
        passed,
        metrics={
            "claims_across_replicates": {
                "n_replicates": len(verdicts),
                "replicate0_is_figure": replicate0_is_figure,
                "verdicts": {"all_positive": verdicts},
            }
        },
    )


def test_sweep_claims_show_k_of_r_replicates():
    text = claims_markdown(summarise_claims([_sweep_payload(True, [True, False, True], False)]))
    line = next(line for line in text.splitlines() if "positive reductions" in line)
    assert "| 2 of 3 sweep replicates [0.21, 0.94] |" in line
    failed = summarise_claims([_sweep_payload(False, [False, True, False], False)])
    assert "(holds in 1 of 3 sweep replicates: depends on the draw)" in claims_markdown(failed)
    check = next(r for r in failed.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["passed"] is True  # several replicates: the figure judges their mean


def test_the_default_single_replicate_says_so_and_is_compared_with_the_figure():
    summary = summarise_claims([_sweep_payload(False, [False], True)])
    text = claims_markdown(summary)
    line = next(line for line in text.splitlines() if "positive reductions" in line)
    assert "| 0 of 1 sweep replicate (the main run; more: sensitivity.n_replicates, e.g. " in line
    assert "config/draws_200.yaml) |" in line and "random draws" not in line
    check = next(r for r in summary.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["passed"] is True
    mismatch = summarise_claims([_sweep_payload(True, [False], True)])
    check = next(r for r in mismatch.rows if r["id"] == "draw0_verdicts_equal_the_figures")
    assert check["observed"] == ["fig11_sensitivity:all_positive"]


def test_a_replicate_block_without_verdicts_is_rejected():
    payload = _sweep_payload(True, [], True)
    with pytest.raises(DtwinValueError, match="lists no replicate for all_positive"):
        summarise_claims([payload])
