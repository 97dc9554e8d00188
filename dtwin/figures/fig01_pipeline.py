"""Paper Fig. 1: the six-module twin, drawn from the wiring table the code runs on."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.patches import FancyBboxPatch

from dtwin.artifacts import Check, FigureArtifact
from dtwin.arx import arx_orders_from_mapping
from dtwin.figures._style import MODULE_COLORS, apply_style
from dtwin.wiring import MODULES, Module

__all__ = ["fig01_pipeline", "PipelineLayout", "layout_pipeline", "plot_pipeline"]

SOURCE = "Command generator"
COLUMN_SPACING = 1.5
ROW_SPACING = 1.0
BOX_WIDTH, BOX_HEIGHT = 0.9, 0.55


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
            linewidth=1.0,
        )
    )
    ax.text(x, y, text, ha="center", va="center", fontsize=8.5)


def _arrow(ax: plt.Axes, start: tuple[float, float], end: tuple[float, float], label: str) -> None:
    ax.annotate(
        "",
        xy=end,
        xytext=start,
        arrowprops={"arrowstyle": "-|>", "color": "#333333", "lw": 1.1, "shrinkA": 0, "shrinkB": 0},
    )
    mid = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
    ax.text(mid[0], mid[1] + 0.06, label, ha="center", va="bottom", fontsize=8, style="italic")


def plot_pipeline(modules: Sequence[Module], surrogate_labels: Mapping[str, str]) -> Figure:
    """Draw paper Fig. 1 from the wiring table.

    Parameters
    ----------
    modules : sequence of Module
        The wiring table (:data:`dtwin.wiring.MODULES`).
    surrogate_labels : mapping of module name to str
        How the twin replaces each module (``"ARX(2,2)"``, ``"algebraic"``).
    """
    apply_style()
    layout = layout_pipeline(modules)
    by_name = {module.name: module for module in modules}
    figure, ax = plt.subplots(figsize=(12, 5))
    half_width = BOX_WIDTH / 2
    for name, center in layout.positions.items():
        if name == SOURCE:
            _box(ax, center, "Command\ngenerator\nu_cmd", MODULE_COLORS["source"])
            continue
        module = by_name[name]
        title = textwrap.fill(module.title, 18)
        text = f"{module.name}\n{title}\ntwin: {surrogate_labels.get(name, '?')}"
        _box(ax, center, text, MODULE_COLORS[module.surrogate])
        ax.text(
            center[0],
            center[1] - BOX_HEIGHT / 2 - 0.04,
            f"residual {module.residual}",
            ha="center",
            va="top",
            fontsize=7.5,
            color="#b3001b",
        )
    for src, dst, label in layout.edges:
        (x0, y0), (x1, y1) = layout.positions[src], layout.positions[dst]
        _arrow(ax, (x0 + half_width, y0), (x1 - half_width, y1), label)
    for name, signal in layout.sinks:
        x0, y0 = layout.positions[name]
        _arrow(ax, (x0 + half_width, y0), (x0 + half_width + 0.5, y0), signal)
    xs = [p[0] for p in layout.positions.values()]
    ys = [p[1] for p in layout.positions.values()]
    ax.set_xlim(min(xs) - BOX_WIDTH / 2 - 0.05, max(xs) + BOX_WIDTH / 2 + 0.6)
    ax.set_ylim(min(ys) - 0.65, max(ys) + 0.4)
    ax.set_axis_off()
    legend = [
        FancyBboxPatch((0, 0), 1, 1, facecolor=MODULE_COLORS["arx"], edgecolor="#333333"),
        FancyBboxPatch((0, 0), 1, 1, facecolor=MODULE_COLORS["algebraic"], edgecolor="#333333"),
    ]
    ax.legend(
        legend,
        [
            "ARX(na, nb) surrogate in the twin",
            "recomputed algebraically from upstream twin signals",
        ],
        loc="lower left",
        fontsize=8,
    )
    ax.set_title(
        "Six-module digital twin (paper Fig. 1), drawn from dtwin.wiring.MODULES;\n"
        "red: the residual of each module, e = twin output − physics output (Eq. 1)",
        fontsize=10,
    )
    return figure


def fig01_pipeline(arx: Mapping[str, Any]) -> FigureArtifact:
    """Paper Fig. 1 drawn from :data:`dtwin.wiring.MODULES`."""
    orders = arx_orders_from_mapping(arx)
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
    return FigureArtifact("fig01_pipeline", figure, metrics, checks)
