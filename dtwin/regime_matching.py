"""Matching HMM states to regimes and scoring the match (paper Eqs. (11)–(18), §4.4).

:func:`hungarian_map` assigns HMM states to the scheduled regimes by maximum overlap
(``scipy.optimize.linear_sum_assignment`` on the negated contingency table, Eqs. (11)–(18));
:func:`mapped_posteriors` sums the state posteriors per regime and
:func:`classification_scores` scores the mapped path (confusion, accuracy, macro-F1, Cohen's
κ). The regimes themselves are injected by :mod:`dtwin.fault_injection`.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

from dtwin._validation import DtwinValueError, require_finite_array
from dtwin.fault_injection import REGIMES

__all__ = [
    "UNMATCHED",
    "StateMapping",
    "hungarian_map",
    "mapped_posteriors",
    "ClassificationScores",
    "classification_scores",
]

#: Label of samples whose HMM state was matched to no regime (more states than regimes).
UNMATCHED = "<unmatched>"


@dataclass(frozen=True)
class StateMapping:
    """Maximum-overlap assignment of HMM states to regimes.

    Attributes
    ----------
    mapping : dict
        State label → regime name, or :data:`UNMATCHED` for states left over when there are
        more states than regimes.
    contingency : DataFrame
        Counts ``B_ij`` (Eq. (11)): index = state labels, columns = regime labels.
    predicted : ndarray of str, shape (T,)
        The mapped regime of every sample.
    """

    mapping: dict[Hashable, str]
    contingency: pd.DataFrame
    predicted: np.ndarray

    @property
    def states(self) -> tuple[Hashable, ...]:
        """State labels in contingency-row order."""
        return tuple(self.contingency.index)


def hungarian_map(
    states: Any,
    regimes: Any,
    *,
    all_states: Sequence[Hashable] | None = None,
    all_regimes: Sequence[str] | None = None,
) -> StateMapping:
    """Map HMM states to regimes by maximum total overlap (Hungarian algorithm).

    Parameters
    ----------
    states : array, shape (T,)
        Decoded state of every sample (e.g. the Viterbi path).
    regimes : array of str, shape (T,)
        Ground-truth regime of every sample.
    all_states : sequence, optional
        Every state of the model, including states that never occur in ``states``;
        default: the sorted distinct values of ``states``.
    all_regimes : sequence of str, optional
        Regime columns; default: the sorted distinct values of ``regimes`` (R's ``table``).

    Returns
    -------
    StateMapping

    Notes
    -----
    Builds the benefit matrix ``B_ij = #{t : Ŝ_t = i, S_t = j}`` (Eq. (11)), pads it with zero
    rows or columns to a square matrix, and solves ``max tr(PᵀB)`` (Eqs. (12)–(18)) with
    :func:`scipy.optimize.linear_sum_assignment`. States assigned to a padding column are
    :data:`UNMATCHED`; regimes assigned to a padding row are never predicted. Among optimal
    assignments with equal total overlap, the one returned may differ from R's
    ``clue::solve_LSAP``.

    Examples
    --------
    >>> m = hungarian_map([1, 1, 0, 0, 2], ["a", "a", "b", "b", "b"])
    >>> m.mapping
    {0: 'b', 1: 'a', 2: '<unmatched>'}
    """
    states = np.asarray(states)
    regimes = np.asarray(regimes)
    if states.ndim != 1 or regimes.ndim != 1 or len(states) != len(regimes):
        raise DtwinValueError(
            "states and regimes must be 1-dimensional of equal length "
            f"(got shapes {states.shape} and {regimes.shape})"
        )
    if len(states) == 0:
        raise DtwinValueError("states must hold at least one sample (got 0)")
    rows = [_plain(s) for s in (np.unique(states) if all_states is None else all_states)]
    columns = [str(r) for r in (np.unique(regimes) if all_regimes is None else all_regimes)]
    row_of = {label: i for i, label in enumerate(rows)}
    column_of = {label: j for j, label in enumerate(columns)}
    if len(row_of) != len(rows) or len(column_of) != len(columns):
        raise DtwinValueError("all_states and all_regimes must not repeat labels")
    state_values = [_plain(s) for s in states.tolist()]
    regime_values = [str(r) for r in regimes.tolist()]
    for name, values, known in (
        ("states", state_values, row_of),
        ("regimes", regime_values, column_of),
    ):
        unknown = sorted({v for v in values if v not in known}, key=str)
        if unknown:
            raise DtwinValueError(f"{name} holds labels missing from all_{name} (got {unknown})")
    counts = np.zeros((len(rows), len(columns)), dtype=int)
    np.add.at(counts, ([row_of[v] for v in state_values], [column_of[v] for v in regime_values]), 1)
    contingency = pd.DataFrame(
        counts, index=pd.Index(rows, name="state"), columns=pd.Index(columns, name="regime")
    )
    benefit = contingency.to_numpy(dtype=float)
    size = max(benefit.shape)
    padded = np.zeros((size, size))
    padded[: benefit.shape[0], : benefit.shape[1]] = benefit
    cost = padded.max() - padded  # Eq. (17)
    row_index, column_index = linear_sum_assignment(cost)
    mapping: dict[Hashable, str] = {}
    for i, j in zip(row_index, column_index, strict=True):
        if i < len(rows):
            mapping[rows[i]] = str(columns[j]) if j < len(columns) else UNMATCHED
    mapping = {label: mapping[label] for label in rows}
    predicted = np.array([mapping[v] for v in state_values], dtype=str)
    return StateMapping(mapping=mapping, contingency=contingency, predicted=predicted)


def _plain(label: Any) -> Hashable:
    """Numpy scalars → Python scalars, so mapping keys print and compare plainly."""
    return label.item() if isinstance(label, np.generic) else label


def mapped_posteriors(posteriors: Any, state_mapping: StateMapping) -> pd.DataFrame:
    """Return regime posteriors: state posteriors summed per mapped regime, renormalised.

    Parameters
    ----------
    posteriors : array, shape (T, K)
        State posteriors; column ``j`` belongs to ``state_mapping.states[j]``.
    state_mapping : StateMapping
        From :func:`hungarian_map` (with ``all_states`` listing all K states).

    Returns
    -------
    DataFrame
        One column per regime of the contingency table; unmatched states are dropped and each
        row is renormalised to sum to 1 (rows with no matched mass stay 0).
    """
    gamma = require_finite_array("posteriors", posteriors, ndim=2)
    states = state_mapping.states
    if gamma.shape[1] != len(states):
        raise DtwinValueError(
            f"posteriors must have one column per state ({len(states)}) (got {gamma.shape[1]})"
        )
    regimes = list(state_mapping.contingency.columns)
    out = np.zeros((len(gamma), len(regimes)))
    for j, state in enumerate(states):
        regime = state_mapping.mapping[state]
        if regime != UNMATCHED:
            out[:, regimes.index(regime)] += gamma[:, j]
    total = out.sum(axis=1, keepdims=True)
    np.divide(out, total, out=out, where=total > 0)
    return pd.DataFrame(out, columns=regimes)


# --- scores ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ClassificationScores:
    """Agreement of mapped states with the ground-truth regimes.

    Attributes
    ----------
    confusion : DataFrame
        Counts, index = predicted label, columns = actual label (in ``labels`` order); a
        final ``<unmatched>`` row appears when some samples were mapped to no regime.
    accuracy : float
        Fraction of samples whose predicted label equals the actual one.
    macro_f1 : float
        Mean over ``labels`` of the per-class F1.
    kappa : float
        Cohen's κ = (p_o − p_e)/(1 − p_e).
    per_class : DataFrame
        Columns ``class``, ``precision``, ``recall``, ``f1``, ``support`` (0 where undefined).
    """

    confusion: pd.DataFrame
    accuracy: float
    macro_f1: float
    kappa: float
    per_class: pd.DataFrame


def classification_scores(
    predicted: Any, actual: Any, labels: Sequence[str] = REGIMES
) -> ClassificationScores:
    """Return the confusion matrix, accuracy, macro-F1 and Cohen's κ of a mapped path.

    Parameters
    ----------
    predicted, actual : array of str, shape (T,)
        Mapped regime and true regime of every sample. ``actual`` must use ``labels``;
        ``predicted`` may also hold :data:`UNMATCHED`.
    labels : sequence of str, default REGIMES
        Class order of the table and of the macro average.

    Returns
    -------
    ClassificationScores

    Examples
    --------
    >>> s = classification_scores(["a", "a", "b", "b"], ["a", "b", "b", "b"], labels=["a", "b"])
    >>> s.accuracy, round(s.kappa, 3)
    (0.75, 0.5)
    """
    predicted = np.asarray(predicted, dtype=str)
    actual = np.asarray(actual, dtype=str)
    labels = [str(label) for label in labels]
    if predicted.shape != actual.shape or predicted.ndim != 1 or len(actual) == 0:
        raise DtwinValueError(
            "predicted and actual must be non-empty, 1-dimensional and of equal length "
            f"(got shapes {predicted.shape} and {actual.shape})"
        )
    bad_actual = sorted(set(actual.tolist()) - set(labels))
    if bad_actual:
        raise DtwinValueError(f"actual holds labels not in labels (got {bad_actual})")
    bad_predicted = sorted(set(predicted.tolist()) - set(labels) - {UNMATCHED})
    if bad_predicted:
        raise DtwinValueError(f"predicted holds labels not in labels (got {bad_predicted})")
    rows = labels + ([UNMATCHED] if (predicted == UNMATCHED).any() else [])
    counts = np.zeros((len(rows), len(labels)), dtype=int)
    row_of = {label: i for i, label in enumerate(rows)}
    column_of = {label: j for j, label in enumerate(labels)}
    np.add.at(counts, ([row_of[p] for p in predicted], [column_of[a] for a in actual]), 1)
    n = counts.sum()
    true_positive = np.diag(counts[: len(labels)]).astype(float)
    predicted_total = counts[: len(labels)].sum(axis=1).astype(float)
    actual_total = counts.sum(axis=0).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        precision = np.where(predicted_total > 0, true_positive / predicted_total, 0.0)
        recall = np.where(actual_total > 0, true_positive / actual_total, 0.0)
        f1 = np.where(precision + recall > 0, 2 * precision * recall / (precision + recall), 0.0)
    accuracy = float(true_positive.sum() / n)
    expected = float((predicted_total * actual_total).sum() / n**2)
    kappa = (accuracy - expected) / (1.0 - expected) if expected < 1.0 else float("nan")
    confusion = pd.DataFrame(
        counts,
        index=pd.Index(rows, name="predicted"),
        columns=pd.Index(labels, name="actual"),
    )
    per_class = pd.DataFrame(
        {
            "class": labels,
            "precision": precision,
            "recall": recall,
            "f1": f1,
            "support": actual_total.astype(int),
        }
    )
    return ClassificationScores(
        confusion=confusion,
        accuracy=accuracy,
        macro_f1=float(f1.mean()),
        kappa=float(kappa),
        per_class=per_class,
    )
