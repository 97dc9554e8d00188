"""Everything about the authors' R code: its column names, loaders of its outputs, crosschecks.

- :mod:`dtwin.reference.columns`: R's column names and labels → ours (the one place they live);
- :mod:`dtwin.reference.loaders`: read ``config/reference/*.csv`` in our names;
- :mod:`dtwin.reference.crosschecks`: run our code on R's own signals and compare with R.

The R code's constants and the numbers it produces are documented in
``docs/r_reference.md``. Names are re-exported lazily so that a light rule importing a loader
does not import the crosschecks' dependencies (scipy.signal through the ARX code).
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "R_PHYSICS_COLUMNS": "dtwin.reference.columns",
    "R_SURROGATE_COLUMNS": "dtwin.reference.columns",
    "R_THETA_MODULES": "dtwin.reference.columns",
    "R_SWEEP_COLUMNS": "dtwin.reference.columns",
    "load_r_physics": "dtwin.reference.loaders",
    "load_r_theta": "dtwin.reference.loaders",
    "load_r_fault_scenario": "dtwin.reference.loaders",
    "load_r_sweep": "dtwin.reference.loaders",
    "crosscheck_arx": "dtwin.reference.crosschecks",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'dtwin.reference' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
