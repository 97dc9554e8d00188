"""Fault injection and the regime features (paper §2.2, §4.4; r_notes.md §5).

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
faulted streams. :func:`regime_features` builds the ten HMM features; matching HMM states to
these regimes and scoring the match is :mod:`dtwin.regime_matching`. Arrays are time-first,
shape ``(T,)``.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_finite_array,
    require_in_range,
    require_nonnegative,
    require_number,
)
from dtwin.config_sections import require_keys
from dtwin.physics import backward_velocity, fuse, kpi
from dtwin.twin.wiring import RESIDUALS

__all__ = [
    "REGIMES",
    "FEATURES",
    "DRIFT_ORIGINS",
    "RegimeWindow",
    "FAULT_SCHEDULE",
    "fault_schedule",
    "FaultMagnitudes",
    "regime_labels",
    "inject_faults",
    "regime_features",
]

#: Regime names in schedule order; each name is also the kind of fault it injects.
REGIMES: tuple[str, ...] = ("Nominal", "SensorNoisy", "DynamicsOff", "Drift")

#: The ten HMM features of the fault scenario (r_notes.md §5), before z-scoring.
FEATURES: tuple[str, ...] = (*RESIDUALS, "e_abs_sum", "e_rms", "e1_diff", "e3_diff")

#: Where the drift ramp starts counting samples.
DRIFT_ORIGINS: tuple[str, ...] = ("global", "regime_start")


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
    """Fault sizes (defaults: the authors' code, r_notes.md §5).

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
        require_nonnegative("faults.magnitudes.sensor_A_std", self.sensor_A_std)
        require_nonnegative("faults.magnitudes.sensor_B_std", self.sensor_B_std)
        require_number("faults.magnitudes.dynamics_scale", self.dynamics_scale)
        require_number("faults.magnitudes.drift_per_sample", self.drift_per_sample)
        if self.drift_origin not in DRIFT_ORIGINS:
            raise DtwinValueError(
                f"faults.drift_origin must be one of {', '.join(DRIFT_ORIGINS)} "
                f"(got {self.drift_origin!r})"
            )

    @classmethod
    def from_mapping(
        cls, raw: Any, section: str = "faults", drift_origin: str | None = None
    ) -> FaultMagnitudes:
        """Return the fault sizes of config section ``section`` (errors name the key).

        Reads ``magnitudes`` and ``drift_origin`` (``drift_origin`` given here overrides it);
        the section's other keys (``schedule``, ``seed``) are not read.

        Examples
        --------
        >>> FaultMagnitudes.from_mapping({"magnitudes": {"sensor_A_std": 0.1}}, drift_origin="global")
        FaultMagnitudes(sensor_A_std=0.1, sensor_B_std=0.05, dynamics_scale=0.8, drift_per_sample=0.0007, drift_origin='global')
        """  # noqa: E501
        if isinstance(raw, cls):
            return raw
        needed = ("magnitudes",) if drift_origin is not None else ("magnitudes", "drift_origin")
        raw = require_keys(section, raw, needed, others=True)
        names = [name for name in cls.__dataclass_fields__ if name != "drift_origin"]
        magnitudes = require_keys(f"{section}.magnitudes", raw["magnitudes"], (), names)
        origin = raw["drift_origin"] if drift_origin is None else drift_origin
        return cls(**magnitudes, drift_origin=origin)


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
        Columns :data:`dtwin.twin.wiring.RESIDUALS` (``e0 … e4``), one row per sample.

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
