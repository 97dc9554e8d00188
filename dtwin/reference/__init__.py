"""Everything about the authors' R code: its column names, loaders of its outputs, crosschecks.

- :mod:`dtwin.reference.columns`: R's column names and labels → ours (the one place they live);
- :mod:`dtwin.reference.loaders`: read ``config/reference/*.csv`` in our names;
- crosschecks, one module per concept checked, each running our code on R's own signals or
  tables and comparing with R: :mod:`~dtwin.reference.arx_crosscheck` (ARX fit and rollout),
  :mod:`~dtwin.reference.em_crosscheck` (EM log-likelihood vs depmixS4),
  :mod:`~dtwin.reference.hungarian_crosscheck` (regime matching and scores),
  :mod:`~dtwin.reference.correction_crosscheck` (targeted intervention),
  :mod:`~dtwin.reference.mcda_crosscheck` (TOPSIS legacy mode vs RMCDA 0.3.1) and
  :mod:`~dtwin.reference.bic_crosscheck` (the BIC formula);
- :mod:`dtwin.reference.crosscheck_result`: a crosscheck's result and its JSON file.

Crosschecks that fit a model run in the stage rule of the concept they check and write
``results/**/…crosscheck.json``; the figures read the finished result (see
:mod:`dtwin.figures`). One module per crosscheck keeps each stage rule's library inputs (and
so its reruns) to what it checks. The R code's notes are ``config/reference/r_notes.md``.
Names are re-exported lazily so that a light rule importing a loader does not import the
crosschecks' dependencies (hmmlearn, scipy.signal).
"""

from __future__ import annotations

import importlib
from typing import Any

_MODULES = {
    "dtwin.reference.columns": (
        "R_PHYSICS_COLUMNS",
        "R_SURROGATE_COLUMNS",
        "R_FAULTED_SURROGATE_COLUMNS",
        "R_N_STATES",
        "R_GAMMA_COLUMNS",
        "R_VITERBI_COLUMN",
        "R_THETA_MODULES",
        "R_SWEEP_COLUMNS",
        "R_CORRECTION_METRICS",
        "R_CONFUSION_PREFIX",
        "R_CLASSIFICATION_METRICS",
        "R_RESTART_AGREEMENT_COLUMN",
        "R_BIC_NOMINAL_COLUMNS",
        "R_BIC_FEATURE_COLUMNS",
        "R_MCDA_VERSION",
        "R_MCDA_TIMELINE_COLUMNS",
        "R_MCDA_COUNT_COLUMNS",
    ),
    "dtwin.reference.loaders": (
        "load_r_physics",
        "load_r_faulted_twin",
        "load_r_theta",
        "load_r_fault_scenario",
        "load_r_sweep",
        "load_r_correction_metrics",
        "load_r_confusion",
        "load_r_classification",
        "load_r_bic",
        "load_r_mcda_timeline",
        "load_r_mcda_counts",
    ),
    "dtwin.reference.crosscheck_result": (
        "CrosscheckResult",
        "write_crosscheck",
        "read_crosscheck",
    ),
    "dtwin.reference.arx_crosscheck": ("crosscheck_arx",),
    "dtwin.reference.em_crosscheck": ("crosscheck_r_loglik",),
    "dtwin.reference.hungarian_crosscheck": ("crosscheck_hungarian",),
    "dtwin.reference.correction_crosscheck": ("crosscheck_correction",),
    "dtwin.reference.mcda_crosscheck": ("crosscheck_mcda_legacy",),
    "dtwin.reference.bic_crosscheck": ("crosscheck_bic_formula",),
}

_EXPORTS = {name: module for module, names in _MODULES.items() for name in names}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'dtwin.reference' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
