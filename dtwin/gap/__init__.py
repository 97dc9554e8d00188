"""Sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks.

Specification: docs/gap.md. The recordings it is checked on (a withheld effect each) and their
scoring are :mod:`dtwin.gapbench`'s, which this package never imports.

Modules: :mod:`~dtwin.gap.recording` (load and validate a recording), :mod:`~dtwin.gap.effects`
(the candidate catalogue), :mod:`~dtwin.gap.models` (module twins with effects),
:mod:`~dtwin.gap.noise` (noise floors), :mod:`~dtwin.gap.fit` (fitting and calibration),
:mod:`~dtwin.gap.localise` (gaps and the chain), :mod:`~dtwin.gap.intervals` (parameter
intervals), :mod:`~dtwin.gap.confidence` (calibrated confidence), :mod:`~dtwin.gap.oe_reference`
(the output-error reference fit), :mod:`~dtwin.gap.twin_file` (the twin file),
:mod:`~dtwin.gap.results` (settings and the diagnosis), the diagnoser's three steps
:mod:`~dtwin.gap.where`, :mod:`~dtwin.gap.which` and :mod:`~dtwin.gap.how_far`,
:mod:`~dtwin.gap.diagnose` (the entry point) and :mod:`~dtwin.gap.report` (JSON, markdown,
figure).

Arrays are time-first: every signal has shape ``(n_samples,)``.
"""

from dtwin.gap.diagnose import diagnose
from dtwin.gap.effects import EFFECT_NAMES, EFFECTS, Effect
from dtwin.gap.recording import Recording, read_recording, recording_from_frame
from dtwin.gap.report import diagnosis_to_dict, write_report
from dtwin.gap.results import Diagnosis, GapSettings
from dtwin.gap.twin_file import twin_discretisation, twin_from_mapping

__all__ = [
    "Diagnosis",
    "GapSettings",
    "diagnose",
    "twin_from_mapping",
    "twin_discretisation",
    "EFFECT_NAMES",
    "EFFECTS",
    "Effect",
    "Recording",
    "read_recording",
    "recording_from_frame",
    "diagnosis_to_dict",
    "write_report",
]
