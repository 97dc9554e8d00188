"""Shared figure style and a deterministic, atomic figure writer."""

from __future__ import annotations

import os
from collections.abc import Sequence

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from dtwin.artifacts import atomic_write, write_artifact

__all__ = [
    "PHYSICS_COLOR",
    "SURROGATE_COLOR",
    "BAND_COLOR",
    "MODULE_COLORS",
    "apply_style",
    "save_figure",
]

PHYSICS_COLOR = "#0b2545"
SURROGATE_COLOR = "#5fa8a0"
BAND_COLOR = "#b3001b"
MODULE_COLORS = {"arx": "#d7ecea", "algebraic": "#f3e3c3", "source": "#e4e4e4"}

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
