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
                "statement": "x is big",
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
    assert summary.counts == {
        "claim": {"passed": 0, "failed": 1},
        "validity": {"passed": 1, "failed": 0},
        "crosscheck": {"passed": 1, "failed": 0},
    }
    assert [row["artifact"] for row in summary.rows] == ["figA", "figA", "figB"]


def test_markdown_reports_a_failed_claim_with_its_reason_and_r_number():
    text = claims_markdown(summarise_claims(PAYLOADS))
    claim_line = next(line for line in text.splitlines() if "x is big" in line)
    assert "**no**" in claim_line and "observed 0.5" in claim_line and "| 2 |" in claim_line
    assert text.index("## Claims") < text.index("## Crosschecks") < text.index("## Validity")
    assert "1.235e-09" in text


def test_malformed_payload_is_rejected():
    with pytest.raises(DtwinValueError, match="artifact"):
        summarise_claims([{"checks": []}])
