"""The finished result of one crosscheck against the R code, and its JSON file.

A crosscheck that fits a model runs in the stage rule whose concept it checks and writes a
:class:`CrosscheckResult` as JSON (e.g. ``results/regimes/crosscheck.json``); the figure that
reports it reads the file back, so figure code never refits. This module imports only
:mod:`dtwin.artifacts`, so a figure script can read the file cheaply.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any, NamedTuple

from dtwin.artifacts import Check, write_json

__all__ = ["CrosscheckResult", "write_crosscheck", "read_crosscheck"]


class CrosscheckResult(NamedTuple):
    """Checks of one crosscheck (kind ``crosscheck``) and the numbers behind them.

    Attributes
    ----------
    checks : list of Check
        In the order the figure reports them.
    metrics : dict
        Plain data (deviations, R's and our values), reported in the figure's metrics.
    """

    checks: list[Check]
    metrics: dict[str, Any]

    def to_payload(self) -> dict[str, Any]:
        """Return the result as plain data: ``{"checks": [Check fields…], "metrics": …}``."""
        return {"checks": [asdict(check) for check in self.checks], "metrics": self.metrics}

    @classmethod
    def from_payload(cls, payload: Mapping[str, Any]) -> CrosscheckResult:
        """Return the result stored by :meth:`to_payload` (after a JSON round trip)."""
        return cls([Check(**fields) for fields in payload["checks"]], dict(payload["metrics"]))


def write_crosscheck(result: CrosscheckResult, path: str | os.PathLike) -> None:
    """Write ``result`` as JSON, atomically (floats round-trip exactly)."""
    write_json(result.to_payload(), path)


def read_crosscheck(path: str | os.PathLike) -> CrosscheckResult:
    """Return the :class:`CrosscheckResult` written by :func:`write_crosscheck` at ``path``."""
    with open(path, encoding="utf-8") as handle:
        return CrosscheckResult.from_payload(json.load(handle))
