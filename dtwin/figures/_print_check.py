"""What a reader relies on at print size, measured on the drawn figure.

:func:`drawn_texts` renders a figure once and records every piece of text the renderer
actually draws (titles, labels, tick labels, legends, annotations; not the hidden ones), with
its font size and its box on the page. :func:`print_check` turns that into one validity check:
the figure is one of the set's print widths, no text is smaller than
:data:`dtwin.figures._style.MIN_FONT_PT`, no two texts overlap and no text falls off the page.
:func:`axes_and_legends_check` is the second: every numeric axis is labelled, with a unit in
parentheses unless the figure declared the quantity unitless
(:func:`dtwin.figures._style.unitless`), and every legend entry draws the glyph of an artist
that is drawn in the figure (:func:`legend_mismatches`). :func:`reader_checks` returns both;
:func:`dtwin.figures._style.publish_artifact` appends them to every artifact, so the pipeline's
validity checks and the figure tests use this one implementation.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import combinations
from typing import Any

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection, LineCollection, PathCollection
from matplotlib.colors import to_rgba_array
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import Bbox

from dtwin.artifacts import Check
from dtwin.figures._style import COLUMN_WIDTH, FULL_WIDTH, MIN_FONT_PT, UNITLESS_GID

__all__ = [
    "DrawnText",
    "recording_texts",
    "agg_canvas",
    "drawn_texts",
    "text_overlaps",
    "print_check",
    "unlabelled_axes",
    "legend_mismatches",
    "axes_and_legends_check",
    "reader_checks",
    "MAX_HEIGHT",
]

#: Tallest figure that still fits a page with its caption, inches.
MAX_HEIGHT = 9.0
#: Allowed widths: full width (7.0–7.5 in) or one column (3.4–3.6 in).
WIDTHS: tuple[tuple[float, float], ...] = ((7.0, 7.5), (COLUMN_WIDTH - 0.1, COLUMN_WIDTH + 0.1))
#: Two texts overlap when their boxes share more than this share of the smaller box's area.
OVERLAP_SHARE = 0.01
#: Slack at the page edge before a text counts as off the page, inches (1 pixel at 100 dpi).
EDGE_SLACK_IN = 0.01

assert WIDTHS[0][0] <= FULL_WIDTH <= WIDTHS[0][1]


@dataclass(frozen=True)
class DrawnText:
    """One text the renderer drew: its string, font size (pt) and box (display pixels)."""

    text: str
    size_pt: float
    box: Bbox


@contextmanager
def recording_texts(renderer: Any) -> Iterator[list[DrawnText]]:
    """Record, while the block runs, every text ``renderer`` draws (once per text artist).

    Yields the list, filled as the figure is drawn; the renderer is restored afterwards.
    """
    seen: dict[int, DrawnText] = {}
    texts: list[DrawnText] = []
    original = renderer.draw_text

    def record(gc, x, y, s, prop, angle, ismath=False, mtext=None):
        if mtext is not None and id(mtext) not in seen and mtext.get_text().strip():
            seen[id(mtext)] = DrawnText(
                mtext.get_text(), float(prop.get_size_in_points()), mtext.get_window_extent()
            )
        return original(gc, x, y, s, prop, angle, ismath, mtext)

    renderer.draw_text = record
    try:
        yield texts
    finally:
        del renderer.draw_text
        texts.extend(seen.values())


def agg_canvas(figure: Figure) -> FigureCanvasAgg:
    """Return the figure's Agg canvas (attached first if the figure has another)."""
    if isinstance(figure.canvas, FigureCanvasAgg):
        return figure.canvas
    return FigureCanvasAgg(figure)


def drawn_texts(figure: Figure) -> list[DrawnText]:
    """Render ``figure`` with Agg and return every text actually drawn, once per text artist."""
    renderer = agg_canvas(figure).get_renderer()
    with recording_texts(renderer) as texts:
        figure.draw(renderer)
    return texts


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


def _off_page(texts: list[DrawnText], page: Bbox, dpi: float) -> list[str]:
    slack = EDGE_SLACK_IN * dpi
    return [
        t.text
        for t in texts
        if t.box.x0 < page.x0 - slack
        or t.box.y0 < page.y0 - slack
        or t.box.x1 > page.x1 + slack
        or t.box.y1 > page.y1 + slack
    ]


def print_check(figure: Figure, texts: list[DrawnText] | None = None) -> Check:
    """Return the validity check of the print rules for ``figure`` (see the module docstring).

    ``texts`` are the texts of a draw at the figure's current dpi (:func:`recording_texts`);
    by default the figure is drawn here (:func:`drawn_texts`). ``observed`` holds the size
    (in), the smallest font (pt), and the texts that are too small, overlap or fall off the
    page (at most five of each, shortened).
    """
    width, height = (float(v) for v in figure.get_size_inches())
    texts = drawn_texts(figure) if texts is None else texts
    small = sorted({t.text for t in texts if t.size_pt < MIN_FONT_PT - 1e-9})
    overlaps = text_overlaps(texts)
    off_page = _off_page(texts, figure.bbox, figure.dpi)
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


# --- axis labels and units ------------------------------------------------------------------

#: A tick label that reads as a number once mathtext, signs, % and thousands marks are removed.
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
#: A unit in an axis label: "(s)", "(m/s)", "[N]", "(%)"; an empty "()" does not count.
_UNIT = re.compile(r"[(\[][^()\[\]]*\S[^()\[\]]*[)\]]")


def _has_unit(label: str) -> bool:
    """Whether ``label`` has a unit in parentheses outside mathtext ("$x$ (m)", not "$f(k)$")."""
    return bool(_UNIT.search(re.sub(r"\$[^$]*\$", "", label)))


def _is_number(text: str) -> bool:
    plain = re.sub(r"\\mathdefault|\\times|[${}^\s,%]", "", text).replace("\u2212", "-")
    return bool(_NUMBER.fullmatch(plain))


def _numeric_ticks(axis: Axis) -> bool:
    """Whether ``axis`` draws tick labels and they are numbers (not categories)."""
    labels = [t.get_text() for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
    return bool(labels) and all(_is_number(text) for text in labels)


def _has_label(axis: Axis) -> bool:
    return bool(axis.label.get_visible() and axis.label.get_text().strip())


def _covering_label(ax: Axes, name: str, figure: Figure) -> Any:
    """Return the label naming ``ax``'s ``name`` axis (own, shared sibling's, figure's)."""
    axis = getattr(ax, f"{name}axis")
    if _has_label(axis):
        return axis.label
    shared = ax.get_shared_x_axes() if name == "x" else ax.get_shared_y_axes()
    for sibling in shared.get_siblings(ax):
        if sibling is not ax and _has_label(getattr(sibling, f"{name}axis")):
            return getattr(sibling, f"{name}axis").label
    figure_label = figure._supxlabel if name == "x" else figure._supylabel
    if figure_label is not None and figure_label.get_visible() and figure_label.get_text():
        return figure_label
    return None


def _panel_name(ax: Axes, number: int) -> str:
    """Return the panel's title without its letter's mathtext ("A Short title"), or its index."""
    title = ax.get_title(loc="left") or ax.get_title() or f"axes {number}"
    return _short(re.sub(r"\$\\mathbf\{(\w+)\}\$\s*", r"\1 ", title), 24)


def unlabelled_axes(figure: Figure) -> list[str]:
    """Return the numeric axes a reader cannot read: no label, or a label without its unit.

    An axis is checked when it draws numeric tick labels (categorical axes name themselves).
    Its label may be its own, a shared sibling's, or the figure's ``supxlabel``/``supylabel``;
    it must hold a unit in parentheses or brackets ("time (s)") unless the figure declared the
    quantity unitless (:func:`dtwin.figures._style.unitless`: a probability, a lag, K, a BIC).
    Each problem reads ``"<panel> x: no label"`` or ``"<panel> y: '<label>' has no unit"``.
    """
    problems = []
    for number, ax in enumerate(figure.axes):
        if not (ax.get_visible() and ax.axison):
            continue
        panel = _panel_name(ax, number)
        for name in ("x", "y"):
            if not _numeric_ticks(getattr(ax, f"{name}axis")):
                continue
            label = _covering_label(ax, name, figure)
            if label is None:
                problems.append(f"{panel} {name}: no label")
            elif label.get_gid() != UNITLESS_GID and not _has_unit(label.get_text()):
                problems.append(f"{panel} {name}: '{label.get_text()}' has no unit")
    return problems


# --- legends ----------------------------------------------------------------------------------


def _rgb(colors: Any) -> list[tuple[float, ...]]:
    """Opaque colours of ``colors`` as rounded RGB tuples (fully transparent ones dropped)."""
    try:
        array = to_rgba_array(colors)
    except (TypeError, ValueError):
        return []
    return [tuple(round(float(c), 3) for c in row[:3]) for row in array if row[3] > 0]


def _line_style(line: Line2D) -> str | None:
    style = line.get_linestyle()
    return None if style in ("None", "none", "", " ") or line.get_linewidth() <= 0 else style


def _marker_colors(line: Line2D) -> list[tuple[float, ...]]:
    return _rgb(line.get_markerfacecolor()) or _rgb(line.get_markeredgecolor())


def _glyphs(artist: Artist) -> set[tuple]:
    """Return what a reader sees of an artist: line, marker, fill or edge keys with their colour.

    Keys are ``("line", rgb, style)``, ``("marker", rgb)``, ``("fill", rgb)``, ``("edge", rgb)``.
    Line styles of collections are coarse (``"solid"`` or ``"patterned"``); a line glyph also
    yields its coarse key so a legend line matches a drawn line collection of its colour.
    """
    keys: set[tuple] = set()
    if isinstance(artist, Line2D):
        style = _line_style(artist)
        if style is not None:
            for rgb in _rgb(artist.get_color()):
                keys |= {("line", rgb, style), ("line", rgb, _coarse(style))}
        if artist.get_marker() not in (None, "None", "none", "", " "):
            keys |= {("marker", rgb) for rgb in _marker_colors(artist)}
    elif isinstance(artist, LineCollection):
        dash_patterns = [dashes for _, dashes in artist.get_linestyle()]
        styles = {"solid" if dashes is None else "patterned" for dashes in dash_patterns}
        keys |= {("line", rgb, s) for rgb in _rgb(artist.get_colors()) for s in styles}
    elif isinstance(artist, Collection):
        faces = _rgb(artist.get_facecolor())
        kind = "marker" if isinstance(artist, PathCollection) else "fill"
        keys |= {(kind, rgb) for rgb in faces or _rgb(artist.get_edgecolor())}
        if kind == "marker":
            keys |= {("fill", rgb) for rgb in faces}
    elif isinstance(artist, Patch):
        faces = _rgb(artist.get_facecolor()) if artist.get_fill() else []
        keys |= {("fill", rgb) for rgb in faces} or {
            ("edge", rgb) for rgb in _rgb(artist.get_edgecolor())
        }
    return keys


def _coarse(style: str) -> str:
    return "solid" if style in ("-", "solid") else "patterned"


def _drawn_glyphs(figure: Figure) -> set[tuple]:
    keys: set[tuple] = set()
    for ax in figure.axes:
        for artist in [*ax.lines, *ax.collections, *ax.patches]:
            if artist.get_visible():
                keys |= _glyphs(artist)
                if isinstance(artist, Patch):  # a drawn box also shows its edge colour
                    keys |= {("edge", rgb) for rgb in _rgb(artist.get_edgecolor())}
    return keys


def _legends(figure: Figure) -> list[Any]:
    found = [ax.get_legend() for ax in figure.axes if ax.get_legend() is not None]
    return [legend for legend in [*found, *figure.legends] if legend.get_visible()]


def _entry_matches(handle: Artist, drawn: set[tuple]) -> bool:
    """Whether every kind of glyph the legend handle shows is drawn somewhere in its colour."""
    wanted = _glyphs(handle)
    kinds = {key[0] for key in wanted}
    return bool(kinds) and all(
        any(key[0] == kind and key in drawn for key in wanted) for kind in kinds
    )


def legend_mismatches(figure: Figure) -> list[str]:
    """Return the legend entries whose glyph matches no drawn artist, or whose label is empty.

    A glyph matches when a visible line, marker, fill or edge of the same colour (and, for a
    line, the same dash pattern) is drawn in any panel of the figure: a legend may sit on an
    empty panel or on the figure. Repeated labels in one legend are reported too.
    """
    drawn = _drawn_glyphs(figure)
    problems = []
    for legend in _legends(figure):
        labels = [text.get_text() for text in legend.get_texts()]
        problems += [f"repeated legend label {label!r}" for label in _repeated(labels)]
        for handle, label in zip(legend.legend_handles, labels, strict=False):
            if not label.strip():
                problems.append("a legend entry without a label")
            elif handle is None or not _entry_matches(handle, drawn):
                problems.append(f"legend {_short(label, 30)!r}: no drawn artist looks like it")
    return problems


def _repeated(labels: list[str]) -> list[str]:
    return sorted({label for label in labels if labels.count(label) > 1})


def axes_and_legends_check(figure: Figure) -> Check:
    """Return the validity check that every axis is readable and every legend entry is drawn.

    See :func:`unlabelled_axes` and :func:`legend_mismatches`; ``observed`` lists at most five
    problems of each.
    """
    axes = unlabelled_axes(figure)
    legends = legend_mismatches(figure)
    return Check(
        id="axes_and_legends",
        kind="validity",
        statement=(
            "every numeric axis is labelled, with its unit unless the quantity is unitless; "
            "every legend entry shows the glyph of an artist drawn in the figure"
        ),
        expected={"unlabelled_axes": 0, "legend_mismatches": 0},
        observed={
            "n_axes": sum(1 for ax in figure.axes if ax.get_visible() and ax.axison),
            "n_legend_entries": sum(len(lg.get_texts()) for lg in _legends(figure)),
            "unlabelled_axes": axes[:5],
            "legend_mismatches": legends[:5],
        },
        passed=not axes and not legends,
    )


def reader_checks(figure: Figure, texts: list[DrawnText] | None = None) -> list[Check]:
    """Return every check of what a reader relies on (print size and text, axes and legends).

    :func:`print_check` (on ``texts`` if given), then :func:`axes_and_legends_check`.
    """
    return [print_check(figure, texts), axes_and_legends_check(figure)]
