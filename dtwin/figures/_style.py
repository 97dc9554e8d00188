"""Shared figure style and a deterministic, atomic figure writer."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from dtwin.artifacts import atomic_write, write_artifact

__all__ = [
    "PHYSICS_COLOR",
    "SURROGATE_COLOR",
    "BAND_COLOR",
    "MODULE_COLORS",
    "REGIME_COLORS",
    "STATE_COLORS",
    "BEFORE_COLOR",
    "AFTER_COLOR",
    "R_COLOR",
    "RESIDUAL_UNITS",
    "apply_style",
    "save_figure",
    "publish_artifact",
    "regime_spans",
    "shade_regimes",
]

PHYSICS_COLOR = "#0b2545"
SURROGATE_COLOR = "#5fa8a0"
BAND_COLOR = "#b3001b"
MODULE_COLORS = {"arx": "#d7ecea", "algebraic": "#f3e3c3", "source": "#e4e4e4"}
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
R_COLOR = "#8c8c8c"
#: Unit of each residual channel (surrogate − physics of the module output).
RESIDUAL_UNITS = {
    "e0": "actuation units",
    "e1": "m",
    "e2a": "m",
    "e2b": "m",
    "e3": "m",
    "e4": "KPI units",
}

_METADATA = {
    ".png": {"Software": None},
    ".pdf": {"Creator": None, "Producer": None, "CreationDate": None},
}


def apply_style() -> None:
    """Set the project's matplotlib defaults (readable sizes, no top/right spines)."""
    plt.rcParams.update(
        {
            "figure.dpi": 100,
            "savefig.dpi": 150,
            "font.size": 9,
            "axes.titlesize": 10,
            "axes.labelsize": 9,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "axes.grid": True,
            "grid.alpha": 0.25,
            "legend.frameon": False,
            "pdf.fonttype": 42,
            "svg.hashsalt": "dtwin",
        }
    )


def save_figure(figure: Figure, paths: Sequence[str | os.PathLike]) -> None:
    """Save ``figure`` to every path (format from the suffix), atomically and without timestamps.

    PNG files carry no "Software" tag and PDF files no creation date or producer, so the same
    data gives byte-identical files on a rerun.
    """
    for path in paths:
        suffix = os.path.splitext(str(path))[1].lower()
        metadata = _METADATA.get(suffix, {})

        def write(tmp: str, metadata: dict = metadata) -> None:
            figure.savefig(tmp, metadata=metadata, bbox_inches="tight")

        atomic_write(path, write)
    plt.close(figure)


def publish_artifact(artifact, paths: Sequence[str | os.PathLike], json_path: str | os.PathLike):
    """Save a :class:`dtwin.stages.FigureArtifact`'s figure to ``paths`` and write its JSON.

    Raises :class:`dtwin.artifacts.ArtifactValidityError` (after writing the JSON) when a
    validity check failed, so the rule fails and Snakemake removes its outputs.
    """
    save_figure(artifact.figure, paths)
    return write_artifact(json_path, artifact.name, paths, artifact.metrics, artifact.checks)


def regime_spans(t: Any, regimes: Any) -> list[tuple[str, float, float]]:
    """Return the runs of equal regime labels as ``(regime, start, end)`` in seconds.

    ``end`` is the start of the next run, or the last sample plus one sample period.

    Examples
    --------
    >>> regime_spans([0.0, 0.5, 1.0, 1.5], ["a", "a", "b", "b"])
    [('a', 0.0, 1.0), ('b', 1.0, 2.0)]
    """
    t = np.asarray(t, dtype=float)
    labels = np.asarray(regimes, dtype=str)
    step = float(t[1] - t[0]) if len(t) > 1 else 1.0
    starts = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    ends = np.r_[starts[1:], len(t)]
    return [
        (str(labels[i]), float(t[i]), float(t[j]) if j < len(t) else float(t[-1] + step))
        for i, j in zip(starts, ends, strict=True)
    ]


def shade_regimes(
    ax: Axes, spans: Sequence[tuple[str, float, float]], alpha: float = 0.12, lines: bool = True
) -> None:
    """Shade each scheduled regime in its colour and mark the boundaries with dashed lines."""
    for regime, start, end in spans:
        ax.axvspan(start, end, color=REGIME_COLORS.get(regime, "#dddddd"), alpha=alpha, lw=0)
        if lines and start > spans[0][1]:
            ax.axvline(start, color="#555555", lw=0.8, ls="--")
