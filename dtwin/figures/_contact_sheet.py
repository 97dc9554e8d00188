"""The report's landing page: every figure as a thumbnail with its one-line finding.

``make report`` (``snakemake --report``) opens on the workflow description
(``workflow/report/workflow.rst``), which inserts the HTML fragment :func:`contact_sheet_html`
returns: the claims summary of ``CLAIMS.md`` (counts per kind and the paper's claims that fail,
each with its cause) above one card per artifact (thumbnail, paper figure number, the first
sentences of the JSON's ``figure.caption`` and how many of its claims hold). A reader sees the
whole reproduction on one screen and clicks a card to open the figure in the report.

The fragment is self-contained (thumbnails are data URIs, the style is inline) and
deterministic: the same figures and checks give the same bytes.
"""

from __future__ import annotations

import base64
import html
import io
import re
from collections.abc import Mapping, Sequence
from typing import Any

from PIL import Image

__all__ = ["thumbnail_png", "contact_sheet_html", "SHEET_END_COLOR", "THUMBNAIL_WIDTH_PX"]

#: Width of each thumbnail, pixels (about a sixth of a 300-dpi full-width figure).
THUMBNAIL_WIDTH_PX = 480
#: Colour of the rule that closes the sheet (a screenshot test finds it to prove the whole
#: sheet is on one screen).
SHEET_END_COLOR = "#0b2545"
#: A finding is cut to this many characters (the full caption is the card's tooltip).
FINDING_CHARS = 120

_SENTENCE_END = re.compile(r"\.\s(?=[A-Z])")

_STYLE = f"""
<style>
.prose:has(.dtwin-sheet) {{ max-width: none; width: min(1180px, calc(100vw - 390px)); }}
.h-screen:has(.dtwin-sheet) {{ align-items: flex-start; justify-content: flex-start; }}
.dtwin-sheet {{ font: 12px/1.3 "DejaVu Sans", sans-serif; color: #222; }}
.dtwin-sheet h2 {{ font-size: 16px; margin: 0 0 4px 0; }}
.dtwin-sheet p {{ margin: 2px 0; }}
.dtwin-sheet .grid {{ display: grid; grid-template-columns: repeat(5, minmax(0, 1fr));
  gap: 8px; margin-top: 8px; }}
.dtwin-sheet a.card {{ display: block; border: 1px solid #ddd; border-radius: 4px;
  padding: 4px; color: inherit; text-decoration: none; background: #fff; }}
.dtwin-sheet a.card:hover {{ border-color: #0072B2; }}
.dtwin-sheet img {{ display: block; width: 100%; height: 104px; object-fit: contain;
  margin: 0 0 3px 0; }}
.dtwin-sheet .name {{ font-weight: bold; }}
.dtwin-sheet .held {{ color: #009E73; font-weight: bold; }}
.dtwin-sheet .fails {{ color: #b3001b; font-weight: bold; }}
.dtwin-sheet .finding {{ font-size: 11px; }}
.dtwin-sheet ul {{ margin: 2px 0 0 16px; padding: 0; font-size: 11px; }}
.dtwin-sheet hr.end {{ border: 0; border-top: 6px solid {SHEET_END_COLOR}; margin: 8px 0 0 0; }}
</style>
"""


def thumbnail_png(png: bytes, width_px: int = THUMBNAIL_WIDTH_PX) -> bytes:
    """Return a PNG of ``png`` scaled to ``width_px`` wide (aspect kept, never enlarged).

    Examples
    --------
    >>> import io
    >>> from PIL import Image
    >>> buffer = io.BytesIO()
    >>> Image.new("RGB", (960, 300), "white").save(buffer, format="PNG")
    >>> Image.open(io.BytesIO(thumbnail_png(buffer.getvalue(), 480))).size
    (480, 150)
    """
    if width_px < 1:
        raise ValueError(f"width_px must be at least 1 (got {width_px})")
    image = Image.open(io.BytesIO(png)).convert("RGB")
    if image.width > width_px:
        height = max(1, round(image.height * width_px / image.width))
        image = image.resize((width_px, height), Image.Resampling.LANCZOS)
    buffer = io.BytesIO()
    image.save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def _finding(caption: str) -> str:
    """Return the caption's whole sentences that fit :data:`FINDING_CHARS`, else its cut start."""
    text = " ".join(caption.split())
    if len(text) <= FINDING_CHARS:
        return text
    # a sentence ends at ". " before a capital ("Fig. 10 used" does not end one)
    ends = [m.start() for m in _SENTENCE_END.finditer(text, 0, FINDING_CHARS + 1)]
    end = ends[-1] if ends else -1
    return text[: end + 1] if end >= FINDING_CHARS // 2 else text[: FINDING_CHARS - 1] + "…"


def _claim_rows(rows: Sequence[Mapping[str, Any]], artifact: str) -> list[Mapping[str, Any]]:
    return [r for r in rows if r["artifact"] == artifact and r["kind"] in ("claim", "target")]


def _badge(claims: Sequence[Mapping[str, Any]]) -> str:
    if not claims:
        return '<span class="held">no claim to check</span>'
    held = sum(bool(r["passed"]) for r in claims)
    css = "held" if held == len(claims) else "fails"
    word = "claim" if len(claims) == 1 else "claims"
    return f'<span class="{css}">{held}/{len(claims)} {word} hold</span>'


def _card(payload: Mapping[str, Any], thumbnail: bytes, rows: Sequence[Mapping[str, Any]]) -> str:
    artifact = str(payload["artifact"])
    info = payload.get("figure") or {}
    caption = str(info.get("caption") or "")
    label = info.get("paper_figure") or "project"
    uri = "data:image/png;base64," + base64.b64encode(thumbnail).decode("ascii")
    path = f"paper_figures/{artifact}.png"
    return (
        f'<a class="card" href="javascript:app.showResultInfo(\'{path}\')" '
        f'title="{html.escape(caption)}">'
        f'<img src="{uri}" alt="{html.escape(artifact)}">'
        f'<span class="name">{html.escape(str(label))} · {html.escape(artifact)}</span> '
        f"{_badge(_claim_rows(rows, artifact))}"
        f'<div class="finding">{html.escape(_finding(caption))}</div></a>'
    )


def _count(counts: Mapping[str, Mapping[str, int]], kind: str) -> str:
    tally = counts.get(kind, {"passed": 0, "failed": 0})
    return f"{tally['passed']} of {tally['passed'] + tally['failed']}"


def _failed_claims(rows: Sequence[Mapping[str, Any]], n_shown: int) -> str:
    failed = [r for r in rows if r["kind"] == "claim" and not r["passed"]]
    items = []
    for row in failed[:n_shown]:
        cause = str(row.get("note") or "no cause recorded")
        cause = cause if len(cause) <= 90 else cause[:89] + "…"
        items.append(
            f"<li><b>{html.escape(row['artifact'])}:{html.escape(row['id'])}</b> — "
            f"{html.escape(cause)}</li>"
        )
    if len(failed) > n_shown:
        items.append(f"<li>… {len(failed) - n_shown} more in CLAIMS.md</li>")
    return f"<ul>{''.join(items)}</ul>" if items else ""


def contact_sheet_html(
    payloads: Sequence[Mapping[str, Any]],
    thumbnails: Mapping[str, bytes],
    claims: Mapping[str, Any],
    n_failed_shown: int = 5,
) -> str:
    """Return the landing page's HTML fragment: the claims summary, then one card per figure.

    Parameters
    ----------
    payloads : sequence of mapping
        Parsed artifact JSONs, in the order the cards are shown (``artifact``, ``checks``,
        ``figure`` with ``caption`` and ``paper_figure``).
    thumbnails : mapping
        Artifact name → thumbnail PNG bytes (:func:`thumbnail_png`).
    claims : mapping
        The content of ``claims.json`` (``counts`` per kind, ``checks`` rows).
    n_failed_shown : int, default 5
        Failed paper claims listed with their cause (the rest are counted).

    Raises
    ------
    ValueError
        If an artifact has no thumbnail.
    """
    missing = [p["artifact"] for p in payloads if p["artifact"] not in thumbnails]
    if missing:
        raise ValueError(f"thumbnails must cover every artifact (missing: {missing})")
    counts, rows = claims.get("counts", {}), claims.get("checks", [])
    summary = (
        f"<p><b>The paper's claims: {_count(counts, 'claim')} reproduced on our main run.</b> "
        f"Project targets {_count(counts, 'target')} · crosschecks on the R code's signals "
        f"{_count(counts, 'crosscheck')} · validity checks {_count(counts, 'validity')}. "
        "Click a figure to open it; CLAIMS.md has every check.</p>"
    )
    cards = "".join(_card(p, thumbnails[p["artifact"]], rows) for p in payloads)
    return (
        f'{_STYLE}<div class="dtwin-sheet"><h2>The reproduction on one screen</h2>{summary}'
        f"{_failed_claims(rows, n_failed_shown)}"
        f'<div class="grid">{cards}</div><hr class="end"></div>\n'
    )
