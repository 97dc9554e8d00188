"""Sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks.

Checked on generated recordings whose effect is withheld.

Specification: docs/gap.md.

Modules: :mod:`~dtwin.gap.recording` (load and validate a recording), :mod:`~dtwin.gap.effects`
(the candidate catalogue), :mod:`~dtwin.gap.models` (module twins with effects),
:mod:`~dtwin.gap.noise` (noise floors), :mod:`~dtwin.gap.fit` (fitting and calibration),
:mod:`~dtwin.gap.localise` (gaps and the chain), :mod:`~dtwin.gap.diagnose` (the diagnoser),
:mod:`~dtwin.gap.report` (JSON, markdown, figure), :mod:`~dtwin.gap.generator` (withheld-effect
recordings) and :mod:`~dtwin.gap.benchmark` (scoring diagnoses against the truth).

Arrays are time-first: every signal has shape ``(n_samples,)``.
"""

from dtwin.gap.diagnose import (
    Diagnosis,
    GapSettings,
    diagnose,
    twin_discretisation,
    twin_from_mapping,
)
from dtwin.gap.effects import EFFECT_NAMES, EFFECTS, Effect
from dtwin.gap.generator import GeneratedCase, generate_case
from dtwin.gap.recording import Recording, read_recording, recording_from_frame
from dtwin.gap.report import diagnosis_to_dict, write_report

__all__ = [
    "Diagnosis",
    "GapSettings",
    "diagnose",
    "twin_from_mapping",
    "twin_discretisation",
    "EFFECT_NAMES",
    "EFFECTS",
    "Effect",
    "GeneratedCase",
    "generate_case",
    "Recording",
    "read_recording",
    "recording_from_frame",
    "diagnosis_to_dict",
    "write_report",
]
