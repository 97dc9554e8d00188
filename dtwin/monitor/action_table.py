"""Actions per regime: the user's alternatives × criteria ranked by the paper's TOPSIS.

Specification: docs/monitor.md §Actions. An actions file lists the alternatives, the criteria
with their weights (and which of them are costs: less is better, negated as the paper's
``Cost``) and, per regime, one row of criterion values per alternative. A regime is looked up
by its label (``S1 … SK``, ``unknown``), then as ``nominal`` (for a nominal regime), then as
``default``. At every sample the decision matrix is the posterior-weighted sum of the regimes'
matrices (as the paper weights its criteria by the regime posteriors, §5) and the action is the
alternative with the largest TOPSIS closeness (:func:`dtwin.mcda.topsis`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.mcda import topsis

__all__ = ["ActionTable", "action_table_from_mapping"]


def _fail(key: str, rule: str) -> DtwinValueError:
    return DtwinValueError(f"actions file: {key}: {rule}")


def _names(raw: Any, key: str) -> tuple[str, ...]:
    if not isinstance(raw, list) or not raw or not all(isinstance(v, str) for v in raw):
        raise _fail(key, "must be a list of names")
    if len(set(raw)) != len(raw):
        raise _fail(key, "lists a name twice")
    return tuple(raw)


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(key, f"must be a finite number (got {value!r})")
    return float(value)


@dataclass(frozen=True)
class ActionTable:
    """The parsed actions file.

    Attributes
    ----------
    alternatives, criteria : tuple of str
    weights : ndarray, shape (n_criteria,)
        Criterion weights, summing to 1.
    costs : tuple of str
        Criteria where less is better.
    matrices : dict of str to ndarray, shape (n_alternatives, n_criteria)
        Per regime key (a label, ``nominal`` or ``default``), the values as given.
    """

    alternatives: tuple[str, ...]
    criteria: tuple[str, ...]
    weights: np.ndarray
    costs: tuple[str, ...]
    matrices: dict[str, np.ndarray]

    def matrix_of(self, label: str, nominal: bool) -> np.ndarray:
        """Return the benefit-type matrix of a regime (costs negated)."""
        for key in (label, "nominal" if nominal else None, "default"):
            if key in self.matrices:
                sign = np.array([-1.0 if c in self.costs else 1.0 for c in self.criteria])
                return self.matrices[key] * sign
        raise _fail("regimes", f"no entry for regime {label} (add it, nominal or default)")

    def stacked(self, labels: Sequence[str], nominal: Sequence[bool]) -> np.ndarray:
        """Return the states' matrices, shape (K + 1, n_alternatives, n_criteria)."""
        return np.stack(
            [self.matrix_of(lab, nom) for lab, nom in zip(labels, nominal, strict=True)]
        )

    def per_regime(self, labels: Sequence[str], nominal: Sequence[bool]) -> dict[str, str]:
        """Return the action of each regime alone (TOPSIS on its own matrix)."""
        closeness, _ = topsis(self.stacked(labels, nominal), self.weights)
        best = np.argmax(closeness, axis=1)
        return {label: self.alternatives[i] for label, i in zip(labels, best, strict=True)}

    def decide(self, posteriors: np.ndarray, stacked: np.ndarray) -> np.ndarray:
        """Return the action index at every row of ``posteriors`` (n, K + 1), shape (n,)."""
        matrices = np.einsum("tk,kac->tac", posteriors, stacked)
        closeness, _ = topsis(matrices, self.weights)
        return np.argmax(closeness, axis=1)

    def to_mapping(self) -> dict[str, Any]:
        """Return the table as plain data (``regimes.json``'s ``actions``), as a file gives it."""
        return {
            "alternatives": list(self.alternatives),
            "criteria": dict(zip(self.criteria, self.weights.tolist(), strict=True)),
            "costs": list(self.costs),
            "regimes": {
                key: dict(zip(self.alternatives, m.tolist(), strict=True))
                for key, m in self.matrices.items()
            },
        }


def _matrix(raw: Any, key: str, alternatives, n_criteria: int) -> np.ndarray:
    if not isinstance(raw, Mapping):
        raise _fail(key, "must map each alternative to its criterion values")
    missing = [a for a in alternatives if a not in raw]
    extra = [a for a in raw if a not in alternatives]
    if missing or extra:
        raise _fail(key, f"must list exactly the alternatives (missing {missing}, unknown {extra})")
    rows = []
    for name in alternatives:
        values = raw[name]
        if not isinstance(values, list) or len(values) != n_criteria:
            raise _fail(f"{key}.{name}", f"must list {n_criteria} numbers, one per criterion")
        rows.append([_number(v, f"{key}.{name}") for v in values])
    return np.array(rows)


def action_table_from_mapping(raw: Any) -> ActionTable:
    """Return the :class:`ActionTable` of an actions file's content (module docstring).

    Raises
    ------
    DtwinValueError
        One line naming the key: ``actions file: regimes.S2.Inspect: must list 3 numbers, one
        per criterion``.

    Examples
    --------
    >>> table = action_table_from_mapping({
    ...     "alternatives": ["NoAction", "Inspect", "Stop"],
    ...     "criteria": {"benefit": 2, "cost": 1}, "costs": ["cost"],
    ...     "regimes": {"nominal": {"NoAction": [0, 0], "Inspect": [0, 1], "Stop": [0, 10]},
    ...                 "default": {"NoAction": [0, 0], "Inspect": [5, 1], "Stop": [6, 10]},
    ...                 "unknown": {"NoAction": [0, 0], "Inspect": [1, 1], "Stop": [9, 2]}}})
    >>> table.per_regime(["S1", "S2", "unknown"], [True, False, False])
    {'S1': 'NoAction', 'S2': 'Inspect', 'unknown': 'Stop'}
    """
    if not isinstance(raw, Mapping):
        raise _fail("top level", "must be a mapping with alternatives, criteria and regimes")
    unknown = sorted(set(raw) - {"alternatives", "criteria", "costs", "regimes"})
    if unknown:
        raise _fail(", ".join(map(str, unknown)), "unknown key")
    for key in ("alternatives", "criteria", "regimes"):
        if key not in raw:
            raise _fail(key, "missing")
    alternatives = _names(raw["alternatives"], "alternatives")
    if not isinstance(raw["criteria"], Mapping) or not raw["criteria"]:
        raise _fail("criteria", "must map each criterion to its weight")
    criteria = tuple(str(c) for c in raw["criteria"])
    weights = np.array([_number(raw["criteria"][c], f"criteria.{c}") for c in criteria])
    if np.any(weights < 0) or weights.sum() <= 0:
        raise _fail("criteria", "weights must be >= 0 and not all 0")
    costs = _names(raw["costs"], "costs") if raw.get("costs") else ()
    if set(costs) - set(criteria):
        raise _fail("costs", f"names no criterion: {sorted(set(costs) - set(criteria))}")
    if not isinstance(raw["regimes"], Mapping) or not raw["regimes"]:
        raise _fail("regimes", "must map regimes (S1 …, unknown, nominal, default) to matrices")
    matrices = {
        str(key): _matrix(value, f"regimes.{key}", alternatives, len(criteria))
        for key, value in raw["regimes"].items()
    }
    return ActionTable(alternatives, criteria, weights / weights.sum(), costs, matrices)
