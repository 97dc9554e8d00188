"""Fault injection, regime features and state-to-regime scoring (paper §2.2, §4.4; REFERENCE.md §5).

The fault scenario injects four scheduled regimes into the *surrogate* streams after the ARX
rollout (the physics and the surrogate dynamics are untouched), exactly as the authors' code
does:

- ``Nominal``: nothing;
- ``SensorNoisy``: ``y_A += N(0, 0.06²)``, ``y_B += N(0, 0.05²)``, drawn per sample, A then B;
- ``DynamicsOff``: ``x *= 0.8`` (a 20 % output scale); the sensor surrogates are *not*
  recomputed from the faulted position;
- ``Drift``: ``y_A += 0.0007·k``, with ``k`` the global sample index (a step of 0.5075 at
  14.5 s, then a ramp), or counted from the regime start (``drift_origin="regime_start"``).

Fusion and the KPI (with the backward-difference velocity) are then recomputed from the
faulted streams. :func:`regime_features` builds the ten HMM features, :func:`hungarian_map`
maps HMM states to regimes by maximum overlap (Eqs. (11)–(18)) and
:func:`classification_scores` scores the mapped path. Arrays are time-first, shape ``(T,)``.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_finite_array,
    require_in_range,
    require_nonnegative,
    require_number,
)
from dtwin.physics import backward_velocity, fuse, kpi
from dtwin.wiring import RESIDUALS

__all__ = [
    "REGIMES",
    "FEATURES",
    "DRIFT_ORIGINS",
    "UNMATCHED",
    "RegimeWindow",
    "FAULT_SCHEDULE",
    "fault_schedule",
    "FaultMagnitudes",
    "regime_labels",
    "inject_faults",
    "regime_features",
    "StateMapping",
    "hungarian_map",
    "mapped_posteriors",
    "ClassificationScores",
    "classification_scores",
]

#: Regime names in schedule order; each name is also the kind of fault it injects.
REGIMES: tuple[str, ...] = ("Nominal", "SensorNoisy", "DynamicsOff", "Drift")

#: The ten HMM features of the fault scenario (REFERENCE.md §5), before z-scoring.
FEATURES: tuple[str, ...] = (*RESIDUALS, "e_abs_sum", "e_rms", "e1_diff", "e3_diff")

#: Where the drift ramp starts counting samples.
DRIFT_ORIGINS: tuple[str, ...] = ("global", "regime_start")

#: Label of samples whose HMM state was matched to no regime (more states than regimes).
UNMATCHED = "<unmatched>"


@dataclass(frozen=True)
class RegimeWindow:
    """One scheduled regime, active for ``start <= t < end`` (seconds)."""

    regime: str
    start: float
    end: float


#: The paper's schedule: Nominal [0, 5), SensorNoisy [5, 10), DynamicsOff [10, 14.5),
#: Drift [14.5, 20) s.
FAULT_SCHEDULE: tuple[RegimeWindow, ...] = (
    RegimeWindow("Nominal", 0.0, 5.0),
    RegimeWindow("SensorNoisy", 5.0, 10.0),
    RegimeWindow("DynamicsOff", 10.0, 14.5),
    RegimeWindow("Drift", 14.5, 20.0),
)


def fault_schedule(entries: Sequence[Mapping[str, Any] | RegimeWindow]) -> tuple[RegimeWindow, ...]:
    """Return a validated schedule from ``{regime, start, end}`` mappings (or windows).

    Raises
    ------
    DtwinValueError
        If a regime is unknown, a window is empty, or two windows overlap.

    Examples
    --------
    >>> fault_schedule([{"regime": "Nominal", "start": 0, "end": 5}])[0].end
    5.0
    """
    windows = []
    for i, entry in enumerate(entries):
        if isinstance(entry, RegimeWindow):
            entry = {"regime": entry.regime, "start": entry.start, "end": entry.end}
        if not isinstance(entry, Mapping):
            raise DtwinTypeError(
                f"faults.schedule[{i}] must be a mapping with regime, start, end "
                f"(got {type(entry).__name__})"
            )
        missing = [key for key in ("regime", "start", "end") if key not in entry]
        if missing:
            raise DtwinValueError(f"faults.schedule[{i}] is missing {', '.join(missing)}")
        regime = entry["regime"]
        if regime not in REGIMES:
            raise DtwinValueError(
                f"faults.schedule[{i}].regime must be one of {', '.join(REGIMES)} (got {regime!r})"
            )
        start = require_number(f"faults.schedule[{i}].start", entry["start"])
        end = require_number(f"faults.schedule[{i}].end", entry["end"])
        if end <= start:
            raise DtwinValueError(
                f"faults.schedule[{i}] must have end > start (got start {start}, end {end})"
            )
        windows.append(RegimeWindow(regime, start, end))
    if not windows:
        raise DtwinValueError("faults.schedule must list at least one window (got none)")
    ordered = sorted(windows, key=lambda w: w.start)
    for before, after in itertools.pairwise(ordered):
        if after.start < before.end:
            raise DtwinValueError(
                f"faults.schedule windows must not overlap (got {before.regime} "
                f"[{before.start}, {before.end}) and {after.regime} [{after.start}, {after.end}))"
            )
    return tuple(windows)


@dataclass(frozen=True)
class FaultMagnitudes:
    """Fault sizes (defaults: the authors' code, REFERENCE.md §5).

    Attributes
    ----------
    sensor_A_std, sensor_B_std : float
        SensorNoisy: standard deviation of the noise added to ``y_A`` / ``y_B`` (m).
    dynamics_scale : float
        DynamicsOff: factor on the surrogate position ``x`` (dimensionless).
    drift_per_sample : float
        Drift: slope of the bias added to ``y_A`` (m per sample; 0.0007 m = 0.035 m/s).
    drift_origin : {"global", "regime_start"}
        ``"global"``: ``k`` is the global sample index (the code: a step then a ramp);
        ``"regime_start"``: ``k`` counts from the first sample of the drift window (a ramp).
    """

    sensor_A_std: float = 0.06
    sensor_B_std: float = 0.05
    dynamics_scale: float = 0.8
    drift_per_sample: float = 0.0007
    drift_origin: str = "global"

    def __post_init__(self) -> None:
        require_nonnegative("faults.sensor_A_std", self.sensor_A_std)
        require_nonnegative("faults.sensor_B_std", self.sensor_B_std)
        require_number("faults.dynamics_scale", self.dynamics_scale)
        require_number("faults.drift_per_sample", self.drift_per_sample)
        if self.drift_origin not in DRIFT_ORIGINS:
            raise DtwinValueError(
                f"faults.drift_origin must be one of {', '.join(DRIFT_ORIGINS)} "
                f"(got {self.drift_origin!r})"
            )


def regime_labels(t: Any, schedule: Sequence[RegimeWindow] = FAULT_SCHEDULE) -> np.ndarray:
    """Return the scheduled regime of every sample, shape ``(T,)`` of str.

    Parameters
    ----------
    t : array, shape (T,)
        Sample times, s.
    schedule : sequence of RegimeWindow
        Non-overlapping windows ``start <= t < end`` covering every sample.

    Raises
    ------
    DtwinValueError
        If a sample falls in no window.

    Examples
    --------
    >>> regime_labels(np.array([0.0, 5.0, 14.48, 14.5])).tolist()
    ['Nominal', 'SensorNoisy', 'DynamicsOff', 'Drift']
    """
    t = require_finite_array("t", t)
    schedule = fault_schedule(schedule)
    labels = np.full(len(t), "", dtype=object)
    for window in schedule:
        labels[(t >= window.start) & (t < window.end)] = window.regime
    uncovered = np.flatnonzero(labels == "")
    if uncovered.size:
        raise DtwinValueError(
            f"faults.schedule must cover every sample (got {uncovered.size} samples outside "
            f"it, first at t = {t[uncovered[0]]:g} s)"
        )
    return labels.astype(str)


def _require_columns(name: str, table: Any, columns: Sequence[str]) -> None:
    missing = [c for c in columns if c not in table]
    if missing:
        raise DtwinValueError(f"{name} is missing column(s) {', '.join(missing)}")


def inject_faults(
    surrogate: pd.DataFrame,
    rng: np.random.Generator,
    *,
    alpha: float,
    w1: float,
    w2: float,
    dt: float,
    schedule: Sequence[RegimeWindow] = FAULT_SCHEDULE,
    magnitudes: FaultMagnitudes | None = None,
) -> pd.DataFrame:
    """Return the surrogate streams with the scheduled faults injected (paper §4.4).

    Parameters
    ----------
    surrogate : DataFrame
        Surrogate chain output (:func:`dtwin.surrogate.run_surrogate_chain`): columns ``t``
        (s), ``u_act``, ``x`` (m), ``y_A``, ``y_B`` (m); other columns are carried over.
    rng : numpy.random.Generator
        Source of the SensorNoisy noise: one ``(n_noisy, 2)`` standard-normal block, i.e.
        per noisy sample one draw for A then one for B (the R code's order).
    alpha : float
        Fusion weight on sensor A, in [0, 1].
    w1, w2 : float
        KPI weights on position and velocity.
    dt : float
        Sample period, s (for the backward-difference velocity).
    schedule : sequence of RegimeWindow, default FAULT_SCHEDULE
    magnitudes : FaultMagnitudes, optional
        Defaults to :class:`FaultMagnitudes` ``()``.

    Returns
    -------
    DataFrame
        The input columns with ``x``, ``y_A``, ``y_B`` faulted, ``v`` the backward-difference
        velocity of the faulted ``x``, ``y_fused = α·y_A + (1−α)·y_B`` and
        ``z = w1·x + w2·v`` recomputed, plus ``regime`` (str).
    """
    _require_columns("surrogate", surrogate, ("t", "u_act", "x", "y_A", "y_B"))
    alpha = require_in_range("twin.fusion.alpha", alpha, 0.0, 1.0)
    w1 = require_number("twin.kpi.w1", w1)
    w2 = require_number("twin.kpi.w2", w2)
    dt = require_number("twin.dt", dt)
    if dt <= 0:
        raise DtwinValueError(f"twin.dt must be > 0 (got {dt})")
    if not isinstance(rng, np.random.Generator):
        raise DtwinTypeError(f"rng must be a numpy.random.Generator (got {type(rng).__name__})")
    magnitudes = FaultMagnitudes() if magnitudes is None else magnitudes
    t = require_finite_array("surrogate.t", surrogate["t"].to_numpy())
    regimes = regime_labels(t, schedule)
    x = require_finite_array("surrogate.x", surrogate["x"].to_numpy()).copy()
    y_a = require_finite_array("surrogate.y_A", surrogate["y_A"].to_numpy()).copy()
    y_b = require_finite_array("surrogate.y_B", surrogate["y_B"].to_numpy()).copy()

    noisy = np.flatnonzero(regimes == "SensorNoisy")
    draws = rng.standard_normal((noisy.size, 2))
    y_a[noisy] += magnitudes.sensor_A_std * draws[:, 0]
    y_b[noisy] += magnitudes.sensor_B_std * draws[:, 1]

    x[regimes == "DynamicsOff"] *= magnitudes.dynamics_scale

    index = np.arange(len(t))
    for window in fault_schedule(schedule):
        if window.regime != "Drift":
            continue
        samples = np.flatnonzero((t >= window.start) & (t < window.end))
        if samples.size == 0:
            continue
        origin = 0 if magnitudes.drift_origin == "global" else samples[0]
        y_a[samples] += magnitudes.drift_per_sample * (index[samples] - origin)

    faulted = surrogate.copy()
    velocity = backward_velocity(x, dt)
    faulted["x"] = x
    faulted["v"] = velocity
    faulted["y_A"] = y_a
    faulted["y_B"] = y_b
    faulted["y_fused"] = fuse(y_a, y_b, alpha)
    faulted["z"] = kpi(x, velocity, w1, w2)
    faulted["regime"] = regimes
    return faulted


def regime_features(residuals: pd.DataFrame) -> pd.DataFrame:
    """Return the ten HMM features of the fault scenario (not yet z-scored).

    Parameters
    ----------
    residuals : DataFrame
        Columns :data:`dtwin.wiring.RESIDUALS` (``e0 … e4``), one row per sample.

    Returns
    -------
    DataFrame
        Columns :data:`FEATURES`: the six residuals, ``e_abs_sum = Σ|e_i|``,
        ``e_rms = sqrt(Σ e_i²/6)``, ``e1_diff`` and ``e3_diff`` (first differences with a
        leading 0, R's ``c(0, diff(e))``).

    Examples
    --------
    >>> e = pd.DataFrame({name: [0.0, 1.0] for name in RESIDUALS})
    >>> regime_features(e).loc[1, ["e_abs_sum", "e_rms", "e1_diff"]].tolist()
    [6.0, 1.0, 1.0]
    """
    _require_columns("residuals", residuals, RESIDUALS)
    values = require_finite_array("residuals", residuals[list(RESIDUALS)].to_numpy(), ndim=2)
    features = pd.DataFrame(values, columns=list(RESIDUALS))
    features["e_abs_sum"] = np.abs(values).sum(axis=1)
    features["e_rms"] = np.sqrt((values**2).sum(axis=1) / values.shape[1])
    for name in ("e1", "e3"):
        column = features[name].to_numpy()
        features[f"{name}_diff"] = np.concatenate([[0.0], np.diff(column)])
    return features[list(FEATURES)]


# --- state-to-regime matching ---------------------------------------------------------------


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
    """numpy scalars → Python scalars, so mapping keys print and compare plainly."""
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
