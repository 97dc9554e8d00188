"""The gap diagnoser's benchmark: recordings with a withheld effect, and their scores.

A test-data factory for :mod:`dtwin.gap`, which never imports it (tests/test_architecture.py).
Specification: docs/gap.md §Generator, §Benchmark.

Modules: :mod:`~dtwin.gapbench.generator` (a case: recording, twin file and key from the paper's
asset with one effect), :mod:`~dtwin.gapbench.arms` (the arms' harder cases),
:mod:`~dtwin.gapbench.rigs` (the rig families), :mod:`~dtwin.gapbench.families` (families of
other physics whose twin is a ``modules:`` table: tanks, a DC motor, a thermal network, a
battery; their assets in :mod:`~dtwin.gapbench.family_assets`, their effects' real forms in
:mod:`~dtwin.gapbench.family_effects`), :mod:`~dtwin.gapbench.batch` (a chunk of cases
written to and diagnosed from folders), :mod:`~dtwin.gapbench.scores` (diagnoses scored
against their keys, the benchmark's metrics and checks) and :mod:`~dtwin.gapbench.power` (the
share named against the effect's signal-to-noise ratio, docs/gap.md §Detection power).

The package re-exports :func:`generate_case` and :class:`GeneratedCase` lazily (PEP 562), so
importing one module loads only what it needs.
"""

from __future__ import annotations

from dtwin._lazy import lazy_exports

_EXPORTS = {
    "GeneratedCase": "dtwin.gapbench.generator",
    "generate_case": "dtwin.gapbench.generator",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
