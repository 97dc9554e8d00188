"""The regime model run forward over residual rows: posteriors, regime, correction, action.

Specification: docs/monitor.md §Regimes, §Correction. :class:`RegimeTracker` holds the
filter's last vector and the correction's last values, so a series fed in chunks of any size
gives the bits it gives in one call (``dtwin regimes`` feeds the whole recording, ``dtwin
monitor`` what the stream holds). Per row: the filtered posteriors of the K fitted regimes and
``unknown`` (:func:`dtwin.monitor._stream_kernels.filter_rows`, paper Eq. (4)); the most
probable regime; the novelty test (:mod:`dtwin.monitor.novelty`: CUSUMs on the residuals'
innovations under the nominal regimes, its statistic in units of its threshold; while it is at
or above 1 the sample is not nominal and its regime ``unknown`` unless a non-nominal regime is
the most probable); whether the nominal regimes hold at least half the probability; the
posterior-weighted bias ``b̂ = Σ_k γ_t(k) μ_k`` (Eq. (25); ``μ_unknown = 0``: no correction for a
regime never seen), shaped in residual standard deviations by the DAG's own
:func:`dtwin.bias_correction.shaped_bias` and added to the twin's outputs; and, with an
actions table, the action (:mod:`dtwin.monitor.action_table`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dtwin.bias_correction import shaped_bias
from dtwin.monitor._stream_kernels import cusum_rows, filter_rows, standardise_rows
from dtwin.monitor.action_table import ActionTable
from dtwin.monitor.regime_model import RegimeModel

__all__ = ["TrackedRows", "RegimeTracker", "HoldEvent", "HoldRule"]


@dataclass(frozen=True)
class TrackedRows:
    """What :meth:`RegimeTracker.feed` returns for a chunk of rows.

    Attributes
    ----------
    posteriors : ndarray, shape (n, K + 1)
        Filtered posteriors of ``S1 … SK, unknown``.
    regime : ndarray of int, shape (n,)
        The most probable of them.
    nominal : ndarray of bool, shape (n,)
        The nominal regimes hold at least half the probability and the novelty test does not
        alarm.
    novelty : ndarray, shape (n,)
        The novelty statistic in units of its threshold (alarm at 1; zeros without a test).
    applied : ndarray, shape (n, C), or None
        The shaped bias added to the twin's outputs, channel units (None: fed without them).
    corrected : ndarray, shape (n, C), or None
        The twin's outputs plus ``applied``.
    action : ndarray of int, shape (n,), or None
        Index of the chosen alternative (None without an actions table).
    """

    posteriors: np.ndarray
    regime: np.ndarray
    nominal: np.ndarray
    novelty: np.ndarray
    applied: np.ndarray | None
    corrected: np.ndarray | None
    action: np.ndarray | None


class RegimeTracker:
    """Filter, correction and action over residual rows, continued across calls.

    Parameters
    ----------
    model : RegimeModel
    actions : ActionTable, optional
    gap_hold : int
        Rows after a missing row (a bridged gap: the twin ran on guessed inputs) over which the
        novelty test is held (its statistics kept as they were); the twin's settling period.
    """

    def __init__(self, model: RegimeModel, actions: ActionTable | None = None, gap_hold: int = 0):
        self.model = model
        self.gap_hold = int(gap_hold)
        self.arrays = model.filter_arrays()
        self.mask = model.nominal_mask
        self.nominal_index = np.flatnonzero(self.mask)
        self.variances = model.sds**2
        self.bias_z = np.vstack([model.state_means / model.scale, np.zeros(len(model.scale))])
        self.actions = actions
        self.stacked = None if actions is None else actions.stacked(model.labels, self.mask)
        self.restart()

    def restart(self) -> None:
        """Start a new sequence: the filter from its initial distribution, no correction yet."""
        self.alpha = self.arrays.start.copy()
        self.fresh = True
        self.shaping: tuple[np.ndarray, np.ndarray] | None = None
        c = len(self.model.scale)
        test = self.model.novelty
        self.history = np.full((0 if test is None else test.lags, c), np.nan)
        self.cusums = np.zeros((c, 3))
        self.since_gap = self.gap_hold  # rows since the last missing row

    def feed(self, residuals: np.ndarray, simulated: np.ndarray | None) -> TrackedRows:
        """Track the next rows.

        Parameters
        ----------
        residuals : ndarray, shape (n, C)
            ``recorded − twin`` per channel (NaN at a missing sample, or not finite: a
            prediction step).
        simulated : ndarray, shape (n, C), or None
            The twin's outputs; None: no correction (regimes and events only, as the
            false-alarm simulation needs; a tracker fed so keeps no correction state).

        Returns
        -------
        TrackedRows
        """
        model, arrays = self.model, self.arrays
        with np.errstate(invalid="ignore", over="ignore"):
            z = np.ascontiguousarray((residuals - model.center) / model.scale)
        if not np.isfinite(z).all():
            z[~np.isfinite(z)] = np.nan  # a diverged twin's row: a prediction step
        before, fresh = self.alpha.copy(), self.fresh
        posteriors = filter_rows(
            z, arrays.means, arrays.precision, arrays.log_norm, arrays.transmat, self.alpha,
            self.fresh,
        )  # fmt: skip
        self.fresh = False
        novelty = self._novelty(z, posteriors, before, fresh)
        novel = novelty >= 1.0
        regime = np.argmax(posteriors, axis=1)
        regime[novel & self.mask[regime]] = model.n_states  # unknown
        applied = corrected = None
        if simulated is not None:
            shaped = shaped_bias(
                posteriors @ self.bias_z, kappa=model.kappa, ema_alpha=model.ema_alpha,
                rate_max=model.rate_max, initial=self.shaping,
            )  # fmt: skip
            self.shaping = (shaped.smoothed[-1], shaped.applied[-1])
            applied = shaped.applied * model.scale
            corrected = simulated + applied
        action = None if self.actions is None else self.actions.decide(posteriors, self.stacked)
        return TrackedRows(
            posteriors=posteriors,
            regime=regime,
            nominal=(posteriors[:, self.nominal_index].sum(axis=1) >= 0.5) & ~novel,
            novelty=novelty,
            applied=applied,
            corrected=corrected,
            action=action,
        )

    def _novelty(self, z, posteriors, before, fresh) -> np.ndarray:
        """Return the novelty statistic of the rows (units of its threshold), continued."""
        test, model = self.model.novelty, self.model
        if test is None:
            return np.zeros(len(z))
        x = standardise_rows(z, posteriors, before, fresh, self.arrays.transmat, model.means,
                             self.variances, self.mask[:-1])  # fmt: skip
        held = np.zeros(len(z), dtype=bool)
        missing = np.isnan(z).any(axis=1)
        if self.gap_hold and (missing.any() or self.since_gap < self.gap_hold):
            index = np.arange(len(z))
            last = np.maximum.accumulate(np.where(missing, index, -1 - self.since_gap))
            held = index - last <= self.gap_hold
        if missing.any():
            self.since_gap = len(z) - 1 - int(np.flatnonzero(missing)[-1])
        else:
            self.since_gap = min(self.since_gap + len(z), self.gap_hold)
        return cusum_rows(x, self.history, test.coef, test.sigma, self.cusums, test.shift,
                          test.ratio, test.threshold, held)  # fmt: skip


@dataclass(frozen=True)
class HoldEvent:
    """A change of regime that held: ``left`` nominal or came ``back``.

    ``change`` is the index of the run's first sample, ``fired`` that of the sample at which
    it had held ``hold`` samples (indices as the caller numbers the rows it feeds).
    """

    kind: str
    change: int
    fired: int


class HoldRule:
    """Events when the nominal flag changes and holds for ``hold`` consecutive samples.

    A run of ``hold`` non-nominal samples fires ``left`` (once); after it, a run of ``hold``
    nominal samples fires ``back`` and re-arms the rule.
    """

    def __init__(self, hold: int):
        self.hold = int(hold)
        self.restart()

    def restart(self) -> None:
        """Forget the current run (a new sequence starts nominal)."""
        self.away, self.run, self.start = False, 0, 0

    def feed(self, nominal: np.ndarray, first: int) -> list[HoldEvent]:
        """Return the events fired by ``nominal`` (bool per row; row 0 has index ``first``)."""
        events = []
        for offset, flag in enumerate(nominal.tolist()):
            index = first + offset
            if flag == (not self.away):  # the current side: no run towards a change
                self.run = 0
                continue
            if self.run == 0:
                self.start = index
            self.run += 1
            if self.run >= self.hold:
                self.away = not self.away
                events.append(HoldEvent("left" if self.away else "back", self.start, index))
                self.run = 0
        return events
