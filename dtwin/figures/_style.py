"""The figure style of the set, and a deterministic, atomic figure writer.

Every figure is drawn at its print size: :data:`FULL_WIDTH` (a journal's full text width) or
:data:`COLUMN_WIDTH` (one column), with :data:`BASE_FONT_PT` text in one font (DejaVu Sans,
shipped with matplotlib, so every machine draws the same glyphs) and mathtext notation
for signals (:func:`tex`). One colour map per meaning, used by every figure:

- :data:`REGIME_COLORS`: the scheduled regimes of the fault scenario;
- :data:`MODULE_COLORS`: the modules M0 … M4 (and :data:`SURROGATE_FILL` for how the twin
  replaces each module);
- :data:`BEFORE_COLOR` / :data:`AFTER_COLOR`: a residual before and after the correction;
- :data:`OURS_COLOR` / :data:`R_COLOR` / :data:`R_SIGNALS_COLOR`: our number, the R code's
  number, ours on R's signals;
- :data:`STATE_COLORS`: unlabelled HMM states (deliberately not the regime colours).

Titles are short (or absent) and start with a panel letter (:func:`panel_title`); provenance
and the paper-figure number go in the artifact JSON and the report caption. PNG files are
written at :data:`PNG_DPI` dpi beside a vector PDF (:func:`save_figure`), without timestamps,
so a rerun gives byte-identical files. :func:`publish_artifact` also checks the print rules
(:func:`dtwin.figures._print_check.print_check`) and fails the rule if a figure breaks them.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import font_manager
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from dtwin.artifacts import FigureArtifact, atomic_write, write_artifact

__all__ = [
    "FULL_WIDTH",
    "COLUMN_WIDTH",
    "BASE_FONT_PT",
    "MIN_FONT_PT",
    "PNG_DPI",
    "PHYSICS_COLOR",
    "SURROGATE_COLOR",
    "OURS_COLOR",
    "R_COLOR",
    "R_SIGNALS_COLOR",
    "ALT_METHOD_COLOR",
    "BAND_COLOR",
    "PAPER_BAND_COLOR",
    "MODULE_COLORS",
    "SURROGATE_FILL",
    "REGIME_COLORS",
    "STATE_COLORS",
    "BEFORE_COLOR",
    "AFTER_COLOR",
    "SIGNAL_UNITS",
    "RESIDUAL_UNITS",
    "UNITLESS_GID",
    "tex",
    "axis_label",
    "unitless",
    "label_cells",
    "apply_style",
    "new_figure",
    "panel_title",
    "save_figure",
    "publish_artifact",
    "shade_regimes",
    "warm_up",
]

#: Full text width of a journal page, inches (every full-width figure is drawn at this size).
FULL_WIDTH = 7.2
#: One column of a two-column page, inches.
COLUMN_WIDTH = 3.5
#: Body text (labels, legends), points; titles are one point larger, ticks half a point smaller.
BASE_FONT_PT = 8.0
#: No text of any figure is smaller than this (checked by :func:`publish_artifact`), points.
MIN_FONT_PT = 7.0
#: Margin the constrained layout keeps around every panel and the page edge, inches.
LAYOUT_PAD_IN = 0.06
#: Resolution of every PNG, dots per inch.
PNG_DPI = 300
#: Decimals of the figure's width and height that a laid-out position keeps
#: (:func:`_snap_layout`): 1e-9 of a 7-inch page is 5e-7 pt, far below a PDF's drawn precision.
LAYOUT_DECIMALS = 9

PHYSICS_COLOR = "#0b2545"
SURROGATE_COLOR = "#5fa8a0"
#: Our number wherever ours stands beside R's.
OURS_COLOR = PHYSICS_COLOR
#: The R code's number (its own draw or its own run).
R_COLOR = "#8c8c8c"
#: Our method on R's exact signals.
R_SIGNALS_COLOR = SURROGATE_COLOR
#: A second method of ours beside the configured one (Fig. 11: the paper's §4.3 correction).
ALT_METHOD_COLOR = "#CC79A7"
#: Confidence bands and white-noise limits.
BAND_COLOR = "#b3001b"
#: The range the paper claims, drawn as a shaded band.
PAPER_BAND_COLOR = "#f2d8a7"
#: Modules of the twin (Okabe–Ito, colour-blind safe; not the regime colours' order).
MODULE_COLORS = {
    "M0": "#56B4E9",
    "M1": "#0072B2",
    "M2a": "#009E73",
    "M2b": "#66C2A5",
    "M3": "#CC79A7",
    "M4": "#E69F00",
}
#: Box fill of how the twin replaces a module (paper Fig. 1).
SURROGATE_FILL = {"arx": "#d7ecea", "algebraic": "#f3e3c3", "source": "#e4e4e4"}
#: Ground-truth regimes of the fault scenario (Okabe–Ito, colour-blind safe).
REGIME_COLORS = {
    "Nominal": "#0072B2",
    "SensorNoisy": "#009E73",
    "DynamicsOff": "#D55E00",
    "Drift": "#E69F00",
}
#: Unlabelled HMM states S1 … S9 (Paul Tol's "muted"; deliberately not the regime colours).
STATE_COLORS = (
    "#332288",
    "#88CCEE",
    "#CC6677",
    "#DDCC77",
    "#117733",
    "#AA4499",
    "#44AA99",
    "#999933",
    "#882255",
)
BEFORE_COLOR = "#9db08f"
AFTER_COLOR = PHYSICS_COLOR
#: Unit of each signal of the pipeline (paper §3.1).
SIGNAL_UNITS = {
    "u_cmd": "N",
    "u_act": "N",
    "x": "m",
    "v": "m/s",
    "y_A": "m",
    "y_B": "m",
    "y_fused": "m",
    "z": "KPI units",
}
#: Unit of each residual channel (surrogate − physics of the module output).
RESIDUAL_UNITS = {
    "e0": "N",
    "e1": "m",
    "e2a": "m",
    "e2b": "m",
    "e3": "m",
    "e4": "KPI units",
}

#: gid of an axis label whose quantity has no unit (read by the figures' axes check).
UNITLESS_GID = "dtwin-unitless"

_TEX = {
    "u_cmd": r"$u_\mathrm{cmd}$",
    "u_act": r"$u_\mathrm{act}$",
    "x": r"$x$",
    "v": r"$v$",
    "y_A": r"$y_A$",
    "y_B": r"$y_B$",
    "y_fused": r"$y_\mathrm{fused}$",
    "z": r"$z$",
    "e0": r"$e_0$",
    "e1": r"$e_1$",
    "e2a": r"$e_{2a}$",
    "e2b": r"$e_{2b}$",
    "e3": r"$e_3$",
    "e4": r"$e_4$",
    "e_abs_sum": r"$\Sigma|e|$",
    "e_rms": r"$e_\mathrm{rms}$",
    "e1_diff": r"$\Delta e_1$",
    "e3_diff": r"$\Delta e_3$",
}

_METADATA = {
    ".png": {"Software": None},
    ".pdf": {"Creator": None, "Producer": None, "CreationDate": None},
}


def tex(name: str) -> str:
    r"""Return the mathtext of a signal, residual or feature name (the name itself if unknown).

    Examples
    --------
    >>> tex("u_act"), tex("e2a"), tex("other")
    ('$u_\\mathrm{act}$', '$e_{2a}$', 'other')
    """
    return _TEX.get(name, name)


def axis_label(name: str, units: Mapping[str, str] | None = None) -> str:
    """Return ``"<mathtext> (<unit>)"`` for a signal or residual (its unit from ``units``).

    Examples
    --------
    >>> axis_label("x")
    '$x$ (m)'
    """
    table = {**SIGNAL_UNITS, **RESIDUAL_UNITS, **(units or {})}
    unit = table.get(name)
    return f"{tex(name)} ({unit})" if unit else tex(name)


def unitless(ax: Axes, which: str = "y") -> None:
    """Declare that the quantity on ``ax``'s ``which`` axes ("x", "y" or "xy") has no unit.

    A probability, an autocorrelation, a lag count, a number of states, a BIC or a z-score is
    labelled without a unit; the declaration tells the axes check
    (:func:`dtwin.figures._print_check.unlabelled_axes`) that the missing unit is intended.
    """
    for name in which:
        getattr(ax, f"{name}axis").label.set_gid(UNITLESS_GID)


def _bundled_fonts_first() -> None:
    """Put the font files matplotlib ships first in its font list, so ties go to them.

    A system copy of a family the set uses (DejaVu Sans and its faces, another version) ties
    with matplotlib's own file on every property :func:`matplotlib.font_manager.findfont`
    scores, and a tie goes to whichever comes first in the font list, which is read from the
    user's font cache (``fontlist-*.json``, shared by every matplotlib of that version on the
    machine and rewritten by whichever process rebuilt it last). The PNG does not show which
    file was used (the same outlines); the PDF embeds it, so its bytes would change with the
    machine's state. The sort is stable and skipped when the list is already in order.
    """
    bundled = Path(matplotlib.get_data_path(), "fonts")
    fonts = font_manager.fontManager.ttflist
    ordered = sorted(fonts, key=lambda font: not Path(font.fname).is_relative_to(bundled))
    if ordered != fonts:
        fonts[:] = ordered
        # findfont's results are cached; matplotlib clears the cache itself when it adds a font
        font_manager.fontManager._findfont_cached.cache_clear()


def apply_style() -> None:
    """Set the project's matplotlib defaults: one font, print-size text, 300-dpi PNG.

    The font is matplotlib's own DejaVu Sans file, whatever else is installed
    (:func:`_bundled_fonts_first`), so a PDF's bytes do not depend on the machine.
    """
    _bundled_fonts_first()
    plt.rcParams.update(
        {
            "figure.dpi": 100,
            "savefig.dpi": PNG_DPI,
            "font.family": "DejaVu Sans",
            "mathtext.fontset": "dejavusans",
            "font.size": BASE_FONT_PT,
            "axes.titlesize": BASE_FONT_PT + 0.5,
            "axes.titlelocation": "left",
            "axes.labelsize": BASE_FONT_PT,
            "xtick.labelsize": BASE_FONT_PT - 0.5,
            "ytick.labelsize": BASE_FONT_PT - 0.5,
            "legend.fontsize": BASE_FONT_PT - 0.5,
            "figure.titlesize": BASE_FONT_PT + 1,
            "axes.linewidth": 0.6,
            "lines.linewidth": 1.0,
            "xtick.major.width": 0.6,
            "ytick.major.width": 0.6,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "axes.grid": True,
            "grid.alpha": 0.25,
            "grid.linewidth": 0.5,
            "legend.frameon": False,
            "pdf.fonttype": 42,
            "svg.hashsalt": "dtwin",
        }
    )


def new_figure(height: float, width: float = FULL_WIDTH) -> Figure:
    """Return an empty figure of print size ``width`` × ``height`` inches, constrained layout.

    Applies :func:`apply_style` first, so every figure of the set starts from the same defaults.
    """
    apply_style()
    figure = plt.figure(figsize=(width, height), layout="constrained")
    figure.get_layout_engine().set(w_pad=LAYOUT_PAD_IN, h_pad=LAYOUT_PAD_IN)
    return figure


def panel_title(ax: Axes, letter: str, text: str = "", **kwargs: Any) -> None:
    """Title ``ax`` with a bold panel letter and an optional short description, left-aligned."""
    ax.set_title(rf"$\mathbf{{{letter}}}$  {text}".rstrip(), loc="left", **kwargs)


def label_cells(ax: Axes, values: Any, fmt: str, dark: Any, fontsize: float) -> None:
    """Write each heatmap cell's value at its centre: white on a dark cell, black elsewhere.

    ``values`` (numbers, formatted with ``fmt``, e.g. ``"{:.1f}"``) and ``dark`` (booleans)
    have the heatmap's shape ``(n_rows, n_columns)``; cell ``(i, j)`` sits at ``x = j, y = i``,
    as ``imshow`` draws it.
    """
    for i, row in enumerate(values):
        for j, value in enumerate(row):
            ax.text(
                j,
                i,
                fmt.format(value),
                ha="center",
                va="center",
                fontsize=fontsize,
                color="white" if dark[i][j] else "black",
            )


def _save_file(figure: Figure, path: str | os.PathLike, tight: bool, dpi: float | None) -> None:
    """Save ``figure`` to ``path`` (format from the suffix), atomically and without timestamps."""
    metadata = _METADATA.get(os.path.splitext(str(path))[1].lower(), {})
    bbox = "tight" if tight else None

    def write(tmp: str) -> None:
        figure.savefig(tmp, metadata=metadata, dpi=dpi, bbox_inches=bbox)

    atomic_write(path, write)


def save_figure(
    figure: Figure,
    paths: Sequence[str | os.PathLike],
    tight: bool = True,
    dpi: float | None = None,
) -> None:
    """Save ``figure`` to every path (format from the suffix), atomically and without timestamps.

    PNG files carry no "Software" tag and PDF files no creation date or producer, so the same
    data gives byte-identical files on a rerun. ``tight=False`` keeps the figure's own size
    (the print size); ``tight=True`` crops to the drawn content. ``dpi`` defaults to
    matplotlib's ``savefig.dpi`` (:data:`PNG_DPI` once :func:`apply_style` ran). The figure is
    laid out once, at ``dpi`` (:func:`_lay_out_once`), and every file drawn from that layout.
    """
    _lay_out_once(figure, PNG_DPI if dpi is None else dpi)
    for path in paths:
        _save_file(figure, path, tight, dpi)
    plt.close(figure)


def _lay_out_once(figure: Figure, dpi: float = PNG_DPI) -> None:
    """Lay ``figure`` out at ``dpi``, round the positions (:func:`_snap_layout`), detach the engine.

    Without an engine ``savefig`` neither lays the figure out again at the file's dpi (72 for
    a PDF) nor draws it once without rendering to do so: every later save is one draw at
    these positions.
    """
    figure.dpi = dpi
    engine = figure.get_layout_engine()
    if engine is not None:
        engine.execute(figure)
        _snap_layout(figure)
    with plt.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        figure.set_layout_engine(None)


def _snap_layout(figure: Figure) -> None:
    """Round every position the layout engine set to :data:`LAYOUT_DECIMALS` figure fractions.

    The constrained layout's solver returns positions that differ between two processes in
    their last bits (17 ulps of an axes' height in fig02, with the same inputs); a PDF writes
    text positions with 10 decimals, so now and then one of them rounded the other way and the
    file's bytes changed on a rerun. Rounded positions are the same in every process; the
    page moves by less than 1e-9 of its size. Axes (colour bars included) and the figure's
    ``suptitle``, ``supxlabel`` and ``supylabel`` are what the engine places.
    """
    for ax in figure.axes:
        corners = ax.get_position(original=True).get_points()
        ax._set_position(Bbox(np.round(corners, LAYOUT_DECIMALS)))
    for text in (figure._suptitle, figure._supxlabel, figure._supylabel):
        if text is not None:
            text.set_position(tuple(np.round(text.get_position(), LAYOUT_DECIMALS)))


def publish_artifact(
    artifact: FigureArtifact, paths: Sequence[str | os.PathLike], json_path: str | os.PathLike
):
    """Save the figure at print size to ``paths``, check what a reader relies on, write its JSON.

    The figure is laid out once, at :data:`PNG_DPI`, and every file is drawn from that one
    layout (the layout engine is detached before they are saved, so neither the PNG nor the PDF
    lays the figure out again at its own dpi): each file is one draw. The texts the first
    PNG's draw puts on the page feed the reader checks
    (:func:`dtwin.figures._print_check.reader_checks`: size, smallest font, text overlaps,
    text inside the page; every numeric axis labelled with its unit; every legend entry
    drawn), which are appended to the artifact's checks. The figure's caption and paper
    number are written under ``"figure"``. Raises
    :class:`dtwin.artifacts.ArtifactValidityError` (after writing the JSON) when a validity
    check failed, so the rule fails and Snakemake removes its outputs.
    """
    from dtwin.figures._print_check import agg_canvas, reader_checks, recording_texts

    figure, checks = artifact.figure, None
    _lay_out_once(figure)
    for path in paths:
        if checks is None and str(path).lower().endswith(".png"):
            with recording_texts(agg_canvas(figure).get_renderer()) as texts:
                _save_file(figure, path, tight=False, dpi=PNG_DPI)
            checks = reader_checks(figure, texts)
        else:
            _save_file(figure, path, tight=False, dpi=PNG_DPI)
    checks = reader_checks(figure) if checks is None else checks
    plt.close(figure)
    return write_artifact(
        json_path,
        artifact.name,
        paths,
        artifact.metrics,
        [*artifact.checks, *checks],
        figure=artifact.figure_info(),
    )


def warm_up() -> None:
    """Draw and save a small figure in the set's style, to memory, so this process's caches fill.

    The job server (:mod:`dtwin._job_server`) runs this once before it forks the figure jobs:
    matplotlib's font lookup and font files, its mathtext parser and the PNG and PDF writers'
    first-use set-up are then paid once per run instead of once per figure (~0.07 CPU-s a
    figure). Nothing is written to disk and matplotlib's settings are restored; the figures
    drawn afterwards are byte-identical.
    """
    with plt.rc_context():
        figure = new_figure(1.0, COLUMN_WIDTH)
        ax = figure.add_subplot()
        ax.plot([0.0, 1.0], [0.0, 1.0], label=tex("x"))
        panel_title(ax, "a", "warm-up")
        ax.set_xlabel(axis_label("u_act"))
        ax.legend()
        _lay_out_once(figure)
        for suffix in (".png", ".pdf"):
            figure.savefig(io.BytesIO(), format=suffix[1:], metadata=_METADATA[suffix])
        plt.close(figure)


def shade_regimes(
    ax: Axes, spans: Sequence[tuple[str, float, float]], alpha: float = 0.12, lines: bool = True
) -> None:
    """Shade each scheduled regime in its colour and mark the boundaries with dashed lines."""
    for regime, start, end in spans:
        ax.axvspan(start, end, color=REGIME_COLORS.get(regime, "#dddddd"), alpha=alpha, lw=0)
        if lines and start > spans[0][1]:
            ax.axvline(start, color="#555555", lw=0.6, ls="--")
