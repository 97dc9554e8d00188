"""``dtwin regimes``: the paper's regime method on a recording of a user's twin.

Specification: docs/monitor.md §dtwin regimes. :func:`regimes_of` freezes the twin on the
nominal stretch (:func:`dtwin.monitor.causal_twin.freeze_units`), runs it causally over the
whole recording (the residual channels, :class:`~dtwin.monitor.causal_twin.CausalTwin`), fits
the regime model to the residuals after the settling period
(:func:`dtwin.monitor.regime_model.fit_regime_model`), and runs the monitor's own tracker over
them (:class:`~dtwin.monitor.regime_tracker.RegimeTracker`): the filtered posteriors, the
filtered correction and the actions are exactly what ``dtwin monitor`` gives on a replay of the
recording. The smoothed posteriors and the smoothed correction (the paper's, which look ahead)
come from the fit. It also states the false-alarm rate of the events (docs/monitor.md §False
alarms): on the nominal stretch, and of the ``unknown`` regime on residuals simulated from the
fitted regimes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.bias_correction import shaped_bias
from dtwin.monitor.action_table import ActionTable
from dtwin.monitor.causal_twin import CausalTwin, FrozenUnit, freeze_units
from dtwin.monitor.regime_model import (
    UNKNOWN,
    RegimeFit,
    RegimeSettings,
    fit_regime_model,
    poisson_upper,
    simulate_regimes,
)
from dtwin.monitor.regime_tracker import HoldRule, RegimeTracker, TrackedRows

__all__ = [
    "MIN_NOMINAL_SAMPLES",
    "SIMULATED_SAMPLES",
    "DEFAULT_HOLD",
    "RegimesResult",
    "ZERO_RESIDUAL",
    "nominal_rows",
    "informative_channels",
    "column_ranges",
    "regimes_of",
    "false_alarms",
]

#: Fewest samples of the nominal stretch (the twin is fitted on it).
MIN_NOMINAL_SAMPLES = 200
#: Residual rows simulated from the fitted regimes to measure the unknown regime's false alarms.
SIMULATED_SAMPLES = 100_000
#: Samples a change of regime must hold before it is an event.
DEFAULT_HOLD = 10
#: A residual channel whose spread is below this share of its output's is left out.
ZERO_RESIDUAL = 1e-9
#: Stream of ``seed`` used by the false-alarm simulation (``[seed, stream]``).
_SIMULATION_STREAM = 7


@dataclass(frozen=True)
class RegimesResult:
    """The answer of ``dtwin regimes`` (the content of its output folder).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time, s.
    dt : float
        Sample period, s.
    units : list of FrozenUnit
    channels : list of str
        Every recorded output's channel (``kept`` of them hold the regimes).
    settling : int
        Samples of the settling period (rows ``0 … settling − 1`` carry no residual).
    rows : (int, int)
        The nominal stretch, samples.
    recorded, simulated, residuals : ndarray, shape (n, C)
        Per channel: the recording, the causal twin, their difference (NaN while settling).
        The model, ``tracked`` and ``smoothed_applied`` cover the ``kept`` channels.
    regime_fit : RegimeFit
    tracked : TrackedRows
        The monitor's output on rows ``settling … n − 1``.
    smoothed_applied : ndarray, shape (n − settling, C)
        The correction with smoothed posteriors (the paper's), channel units.
    actions : ActionTable or None
    per_regime : dict of str to str
        Each regime's own action (empty without actions).
    false_alarms : dict
        docs/monitor.md §False alarms.
    hold : int
    """

    t: np.ndarray
    dt: float
    units: list[FrozenUnit]
    channels: list[str]
    settling: int
    rows: tuple[int, int]
    recorded: np.ndarray
    simulated: np.ndarray
    residuals: np.ndarray
    regime_fit: RegimeFit
    tracked: TrackedRows
    smoothed_applied: np.ndarray
    actions: ActionTable | None
    per_regime: dict[str, str]
    false_alarms: dict[str, Any]
    hold: int
    columns: tuple[str, ...] = field(default=())
    kept: list[int] = field(default_factory=list)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def dropped(self) -> list[str]:
        """Channels left out of the regimes: their residual is zero to round-off."""
        return [c for i, c in enumerate(self.channels) if i not in self.kept]


def nominal_rows(t: np.ndarray, stretch: tuple[float, float] | None) -> tuple[int, int]:
    """Return the samples ``(first, stop)`` of the nominal stretch ``(t0, t1)`` s (None: 1st half).

    Examples
    --------
    >>> nominal_rows(np.arange(1000) * 0.5, (100.0, 299.5))
    (200, 600)
    """
    n = len(t)
    if stretch is None:
        rows = (0, n // 2)
    else:
        t0, t1 = stretch
        rows = (int(np.searchsorted(t, t0)), int(np.searchsorted(t, t1, side="right")))
    if rows[1] - rows[0] < MIN_NOMINAL_SAMPLES:
        raise DtwinValueError(
            f"the nominal stretch holds {rows[1] - rows[0]} samples "
            f"(needs {MIN_NOMINAL_SAMPLES}; --nominal T0:T1 in the recording's seconds)"
        )
    return rows


def column_ranges(columns, samples: np.ndarray) -> dict[str, tuple[float, float]]:
    """Return each column's admitted range: its bulk widened by the diagnoser's outlier gap.

    The bulk is the central ``1 − 2·OUTLIER_QUANTILE`` of the recording's values, widened by
    ``OUTLIER_GAP`` times its spread on each side (docs/gap.md §Bad input): the monitor refuses
    a value beyond it (``out_of_range``), which would throw the twin's states out.

    Examples
    --------
    >>> column_ranges(["u"], np.linspace(0.0, 1.0, 101)[:, None])
    {'u': (-9.79, 10.79)}
    """
    from dtwin.gap.recording import OUTLIER_GAP, OUTLIER_QUANTILE

    low, high = np.quantile(samples, [OUTLIER_QUANTILE, 1.0 - OUTLIER_QUANTILE], axis=0)
    margin = OUTLIER_GAP * np.maximum(high - low, 1e-12 * np.maximum(np.abs(high), 1.0))
    return {
        name: (round(float(lo - m), 12), round(float(hi + m), 12))
        for name, lo, hi, m in zip(columns, low, high, margin, strict=True)
    }


def informative_channels(recorded: np.ndarray, residuals: np.ndarray) -> list[int]:
    """Return the channels whose residual varies (beyond :data:`ZERO_RESIDUAL` of the output's).

    A module that the recording satisfies exactly (a fusion recorded without noise) leaves a
    residual of round-off: it holds no regime and would make z-scoring divide by zero.

    Raises
    ------
    DtwinValueError
        If no channel is left.
    """
    spread = np.nanstd(recorded, axis=0)
    varies = np.nanstd(residuals, axis=0) > ZERO_RESIDUAL * np.where(spread > 0, spread, 1.0)
    if not varies.any():
        raise DtwinValueError("every residual channel is zero to round-off: nothing to monitor")
    return [int(i) for i in np.flatnonzero(varies)]


def _count_events(nominal: np.ndarray, hold: int, keep=None) -> int:
    events = HoldRule(hold).feed(nominal, 0)
    return sum(1 for e in events if e.kind == "left" and (keep is None or keep(e)))


def false_alarms(
    model_fit: RegimeFit, tracked: TrackedRows, in_stretch: np.ndarray, dt: float, hold: int,
    seed: int,
) -> dict[str, Any]:  # fmt: skip
    """Events on the nominal stretch, and unknown-regime events on simulated nominal residuals.

    Returns
    -------
    dict
        ``nominal_stretch``: events whose change lies on the stretch, its hours, the rate per
        hour and its 95 % upper bound; ``simulated_unknown``: the same for events into
        ``unknown`` on :data:`SIMULATED_SAMPLES` rows drawn from the fitted regimes;
        ``novelty_bound``: the novelty test's threshold (nats) and its false alarms at most,
        one per ``samples`` samples and per hour, on residuals that follow the model
        (:mod:`dtwin.monitor.novelty`).
    """
    model = model_fit.model
    stretch_events = _count_events(tracked.nominal, hold, keep=lambda e: bool(in_stretch[e.change]))
    hours = float(in_stretch.sum()) * dt / 3600.0
    z = simulate_regimes(model, SIMULATED_SAMPLES, [seed, _SIMULATION_STREAM])
    residuals = z * model.scale + model.center
    simulated = RegimeTracker(model).feed(residuals, None)  # regimes only: no correction
    unknown = simulated.regime == model.n_states
    sim_events = _count_events(~unknown, hold)
    sim_hours = SIMULATED_SAMPLES * dt / 3600.0

    def entry(count: int, exposure: float) -> dict[str, float]:
        rate = count / exposure if exposure > 0 else float("nan")
        upper = poisson_upper(count, exposure)
        return {"events": count, "hours": exposure, "per_hour": rate, "upper95_per_hour": upper}

    test = model.novelty
    return {
        "hold": hold,
        "nominal_stretch": entry(stretch_events, hours),
        f"simulated_{UNKNOWN}": entry(sim_events, sim_hours),
        "novelty_bound": None if test is None else {
            "threshold_nats": test.threshold, "samples": test.arl,
            "per_hour": test.per_hour(dt),
        },
    }  # fmt: skip


def _tracked(model_fit, actions, residuals, simulated, gap_hold: int) -> TrackedRows:
    return RegimeTracker(model_fit.model, actions, gap_hold).feed(residuals, simulated)


def regimes_of(
    recording,
    table,
    *,
    nominal: tuple[float, float] | None = None,
    calibrate: bool = False,
    settings: RegimeSettings | None = None,
    actions: ActionTable | None = None,
    hold: int = DEFAULT_HOLD,
) -> RegimesResult:
    """Run the paper's regime method on a recording of a twin table (module docstring).

    Parameters
    ----------
    recording : dtwin.gap.recording.Recording
    table : dtwin.twin.table.TwinTable
    nominal : (float, float), optional
        The nominal stretch ``(t0, t1)``, s (default: the first half).
    calibrate : bool
        Fit the twin's params freely on the nominal stretch.
    settings : RegimeSettings, optional
    actions : ActionTable, optional
    hold : int
        Samples a change of regime must hold before it is an event.

    Returns
    -------
    RegimesResult
    """
    settings = settings or RegimeSettings()
    rows = nominal_rows(recording.t, nominal)
    units = freeze_units(recording, table, rows, calibrate=calibrate)
    twin = CausalTwin(units, table, recording.dt)
    twin.restart(float(recording.t[0]))
    samples = np.column_stack([recording.signals[c] for c in twin.columns])
    causal = twin.feed(samples)
    s = twin.settling
    if recording.n_samples - s < 2 * settings.k_max + 10:
        raise DtwinValueError(
            f"the recording ends {recording.n_samples - s} samples after the settling period "
            f"({s} samples): too short for regimes"
        )
    columns = [i for u in units for i in (twin.columns.index(o) for o in u.outputs)]
    kept = informative_channels(samples[s:, columns], causal.residuals[s:])
    residuals = pd.DataFrame(causal.residuals[s:, kept], columns=[twin.channels[i] for i in kept])
    in_stretch = (np.arange(s, recording.n_samples) >= rows[0]) & (
        np.arange(s, recording.n_samples) < rows[1]
    )
    model_fit = fit_regime_model(residuals, in_stretch, settings)
    tracked = _tracked(
        model_fit, actions, causal.residuals[s:, kept], causal.simulated[s:, kept], s
    )
    model = model_fit.model
    smoothed = shaped_bias(
        model_fit.fit.smoothed @ (model.state_means / model.scale), kappa=model.kappa,
        ema_alpha=model.ema_alpha, rate_max=model.rate_max,
    ).applied * model.scale  # fmt: skip
    per_regime = {} if actions is None else actions.per_regime(model.labels, model.nominal_mask)
    return RegimesResult(
        t=recording.t, dt=recording.dt, units=units, channels=twin.channels, settling=s,
        rows=rows, recorded=samples[:, columns], simulated=causal.simulated,
        residuals=causal.residuals, regime_fit=model_fit, tracked=tracked,
        smoothed_applied=smoothed, actions=actions, per_regime=per_regime,
        false_alarms=false_alarms(model_fit, tracked, in_stretch, recording.dt, hold,
                                  settings.seed),
        hold=hold, columns=twin.columns, kept=kept,
        ranges=column_ranges(twin.columns, samples),
    )  # fmt: skip
