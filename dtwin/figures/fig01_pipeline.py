"""Paper Fig. 1: the six-module twin, drawn from the wiring table the code runs on."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import FancyBboxPatch

from dtwin.artifacts import Check, FigureArtifact
from dtwin.config_sections import ArxSettings
from dtwin.figures._style import BAND_COLOR, SURROGATE_FILL, new_figure, tex
from dtwin.twin.wiring import MODULES, Module

__all__ = ["fig01_pipeline", "PipelineLayout", "layout_pipeline", "plot_pipeline"]

SOURCE = "Command generator"
COLUMN_SPACING = 1.45
ROW_SPACING = 1.0
BOX_WIDTH, BOX_HEIGHT = 1.0, 0.62
#: Spread of the entry points on a box fed by several arrows (data units, top to bottom).
ENTRY_SPREAD = 0.22
#: Distance of an arrow's label from the arrow, points.
LABEL_OFFSET_PT = 3.0
#: Length of the arrows of the twin's final outputs beyond the last column, data units.
SINK_LENGTH = 0.45


@dataclass(frozen=True)
class PipelineLayout:
    """Where each box goes and which arrows join them.

    Attributes
    ----------
    positions : dict of node name to (column, row)
    edges : list of (producer, consumer, signal labels)
    sinks : list of (module, signal) for outputs no module reads (the twin's final outputs)
    """

    positions: dict[str, tuple[float, float]]
    edges: list[tuple[str, str, str]]
    sinks: list[tuple[str, str]]


def layout_pipeline(modules: Sequence[Module]) -> PipelineLayout:
    """Place modules in columns by data-flow depth and list the edges of the wiring table."""
    producer = {"u_cmd": SOURCE}
    depth = {SOURCE: 0}
    for module in modules:
        depth[module.name] = 1 + max(depth[producer[signal]] for signal in module.inputs)
        for signal in module.outputs:
            producer[signal] = module.name
    columns: dict[int, list[str]] = {}
    for name, column in depth.items():
        columns.setdefault(column, []).append(name)
    positions = {}
    for column, names in columns.items():
        for row, name in enumerate(names):
            positions[name] = (
                COLUMN_SPACING * column,
                ROW_SPACING * ((len(names) - 1) / 2.0 - row),
            )
    grouped: dict[tuple[str, str], list[str]] = {}
    for module in modules:
        for signal in module.inputs:
            grouped.setdefault((producer[signal], module.name), []).append(signal)
    edges = [(src, dst, ", ".join(signals)) for (src, dst), signals in grouped.items()]
    consumed = {signal for module in modules for signal in module.inputs}
    sinks = [(m.name, s) for m in modules for s in m.outputs if s not in consumed]
    return PipelineLayout(positions=positions, edges=edges, sinks=sinks)


def _box(ax: plt.Axes, center: tuple[float, float], text: str, color: str) -> None:
    width, height = BOX_WIDTH, BOX_HEIGHT
    x, y = center
    ax.add_patch(
        FancyBboxPatch(
            (x - width / 2, y - height / 2),
            width,
            height,
            boxstyle="round,pad=0.02,rounding_size=0.06",
            facecolor=color,
            edgecolor="#333333",
            linewidth=0.8,
        )
    )
    ax.text(x, y, text, ha="center", va="center", fontsize=7.5, linespacing=1.15)


def _label_side(start: tuple[float, float], end: tuple[float, float]) -> tuple[float, float]:
    """Return the arrow's unit normal pointing away from the middle row (up on the middle row)."""
    dx, dy = end[0] - start[0], end[1] - start[1]
    length = float(np.hypot(dx, dy)) or 1.0
    up = (start[1] + end[1]) / 2 >= -1e-9
    normal = (-dy, dx) if up else (dy, -dx)
    return normal[0] / length, normal[1] / length


def _arrow(ax: plt.Axes, start: tuple[float, float], end: tuple[float, float], label: str) -> None:
    """Draw an arrow with its signal label beside it, offset perpendicular to the line."""
    ax.annotate(
        "",
        xy=end,
        xytext=start,
        arrowprops={"arrowstyle": "-|>", "color": "#333333", "lw": 0.9, "shrinkA": 0, "shrinkB": 0},
    )
    nx, ny = _label_side(start, end)
    mid = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
    ax.annotate(
        ", ".join(tex(s.strip()) for s in label.split(",")),
        mid,
        xytext=(LABEL_OFFSET_PT * nx, LABEL_OFFSET_PT * ny),
        textcoords="offset points",
        ha="center" if abs(nx) < 0.3 else ("right" if nx < 0 else "left"),
        va="bottom" if ny > 0 else "top",
        fontsize=8,
    )


def _entry_points(layout: PipelineLayout) -> dict[tuple[str, str], tuple[float, float]]:
    """Where each edge enters its consumer: spread over the left edge when several arrive."""
    entries: dict[tuple[str, str], tuple[float, float]] = {}
    consumers = {dst for _, dst, _ in layout.edges}
    for dst in consumers:
        sources = sorted(
            (src for src, d, _ in layout.edges if d == dst),
            key=lambda name: -layout.positions[name][1],
        )
        x, y = layout.positions[dst]
        offsets = np.linspace(ENTRY_SPREAD / 2, -ENTRY_SPREAD / 2, len(sources))
        for src, offset in zip(sources, offsets if len(sources) > 1 else [0.0], strict=True):
            entries[(src, dst)] = (x - BOX_WIDTH / 2, y + float(offset))
    return entries


def plot_pipeline(modules: Sequence[Module], surrogate_labels: Mapping[str, str]) -> Figure:
    """Draw paper Fig. 1 from the wiring table.

    Parameters
    ----------
    modules : sequence of Module
        The wiring table (:data:`dtwin.twin.wiring.MODULES`).
    surrogate_labels : mapping of module name to str
        How the twin replaces each module (``"ARX(2,2)"``, ``"algebraic"``).
    """
    layout = layout_pipeline(modules)
    by_name = {module.name: module for module in modules}
    figure = new_figure(3.2)
    ax = figure.add_subplot()
    half_width = BOX_WIDTH / 2
    for name, center in layout.positions.items():
        if name == SOURCE:
            _box(ax, center, "Command\ngenerator", SURROGATE_FILL["source"])
            continue
        module = by_name[name]
        title = textwrap.fill(module.title, 15)
        text = f"{module.name}\n{title}\ntwin: {surrogate_labels.get(name, '?')}"
        _box(ax, center, text, SURROGATE_FILL[module.surrogate])
        ax.text(
            center[0],
            center[1] - BOX_HEIGHT / 2 - 0.04,
            f"residual {tex(module.residual)}",
            ha="center",
            va="top",
            fontsize=7.5,
            color=BAND_COLOR,
        )
    entries = _entry_points(layout)
    for src, dst, label in layout.edges:
        x0, y0 = layout.positions[src]
        _arrow(ax, (x0 + half_width, y0), entries[(src, dst)], label)
    x_end = max(x for x, _ in layout.positions.values()) + half_width + SINK_LENGTH
    for name, signal in layout.sinks:
        x0, y0 = layout.positions[name]
        _arrow(ax, (x0 + half_width, y0), (x_end, y0), signal)
    ys = [p[1] for p in layout.positions.values()]
    ax.set_xlim(-half_width - 0.05, x_end + 0.3)
    ax.set_ylim(min(ys) - 0.75, max(ys) + 0.45)
    ax.set_axis_off()
    legend = [
        FancyBboxPatch((0, 0), 1, 1, facecolor=SURROGATE_FILL["arx"], edgecolor="#333333"),
        FancyBboxPatch((0, 0), 1, 1, facecolor=SURROGATE_FILL["algebraic"], edgecolor="#333333"),
    ]
    ax.legend(
        legend,
        ["ARX(na, nb) surrogate", "recomputed from upstream twin signals"],
        loc="lower left",
        borderaxespad=0,
    )
    return figure


def fig01_pipeline(arx: ArxSettings) -> FigureArtifact:
    """Paper Fig. 1 drawn from :data:`dtwin.twin.wiring.MODULES`."""
    orders = arx.orders
    labels = {
        m.name: (
            f"ARX({orders[m.name].na},{orders[m.name].nb})" if m.surrogate == "arx" else "algebraic"
        )
        for m in MODULES
    }
    figure = plot_pipeline(MODULES, labels)
    layout = layout_pipeline(MODULES)
    wiring_edges = sorted({(s, m.name) for m in MODULES for s in m.inputs})
    drawn_signals = sorted(
        (signal.strip(), dst) for _, dst, label in layout.edges for signal in label.split(",")
    )
    checks = [
        Check(
            id="every_module_drawn",
            kind="validity",
            statement="every module of the wiring table has a box",
            expected=len(MODULES),
            observed=len(layout.positions) - 1,
            passed=len(layout.positions) - 1 == len(MODULES),
        ),
        Check(
            id="every_connection_drawn",
            kind="validity",
            statement="every (signal, consumer) pair of the wiring table has an arrow",
            expected=len(wiring_edges),
            observed=len(drawn_signals),
            passed=drawn_signals == wiring_edges,
        ),
    ]
    metrics = {
        "modules": [
            {
                "name": m.name,
                "title": m.title,
                "inputs": list(m.inputs),
                "outputs": list(m.outputs),
                "residual": m.residual,
                "twin": labels[m.name],
            }
            for m in MODULES
        ],
        "edges": [{"from": src, "to": dst, "signals": label} for src, dst, label in layout.edges],
    }
    return FigureArtifact(
        "fig01_pipeline",
        figure,
        metrics,
        checks,
        paper_figure="Fig. 1",
        caption=(
            "The six-module twin; red: each module's residual e = twin − physics (Eq. 1). "
            "Same structure as the paper's diagram, which holds no data: nothing differs."
        ),
        provenance="drawn from dtwin.twin.wiring.MODULES (the table the simulator runs on) and "
        "the ARX orders of the arx config",
    )
