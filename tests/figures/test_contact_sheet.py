"""The report's landing page (dtwin/figures/_contact_sheet.py), fast, on small inputs.

The workflow test (tests/workflow/test_workflow.py, slow) renders the real page in headless
Chromium.
"""

from __future__ import annotations

import base64
import io
import re

import pytest
from PIL import Image

from dtwin.figures._contact_sheet import contact_sheet_html, thumbnail_png


def png(width: int, height: int, color: str = "navy") -> bytes:
    buffer = io.BytesIO()
    Image.new("RGB", (width, height), color).save(buffer, format="PNG")
    return buffer.getvalue()


def payload(name: str, caption: str, checks: list[dict]) -> dict:
    return {
        "artifact": name,
        "checks": checks,
        "figure": {"caption": caption, "paper_figure": "Fig. 5"},
    }


CLAIMS = {
    "counts": {
        "claim": {"passed": 1, "failed": 1},
        "crosscheck": {"passed": 9, "failed": 0},
        "validity": {"passed": 30, "failed": 0},
    },
    "checks": [
        {"artifact": "fig05", "id": "lowered_in_m1", "kind": "claim", "passed": False,
         "note": "draw: the DynamicsOff mean of e1 is -0.0006"},
        {"artifact": "fig05", "id": "lowered_in_m3", "kind": "claim", "passed": True,
         "note": None},
        {"artifact": "fig05", "id": "finite", "kind": "validity", "passed": True, "note": None},
    ],
}  # fmt: skip


def test_a_thumbnail_keeps_the_aspect_and_never_enlarges():
    small = Image.open(io.BytesIO(thumbnail_png(png(2160, 1920), 480)))
    assert small.size == (480, 427)
    assert Image.open(io.BytesIO(thumbnail_png(png(300, 100), 480))).size == (300, 100)
    with pytest.raises(ValueError, match="width_px must be at least 1"):
        thumbnail_png(png(10, 10), 0)


def test_the_sheet_shows_every_figure_its_finding_and_the_claims_summary():
    finding = "e1 unchanged: a draw with a zero-mean window. More text."
    payloads = [payload("fig05", finding, CLAIMS["checks"]), payload("fig01", "Twin.", [])]
    thumbnails = {"fig05": thumbnail_png(png(2160, 1920)), "fig01": thumbnail_png(png(900, 400))}
    html = contact_sheet_html(payloads, thumbnails, CLAIMS)
    assert "The paper's claims: 1 of 2 reproduced" in html
    assert "crosschecks on the R code's signals 9 of 9" in html
    assert "fig05:lowered_in_m1</b> — draw: the DynamicsOff mean" in html
    cards = re.findall(r'<a class="card".*?</a>', html)
    assert len(cards) == 2
    assert "app.showResultInfo('paper_figures/fig05.png')" in cards[0]
    assert f"{finding}</div>" in cards[0]  # a short caption whole
    long = "A first sentence that says what the figure finds. " * 4
    card = contact_sheet_html([payload("fig01", long, [])], {"fig01": png(4, 4)}, CLAIMS)
    assert "figure finds. A first sentence that says what the figure finds.</div>" in card
    long = "The published Fig. 10 used RMCDA 0.3, whose weights scale the alternatives. " * 3
    card = contact_sheet_html([payload("fig10", long, [])], {"fig10": png(4, 4)}, CLAIMS)
    assert (
        "The published Fig. 10 used RMCDA 0.3, whose weights scale the alternatives.</div>" in card
    )
    assert '<span class="fails">1/2 claims hold</span>' in cards[0]
    assert "no claim to check" in cards[1]
    uri = re.search(r'src="data:image/png;base64,([^"]+)"', cards[0]).group(1)
    assert Image.open(io.BytesIO(base64.b64decode(uri))).size == (480, 427)
    assert contact_sheet_html(payloads, thumbnails, CLAIMS) == html  # deterministic


def test_a_figure_without_thumbnail_is_named():
    with pytest.raises(ValueError, match=r"missing: \['fig01'\]"):
        contact_sheet_html([payload("fig01", "x", [])], {}, CLAIMS)
