"""The benchmark's case effects: how each is drawn and where its real form acts in the asset.

Specification: docs/gap.md §Generator, §Benchmark.

:class:`CaseEffect` and its helpers are defined in :mod:`dtwin.gap.effects._case`, beside the
catalogue effects whose cases sit in their own modules; the out-of-list cases are
:mod:`dtwin.gapbench.generator`'s, the arms' :mod:`dtwin.gapbench.arms`'.
"""

from __future__ import annotations

from dtwin.gap.effects._case import CaseEffect, Draw, Truth, log_between, spec_value

__all__ = ["CaseEffect", "Draw", "Truth", "log_between", "spec_value"]
