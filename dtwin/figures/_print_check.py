"""What a reader relies on at print size, measured on the drawn figure.

:func:`drawn_texts` renders a figure once and records every piece of text the renderer
actually draws (titles, labels, tick labels, legends, annotations; not the hidden ones), with
its font size and its box on the page. :func:`print_check` turns that into one validity check:
the figure is one of the set's print widths, no text is smaller than
:data:`dtwin.figures._style.MIN_FONT_PT`, no two texts overlap and no text falls off the page.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from dtwin.artifacts import Check
from dtwin.figures._style import COLUMN_WIDTH, FULL_WIDTH, MIN_FONT_PT

__all__ = ["DrawnText", "drawn_texts", "text_overlaps", "print_check", "MAX_HEIGHT"]

#: Tallest figure that still fits a page with its caption, inches.
MAX_HEIGHT = 9.0
#: Allowed widths: full width (7.0–7.5 in) or one column (3.4–3.6 in).
WIDTHS: tuple[tuple[float, float], ...] = ((7.0, 7.5), (COLUMN_WIDTH - 0.1, COLUMN_WIDTH + 0.1))
#: Two texts overlap when their boxes share more than this share of the smaller box's area.
OVERLAP_SHARE = 0.01
#: Slack at the page edge before a text counts as off the page, pixels at the figure's dpi.
EDGE_SLACK_PX = 1.0

assert WIDTHS[0][0] <= FULL_WIDTH <= WIDTHS[0][1]


@dataclass(frozen=True)
class DrawnText:
    """One text the renderer drew: its string, font size (pt) and box (display pixels)."""

    text: str
    size_pt: float
    box: Bbox


def drawn_texts(figure: Figure) -> list[DrawnText]:
    """Render ``figure`` with Agg and return every text actually drawn, once per text artist."""
    canvas = figure.canvas if isinstance(figure.canvas, FigureCanvasAgg) else None
    canvas = canvas or FigureCanvasAgg(figure)
    renderer = canvas.get_renderer()
    seen: dict[int, DrawnText] = {}
    original = renderer.draw_text

    def record(gc, x, y, s, prop, angle, ismath=False, mtext=None):
        if mtext is not None and id(mtext) not in seen and mtext.get_text().strip():
            seen[id(mtext)] = DrawnText(
                mtext.get_text(), float(prop.get_size_in_points()), mtext.get_window_extent()
            )
        return original(gc, x, y, s, prop, angle, ismath, mtext)

    renderer.draw_text = record
    try:
        figure.draw(renderer)
    finally:
        del renderer.draw_text
    return list(seen.values())


def _overlap(a: Bbox, b: Bbox) -> float:
    width = min(a.x1, b.x1) - max(a.x0, b.x0)
    height = min(a.y1, b.y1) - max(a.y0, b.y0)
    if width <= 0 or height <= 0:
        return 0.0
    smaller = min(a.width * a.height, b.width * b.height)
    return width * height / smaller if smaller > 0 else 0.0


def text_overlaps(texts: list[DrawnText]) -> list[tuple[str, str]]:
    """Return the pairs of drawn texts whose boxes overlap (more than :data:`OVERLAP_SHARE`)."""
    return [
        (a.text, b.text)
        for a, b in combinations(texts, 2)
        if _overlap(a.box, b.box) > OVERLAP_SHARE
    ]


def _off_page(texts: list[DrawnText], page: Bbox) -> list[str]:
    slack = EDGE_SLACK_PX
    return [
        t.text
        for t in texts
        if t.box.x0 < page.x0 - slack
        or t.box.y0 < page.y0 - slack
        or t.box.x1 > page.x1 + slack
        or t.box.y1 > page.y1 + slack
    ]


def print_check(figure: Figure) -> Check:
    """Return the validity check of the print rules for ``figure`` (see the module docstring).

    ``observed`` holds the size (in), the smallest font (pt), and the texts that are too small,
    overlap or fall off the page (at most five of each, shortened).
    """
    width, height = (float(v) for v in figure.get_size_inches())
    texts = drawn_texts(figure)
    small = sorted({t.text for t in texts if t.size_pt < MIN_FONT_PT - 1e-9})
    overlaps = text_overlaps(texts)
    off_page = _off_page(texts, figure.bbox)
    width_ok = any(low <= width <= high for low, high in WIDTHS)
    observed: dict[str, Any] = {
        "width_in": round(width, 3),
        "height_in": round(height, 3),
        "min_font_pt": round(min((t.size_pt for t in texts), default=0.0), 2),
        "n_texts": len(texts),
        "too_small": [_short(s) for s in small[:5]],
        "overlapping": [[_short(a), _short(b)] for a, b in overlaps[:5]],
        "off_page": [_short(s) for s in off_page[:5]],
    }
    return Check(
        id="print_size_and_text",
        kind="validity",
        statement=(
            "drawn at print size (full width 7.0–7.5 in or one column 3.5 in, at most "
            f"{MAX_HEIGHT:g} in tall), every text at least {MIN_FONT_PT:g} pt, no two texts "
            "overlapping, no text off the page"
        ),
        expected={"width_in": WIDTHS, "min_font_pt": MIN_FONT_PT, "overlaps": 0, "off_page": 0},
        observed=observed,
        passed=bool(
            width_ok
            and height <= MAX_HEIGHT
            and texts
            and not small
            and not overlaps
            and not off_page
        ),
    )


def _short(text: str, n: int = 40) -> str:
    text = " ".join(text.split())
    return text if len(text) <= n else text[: n - 1] + "…"
