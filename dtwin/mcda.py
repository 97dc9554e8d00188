"""Regime-aware action selection with TOPSIS (paper §5, Table 1; r_notes.md §8).

Per time step the twin scores five mitigation actions on five benefit criteria (KPI gain,
module gain, drift gain, stability = −penalty, cost negated), each gain weighted by the
Hungarian-mapped regime posteriors, ranks them with TOPSIS, then applies a NoAction gate, a
minimum dwell and a switching margin.

Three limitations of the authors' code are fixed here (each can be switched back with
``legacy_r=True`` to crosscheck against R):

* **degenerate steps**: a criterion column that is zero for every action (0/0 in the vector
  normalisation) made R's scores NaN → 0 and the tie went to the first action. Here a zero
  column is treated as carrying no information (normalised to 0, the limit of a constant
  column, which TOPSIS ignores) and the step is counted as degenerate;
* **NoAction is reachable after an action**: in R a gated step scores −Inf in the hysteresis,
  so the selection can never return to NoAction. Here the gate's verdict is binding once the
  dwell has elapsed: the selection goes to NoAction when the gate fires and leaves it when the
  gate no longer fires;
* **decision confidence**: every step reports the closeness gap between the best and the
  second-best action.

TOPSIS weights act on the criteria (columns); RMCDA 0.3 applied them to the alternatives.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import (
    DtwinValueError,
    require_finite_array,
    require_in_range,
    require_nonnegative,
    require_positive,
)
from dtwin.config_sections import require_keys

__all__ = [
    "ACTIONS",
    "CRITERIA",
    "NO_ACTION",
    "Action",
    "McdaSettings",
    "McdaResult",
    "mcda_features",
    "criteria_tensor",
    "topsis",
    "select_actions",
    "run_mcda",
]

NO_ACTION = "NoAction"
CRITERIA: tuple[str, ...] = ("KPI_gain", "Module_gain", "Drift_gain", "Stability", "Cost")


@dataclass(frozen=True)
class Action:
    """A mitigation action with its fixed cost and stability penalty (r_notes.md §8)."""

    name: str
    cost: float
    stability_penalty: float


ACTIONS: tuple[Action, ...] = (
    Action("DownweightSensorA", 0.10, 0.08),
    Action("DownweightSensorB", 0.10, 0.08),
    Action("IncreaseFiltering", 0.15, 0.05),
    Action("ReidentifyPlant", 0.40, 0.15),
    Action("BiasCorrect", 0.25, 0.12),
)


@dataclass(frozen=True)
class McdaSettings:
    """Parameters of the selection (defaults: the authors' ``MCDA_intervention.R``).

    Attributes
    ----------
    weights : mapping of criterion to weight
        Renormalised to sum 1.
    roll_sec : float
        Rolling-window length of the features, s (``max(5, round(roll_sec/dt))`` samples).
    gate_quantile, gate_p_nominal : float
        NoAction when ``kpi_n`` and ``agg_n`` are below their ``gate_quantile`` quantiles and
        ``p_Nominal > gate_p_nominal``.
    min_dwell_sec : float
        Minimum time between switches, s.
    switch_margin : float
        Closeness gain a new action needs over the current one to take over.
    legacy_r : bool
        Reproduce the authors' code exactly (degenerate steps → first action, NoAction can
        never return), for crosschecks only.
    """

    weights: Mapping[str, float]
    roll_sec: float = 1.0
    gate_quantile: float = 0.20
    gate_p_nominal: float = 0.75
    min_dwell_sec: float = 0.50
    switch_margin: float = 0.02
    legacy_r: bool = False

    @classmethod
    def from_mapping(
        cls, raw: Any, section: str = "mcda", *, legacy_r: bool = False
    ) -> McdaSettings:
        """Return the validated settings of config section ``section`` (errors name the key).

        ``legacy_r`` is not a config key: the R crosscheck asks for it.

        Examples
        --------
        >>> weights = dict.fromkeys(CRITERIA, 1.0)
        >>> McdaSettings.from_mapping({"weights": weights, "roll_sec": 2}).roll_sec
        2.0
        >>> McdaSettings.from_mapping({"weights": weights, "gate_quantile": 1.5})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: mcda.gate_quantile must be in [0, 1] (got 1.5)
        """
        if isinstance(raw, cls):
            return raw
        optional = ("roll_sec", "gate_quantile", "gate_p_nominal", "min_dwell_sec", "switch_margin")
        raw = require_keys(section, raw, ("weights",), optional)
        weights = require_keys(f"{section}.weights", raw["weights"], CRITERIA)
        values = {key: raw[key] for key in optional if key in raw}
        checks = {
            "roll_sec": require_positive,
            "gate_quantile": lambda name, v: require_in_range(name, v, 0.0, 1.0),
            "gate_p_nominal": lambda name, v: require_in_range(name, v, 0.0, 1.0),
            "min_dwell_sec": require_nonnegative,
            "switch_margin": require_nonnegative,
        }
        return cls(
            weights={
                name: require_nonnegative(f"{section}.weights.{name}", weights[name])
                for name in CRITERIA
            },
            **{key: checks[key](f"{section}.{key}", value) for key, value in values.items()},
            legacy_r=legacy_r,
        )


@dataclass(frozen=True)
class McdaResult:
    """Per-step decisions.

    Attributes
    ----------
    timeline : DataFrame
        One row per step: ``step``, ``gate`` (bool), ``degenerate`` (bool), ``best`` (raw
        arg-max action or NoAction when gated), ``best_score``, ``confidence`` (closeness gap
        best − second), ``action`` (after dwell and margin), ``score_<action>`` per action.
    n_degenerate : int
        Steps whose criteria had an all-zero column.
    thresholds : dict
        The gate thresholds ``kpi`` and ``agg`` (quantiles of the scaled features).
    """

    timeline: pd.DataFrame
    n_degenerate: int
    thresholds: dict[str, float]


def _rolling(values: np.ndarray, window: int, statistic: str) -> np.ndarray:
    """Right-aligned rolling mean or sample sd; the first ``window−1`` steps are 0 (R: NA→0)."""
    series = pd.Series(values).rolling(window)
    result = series.mean() if statistic == "mean" else series.std(ddof=1)
    return result.fillna(0.0).to_numpy()


def _robust_scale(values: np.ndarray) -> np.ndarray:
    """``x / mad(x)`` with R's ``mad(constant=1)``; falls back to the sd, then to 1."""
    mad = float(np.median(np.abs(values - np.median(values))))
    if not np.isfinite(mad) or mad <= 0:
        mad = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
    if not np.isfinite(mad) or mad <= 0:
        mad = 1.0
    return values / mad


def mcda_features(residuals: pd.DataFrame, dt: float, roll_sec: float = 1.0) -> pd.DataFrame:
    """Return the per-step MCDA features of r_notes.md §8.

    Parameters
    ----------
    residuals : DataFrame
        Columns ``e0, e1, e2a, e2b, e3, e4``, one row per step.
    dt : float
        Sample period, s.
    roll_sec : float
        Rolling window, s.

    Returns
    -------
    DataFrame
        ``kpi_n, plant_n, sensor_n, noise_n, drift_n, agg_n`` (MAD-scaled magnitudes) and
        ``A_dom`` (|e2a| ≥ |e2b|).
    """
    channels = ["e0", "e1", "e2a", "e2b", "e3", "e4"]
    missing = [c for c in channels if c not in residuals.columns]
    if missing:
        raise DtwinValueError(f"residuals are missing column(s): {', '.join(missing)}")
    e = {c: require_finite_array(c, residuals[c].to_numpy()) for c in channels}
    window = max(5, round(roll_sec / dt))
    sens_a, sens_b = np.abs(e["e2a"]), np.abs(e["e2b"])
    drift = sum(np.abs(_rolling(e[c], window, "mean")) for c in ("e2a", "e0", "e1"))
    raw = {
        "kpi_n": np.abs(e["e4"]),
        "plant_n": np.abs(e["e1"]),
        "sensor_n": sens_a + sens_b,
        "noise_n": _rolling(sens_a + sens_b, window, "sd"),
        "drift_n": drift,
        "agg_n": np.sqrt(sum(np.square(e[c]) for c in channels)),
    }
    table = pd.DataFrame({name: _robust_scale(values) for name, values in raw.items()})
    table["plant_var"] = _rolling(e["e1"], window, "sd")
    table["A_dom"] = sens_a >= sens_b
    return table


def criteria_tensor(features: pd.DataFrame, probs: pd.DataFrame) -> np.ndarray:
    """Return the decision matrices of every step, shape ``(T, n_actions, n_criteria)``.

    ``probs`` has columns ``p_SensorNoisy``, ``p_DynamicsOff``, ``p_Drift`` (and
    ``p_Nominal``); the expressions are those of r_notes.md §8 (paper Table 1).
    """
    p_s = probs["p_SensorNoisy"].to_numpy()
    p_d = probs["p_DynamicsOff"].to_numpy()
    p_r = probs["p_Drift"].to_numpy()
    kpi, plant = features["kpi_n"].to_numpy(), features["plant_n"].to_numpy()
    sens, noise = features["sensor_n"].to_numpy(), features["noise_n"].to_numpy()
    drift = features["drift_n"].to_numpy()
    a_dom = features["A_dom"].to_numpy(dtype=bool)
    module = {
        "DownweightSensorA": p_s * sens * np.where(a_dom, 1.2, 0.6),
        "DownweightSensorB": p_s * sens * np.where(~a_dom, 1.2, 0.6),
        "IncreaseFiltering": p_s * noise,
        "ReidentifyPlant": p_d * plant,
        "BiasCorrect": (p_r + 0.5 * p_d) * (drift + 0.3 * plant),
    }
    module_gain = {
        **module,
        "IncreaseFiltering": p_s * sens * noise,
    }
    drift_gain = {
        "DownweightSensorA": p_s * drift * np.where(a_dom, 1.1, 0.7),
        "DownweightSensorB": p_s * drift * np.where(~a_dom, 1.1, 0.7),
        "IncreaseFiltering": p_s * drift * 0.6,
        "ReidentifyPlant": p_d * drift * 0.4,
        "BiasCorrect": (p_r + 0.2 * p_s) * drift,
    }
    n_steps = len(kpi)
    tensor = np.empty((n_steps, len(ACTIONS), len(CRITERIA)))
    for index, action in enumerate(ACTIONS):
        tensor[:, index, 0] = kpi * module[action.name]
        tensor[:, index, 1] = module_gain[action.name]
        tensor[:, index, 2] = drift_gain[action.name]
        tensor[:, index, 3] = -action.stability_penalty
        tensor[:, index, 4] = -action.cost
    return tensor


def topsis(matrices: np.ndarray, weights: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Rank alternatives with TOPSIS, all criteria benefit-type.

    Parameters
    ----------
    matrices : array, shape (n_alternatives, n_criteria) or (T, n_alternatives, n_criteria)
        Decision matrices.
    weights : sequence of float, length n_criteria
        Criterion weights (applied to columns).

    Returns
    -------
    (closeness, degenerate)
        Closeness ``S⁻/(S⁺+S⁻)`` with the leading shape of ``matrices`` minus the criteria axis,
        and a boolean flag per matrix: True when a criterion column was all zero (it is then
        normalised to 0 and carries no information, instead of 0/0).

    Notes
    -----
    Vector normalisation ``r_ij = x_ij / √(Σ_i x_ij²)``; ``v_ij = w_j·r_ij``; ideal and
    anti-ideal are the column max and min. If every alternative is at the same distance
    (all columns constant) the closeness is 0.5 for all.

    Examples
    --------
    >>> closeness, _ = topsis(np.array([[1.0, 2.0], [2.0, 1.0], [3.0, 3.0]]), [0.5, 0.5])
    >>> int(np.argmax(closeness))
    2
    """
    matrices = np.asarray(matrices, dtype=float)
    single = matrices.ndim == 2
    if single:
        matrices = matrices[None]
    weights = np.asarray(weights, dtype=float)
    if weights.shape != (matrices.shape[-1],) or np.any(weights < 0) or weights.sum() <= 0:
        raise DtwinValueError(
            f"weights must be {matrices.shape[-1]} non-negative numbers (got {weights.tolist()})"
        )
    norms = np.sqrt(np.sum(matrices**2, axis=1, keepdims=True))
    degenerate = np.any(norms[:, 0, :] == 0, axis=1)
    safe = np.where(norms == 0, 1.0, norms)
    weighted = matrices / safe * weights
    ideal = weighted.max(axis=1, keepdims=True)
    anti = weighted.min(axis=1, keepdims=True)
    d_plus = np.sqrt(np.sum((weighted - ideal) ** 2, axis=2))
    d_minus = np.sqrt(np.sum((weighted - anti) ** 2, axis=2))
    total = d_plus + d_minus
    closeness = np.where(total > 0, d_minus / np.where(total > 0, total, 1.0), 0.5)
    return (closeness[0], degenerate[0]) if single else (closeness, degenerate)


def _gate(features: pd.DataFrame, probs: pd.DataFrame, settings: McdaSettings):
    kpi, agg = features["kpi_n"].to_numpy(), features["agg_n"].to_numpy()
    thr_kpi = float(np.quantile(kpi, settings.gate_quantile))
    thr_agg = float(np.quantile(agg, settings.gate_quantile))
    gate = (
        (kpi < thr_kpi)
        & (agg < thr_agg)
        & (probs["p_Nominal"].to_numpy() > settings.gate_p_nominal)
    )
    return gate, {"kpi": thr_kpi, "agg": thr_agg}


def select_actions(
    scores: np.ndarray, gate: np.ndarray, dwell: int, margin: float, legacy_r: bool = False
) -> np.ndarray:
    """Apply dwell and switching margin to per-step scores; return action indices.

    ``scores`` has shape ``(T, n_actions)``; index ``n_actions`` means NoAction. A gated step's
    candidate is NoAction. After ``dwell`` steps in an action, a different action takes over
    when its closeness exceeds the current action's by more than ``margin``; NoAction takes
    over when the gate fires and is left when it no longer fires (``legacy_r``: NoAction
    scores −Inf, so it is never re-entered, as in the authors' code).
    """
    n_steps, n_actions = scores.shape
    best = np.where(gate, n_actions, np.argmax(scores, axis=1))
    chosen = np.empty(n_steps, dtype=int)
    chosen[0], hold = best[0], 0
    for step in range(1, n_steps):
        previous, candidate = chosen[step - 1], best[step]
        chosen[step] = previous
        if hold < dwell:
            hold += 1
            continue
        if candidate == previous:
            continue
        if legacy_r or (candidate != n_actions and previous != n_actions):
            new = -np.inf if candidate == n_actions else scores[step, candidate]
            old = -np.inf if previous == n_actions else scores[step, previous]
            switch = new - old > margin
        else:
            switch = True  # the gate's verdict (enter or leave NoAction) is binding
        if switch:
            chosen[step], hold = candidate, 0
    return chosen


def run_mcda(
    residuals: pd.DataFrame, probs: pd.DataFrame, dt: float, settings: McdaSettings
) -> McdaResult:
    """Score, gate and select an action at every step (paper §5; r_notes.md §8).

    Parameters
    ----------
    residuals : DataFrame
        Faulted residuals ``e0 … e4``, one row per step.
    probs : DataFrame
        Regime posteriors ``p_Nominal, p_SensorNoisy, p_DynamicsOff, p_Drift`` per step.
    dt : float
        Sample period, s.
    settings : McdaSettings
    """
    if len(residuals) != len(probs):
        raise DtwinValueError(
            f"residuals and probs must have the same length (got {len(residuals)}, {len(probs)})"
        )
    weights = np.array([float(settings.weights[name]) for name in CRITERIA])
    weights = weights / weights.sum()
    features = mcda_features(residuals, dt, settings.roll_sec)
    tensor = criteria_tensor(features, probs)
    if settings.legacy_r:
        with np.errstate(invalid="ignore", divide="ignore"):
            norms = np.sqrt(np.sum(tensor**2, axis=1, keepdims=True))
            weighted = tensor / norms * weights
            d_plus = np.sqrt(np.sum((weighted - weighted.max(axis=1, keepdims=True)) ** 2, axis=2))
            d_minus = np.sqrt(np.sum((weighted - weighted.min(axis=1, keepdims=True)) ** 2, axis=2))
            scores = d_minus / (d_plus + d_minus)
        degenerate = ~np.all(np.isfinite(scores), axis=1)
        scores = np.where(np.isfinite(scores), scores, 0.0)
    else:
        scores, degenerate = topsis(tensor, weights)
    gate, thresholds = _gate(features, probs, settings)
    dwell = round(settings.min_dwell_sec / dt)
    chosen = select_actions(scores, gate, dwell, settings.switch_margin, settings.legacy_r)
    names = np.array([a.name for a in ACTIONS] + [NO_ACTION])
    ranked = np.sort(scores, axis=1)
    best = np.where(gate, len(ACTIONS), np.argmax(scores, axis=1))
    timeline = pd.DataFrame(
        {
            "step": np.arange(len(residuals)),
            "gate": gate,
            "degenerate": degenerate,
            "best": names[best],
            "best_score": np.where(gate, np.nan, ranked[:, -1]),
            "confidence": ranked[:, -1] - ranked[:, -2],
            "action": names[chosen],
        }
    )
    for index, action in enumerate(ACTIONS):
        timeline[f"score_{action.name}"] = scores[:, index]
    return McdaResult(timeline=timeline, n_degenerate=int(degenerate.sum()), thresholds=thresholds)
