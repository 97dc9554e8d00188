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

from __future__ import annotations

from dtwin._lazy import keep_exports, lazy_exports

#: Public names → their modules, imported on first use (PEP 562): the table diagnoser and the
#: command line load only what they use, not the paper's diagnoser and scipy.signal.
_EXPORTS: dict[str, str] = {
    "Diagnosis": "dtwin.gap.results",
    "GapSettings": "dtwin.gap.results",
    "diagnose": "dtwin.gap.diagnose",
    "twin_from_mapping": "dtwin.gap.twin_file",
    "twin_discretisation": "dtwin.gap.twin_file",
    "EFFECT_NAMES": "dtwin.gap.effects",
    "EFFECTS": "dtwin.gap.effects",
    "Effect": "dtwin.gap.effects",
    "Recording": "dtwin.gap.recording",
    "read_recording": "dtwin.gap.recording",
    "recording_from_frame": "dtwin.gap.recording",
    "diagnosis_to_dict": "dtwin.gap.report",
    "write_report": "dtwin.gap.report",
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
keep_exports(__name__, ["diagnose"])  # the function, not the module dtwin.gap.diagnose
