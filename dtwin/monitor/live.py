"""``dtwin monitor``: the regime model over a live stream, one JSON line per sample.

Specification: docs/monitor.md §dtwin monitor. :class:`Monitor` reads pieces of the stream
(:class:`~dtwin.monitor.row_stream.LineSource`), parses them (:class:`~dtwin.monitor.row_stream.
RowParser`: refused rows are events on standard error), bridges short gaps, restarts on a jump
in time, runs the causal twin and the regime tracker over each piece in one call each, and
writes to standard output:

- a first line ``{"event": "start", ...}`` with the regimes, the channels and the **settling
  period** (samples and seconds);
- one line per sample (or per ``every`` samples): ``t``, ``settling: true`` inside a settling
  period, else the filtered posteriors ``p`` (``S1 … SK, unknown``), the most probable
  ``regime`` (``unknown`` while the novelty test alarms), ``nominal``, the ``novelty``
  statistic (:mod:`dtwin.monitor.novelty`, alarm at 1), the ``corrected`` twin outputs and the
  ``action``;
- ``left_nominal`` / ``back_to_nominal`` events when the nominal regimes lose / regain half the
  probability for ``hold`` samples (never inside a settling period); a ``left_nominal`` starts
  a background ``dtwin diagnose`` (:class:`~dtwin.monitor.background.DiagnosisJobs`) on the
  samples since the change once ``diagnose_samples`` of them are in (a change within
  ``diagnose_samples`` of the last one diagnosed is the same episode: not diagnosed again), its
  answer a ``diagnosis`` event when ready;
- at the end of input (or an interrupt) the diagnoses it started (waited for at the end of
  input, ended on an interrupt), then ``{"event": "summary", ...}``: rows read, used, refused by
  reason, gaps, restarts, events.
"""

from __future__ import annotations

import itertools
import json
import time
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np

from dtwin.artifacts import to_jsonable
from dtwin.monitor.background import DiagnosisJobs
from dtwin.monitor.causal_twin import CausalTwin
from dtwin.monitor.model_file import MonitorModel
from dtwin.monitor.regime_tracker import HoldEvent, HoldRule, RegimeTracker
from dtwin.monitor.row_stream import REASONS, LineSource, ParsedRows, RowParser
from dtwin.monitor.sample_lines import LineTemplate

__all__ = ["MonitorSettings", "Monitor", "MIN_DIAGNOSE_SAMPLES", "MAX_LISTED"]

#: Fewest samples a background diagnosis runs on (``dtwin diagnose``'s minimum).
MIN_DIAGNOSE_SAMPLES = 200
#: Stream events of one kind written to standard error before they are only counted.
MAX_LISTED = 100


@dataclass(frozen=True)
class MonitorSettings:
    """The monitor's options (the command line's).

    Attributes
    ----------
    every : int
        Write one sample line per ``every`` samples.
    hold : int or None
        Samples a change of regime must hold; None: the model file's.
    max_gap : int
        Most missing samples bridged; a longer jump in time restarts.
    diagnose_samples : int
        Samples since a change a background diagnosis runs on.
    """

    every: int = 1
    hold: int | None = None
    max_gap: int = 10
    diagnose_samples: int = 1000


@dataclass
class _Window:
    """Samples collected since a change, for a background diagnosis."""

    start: int
    times: list[np.ndarray] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)
    n: int = 0
    next_k: int = -1


class Monitor:
    """The live monitor (module docstring).

    Parameters
    ----------
    model : MonitorModel
    table : dtwin.twin.table.TwinTable
    settings : MonitorSettings
    out, err : text streams
        Sample lines and events; stream events.
    jobs : DiagnosisJobs, optional
        Background diagnoses (None: no diagnoses).
    header : sequence of str, optional
        The columns of a stream without a header line.
    """

    def __init__(self, model: MonitorModel, table, settings: MonitorSettings, out: IO[str],
                 err: IO[str], jobs: DiagnosisJobs | None = None, header=None):  # fmt: skip
        self.model, self.settings, self.out, self.err, self.jobs = model, settings, out, err, jobs
        self.twin = CausalTwin(model.units, table, model.dt, model.model.channels)
        self.tracker = RegimeTracker(model.model, model.actions, gap_hold=self.twin.settling)
        self.hold = HoldRule(settings.hold or model.hold)
        self.parser = RowParser(self.twin.columns, model.dt, settings.max_gap, header, model.ranges)
        self.modelled = np.array([self.twin.channels.index(c) for c in model.model.channels])
        produced = {s for u in model.units for s in u.outputs}
        self.output_columns = np.array([c in produced for c in self.twin.columns])
        self.labels = list(model.model.labels)
        self.names = None if model.actions is None else list(model.actions.alternatives)
        self.line = self._line_format()
        self.lines = LineTemplate(self.line, (*self.labels, "true", "false", *(self.names or ())))
        self.k, self.k_start, self.t_start = -1, 0, 0.0
        self.last_values: np.ndarray | None = None
        self.recent = (
            np.zeros(0, dtype=np.int64),
            np.zeros(0),
            np.zeros((0, len(self.twin.columns))),
        )
        self.windows: list[_Window] = []
        self.diagnosed = -(10**18)  # the change of the last diagnosis window opened
        self.used = 0
        self.tally = {"restarts": 0, "gaps": 0, "missing_samples": 0, "left_nominal": 0,
                      "back_to_nominal": 0, "diagnoses_skipped": 0}  # fmt: skip
        self.listed: dict[str, int] = {}

    def _line_format(self) -> str:
        k, c = len(self.labels), len(self.modelled)
        p = ", ".join(["%.12g"] * k)
        corrected = ", ".join(["%.12g"] * c)
        action = ', "action": "%s"' if self.names is not None else ""
        return ('{"t": %r, "regime": "%s", "nominal": %s, "novelty": %.4g, "p": [' + p
                + '], "corrected": [' + corrected + "]" + action + "}\n")  # fmt: skip

    # --- writing ---------------------------------------------------------------------------

    def _emit(self, payload: dict[str, Any]) -> None:
        self.out.write(json.dumps(to_jsonable(payload)) + "\n")

    def _stream_event(self, payload: dict[str, Any]) -> None:
        kind = payload["event"]
        count = self.listed.get(kind, 0) + 1
        self.listed[kind] = count
        if count <= MAX_LISTED:
            self.err.write(json.dumps(payload) + "\n")
        if count == MAX_LISTED:
            self.err.write(json.dumps({"event": "listing_stopped", "kind": kind}) + "\n")

    def start_line(self) -> dict[str, Any]:
        """Return the first line: the model, the channels and the settling period."""
        model = self.model
        return {
            "event": "start",
            "columns": ["t", *self.twin.columns],
            "channels": list(model.model.channels),
            "regimes": self.labels,
            "nominal": [*model.model.nominal, False],
            "settling": {"samples": self.twin.settling, "seconds": self.twin.settling * model.dt},
            "dt": model.dt,
            "hold": self.hold.hold,
            "every": self.settings.every,
            "false_alarms": model.false_alarms,
            "actions": self.names,
        }

    # --- the loop --------------------------------------------------------------------------

    def run(self, source: LineSource) -> dict[str, Any]:
        """Monitor ``source`` to its end (or an interrupt); return the summary."""
        started = time.perf_counter()
        self._emit(self.start_line())
        self.out.flush()
        reason = "end_of_input"
        try:
            for lines in source.pieces():
                if lines:
                    self.feed(lines)
                self._poll()
                self.out.flush()
                self.err.flush()
            self._finish_windows()
            if self.jobs is not None:
                for event in self.jobs.wait():
                    self._emit(event)
        except KeyboardInterrupt:
            reason = "interrupted"
            if self.jobs is not None:
                self.jobs.cancel()
        summary = self.summary(reason, time.perf_counter() - started, source)
        self._emit(summary)
        self.out.flush()
        self.err.write(json.dumps(to_jsonable(summary)) + "\n")
        self.err.flush()
        return summary

    def feed(self, lines: list[str]) -> None:
        """Parse and monitor the next lines."""
        parsed = self.parser.parse(lines)
        for event in parsed.events:
            if event.kind in ("time_gap", "time_jump"):
                self.tally["gaps"] += event.kind == "time_gap"
            self._stream_event(event.to_mapping())
        restarts = np.flatnonzero(parsed.restart)
        edges = [*restarts.tolist(), len(parsed.t)]
        if not restarts.size or restarts[0] != 0:
            edges.insert(0, 0)
        for a, b in itertools.pairwise(edges):
            if a == b:
                continue
            if parsed.restart[a]:
                self._restart(float(parsed.t[a]), "time_jump")
            self._process(*self._block(parsed, a, b))
            if self.twin.diverged:  # a state is no longer finite: start again from the stream
                self._restart(float(parsed.t[b - 1]) + self.model.dt, "twin_diverged")

    def _restart(self, t0: float, reason: str) -> None:
        if self.k >= 0:
            self.tally["restarts"] += 1
            self._emit({"event": "restart", "t": t0, "reason": reason,
                        "settling": self.twin.settling})  # fmt: skip
            self._finish_windows()
        self.twin.restart(t0)
        self.tracker.restart()
        self.hold.restart()
        self.k_start, self.t_start = self.k + 1, t0

    def _block(self, parsed: ParsedRows, a: int, b: int):
        """Return rows ``a … b − 1`` with the missing samples bridged: (rows, present, t)."""
        values, times, gaps = parsed.values[a:b], parsed.t[a:b], parsed.gap[a:b]
        if not gaps.any():
            return values, np.ones(len(values), dtype=bool), times
        positions = np.cumsum(gaps + 1) - 1
        block = np.empty((positions[-1] + 1, values.shape[1]))
        present = np.zeros(len(block), dtype=bool)
        block_t = np.empty(len(block))
        block[positions], present[positions], block_t[positions] = values, True, times
        for i in np.flatnonzero(gaps):
            before = values[i - 1] if i > 0 else self.last_values
            t_before = (
                block_t[positions[i] - gaps[i] - 1]
                if i > 0
                else times[i] - (gaps[i] + 1) * self.model.dt
            )
            steps = np.arange(1, gaps[i] + 1) / (gaps[i] + 1)
            rows = before + steps[:, None] * (values[i] - before)
            rows[:, self.output_columns] = np.nan
            block[positions[i] - gaps[i] : positions[i]] = rows
            block_t[positions[i] - gaps[i] : positions[i]] = t_before + steps * (
                times[i] - t_before
            )
        self.tally["missing_samples"] += int(gaps.sum())
        return block, present, block_t

    def _process(self, block: np.ndarray, present: np.ndarray, times: np.ndarray) -> None:
        causal = self.twin.feed(block)
        n, k0 = len(block), self.k + 1
        self.k += n
        self.last_values = block[-1]
        settled = int(n - causal.settling.sum())  # the settling rows come first
        first = k0 + n - settled  # index of the first settled row
        text = []
        if settled < n:
            settling_rows = np.flatnonzero(causal.settling & present)
            text += self._settling_lines(times, settling_rows)
        events: list[HoldEvent] = []
        tracked = None
        if settled:
            tracked = self.tracker.feed(
                causal.residuals[n - settled :, self.modelled],
                causal.simulated[n - settled :, self.modelled],
            )
            events = self.hold.feed(tracked.nominal, first)
            text += self._sample_lines(times[n - settled :], tracked, present[n - settled :])
        self.out.write("".join(text))
        changes = [self._hold_event(event, tracked, first) for event in events]
        opened = [c for c in changes if c >= 0]
        ks = k0 + np.arange(n)
        if present.all():
            self._remember(ks, times, block, opened)
        else:
            self._remember(ks[present], times[present], block[present], opened)

    def _settling_lines(self, times: np.ndarray, rows: np.ndarray) -> list[str]:
        picked = rows[self._counted(len(rows))]
        return [f'{{"t": {t!r}, "settling": true}}\n' for t in times[picked].tolist()]

    def _counted(self, n: int) -> np.ndarray:
        """Which of the next ``n`` samples get a line (one per ``every``), bool (n,)."""
        counts = self.used + np.arange(n)
        self.used += n
        return counts % self.settings.every == 0

    def _sample_lines(self, times, tracked, present) -> list[str]:
        if self.settings.every == 1 and present.all():  # a line for every sample
            self.used += len(present)
            picked = slice(None)
        else:
            rows = np.flatnonzero(present)
            picked = rows[self._counted(len(rows))]
        p, corrected = tracked.posteriors[picked], tracked.corrected[picked]
        if not len(p):
            return []
        if not (np.isfinite(p).all() and np.isfinite(corrected).all()):
            index = np.arange(len(present))[picked]
            return [self._json_line(times[i], tracked, i) for i in index]
        floats = np.column_stack([times[picked], tracked.novelty[picked], p, corrected])
        texts = [tracked.regime[picked], len(self.labels) + ~tracked.nominal[picked]]
        if self.names is not None:
            texts.append(len(self.labels) + 2 + tracked.action[picked])
        return [self.lines.render(floats, np.column_stack(texts))]

    def _json_line(self, t: float, tracked, i: int) -> str:
        payload = {"t": float(t), "regime": self.labels[int(tracked.regime[i])],
                   "nominal": bool(tracked.nominal[i]),
                   "novelty": round(float(tracked.novelty[i]), 4), "p": tracked.posteriors[i],
                   "corrected": tracked.corrected[i]}  # fmt: skip
        if self.names is not None:
            payload["action"] = self.names[int(tracked.action[i])]
        return json.dumps(to_jsonable(payload)) + "\n"

    def _time_of(self, k: int) -> float:
        return self.t_start + (k - self.k_start) * self.model.dt

    def _hold_event(self, event: HoldEvent, tracked, first: int) -> int:
        """Write a hold event; return the change's index if it opens a diagnosis window, else −1."""
        name = "left_nominal" if event.kind == "left" else "back_to_nominal"
        self.tally[name] += 1
        payload = {
            "event": name,
            "t": self._time_of(event.fired),
            "since": self._time_of(event.change),
        }
        opens = -1
        if event.kind == "left":
            row = event.fired - first
            regime = int(tracked.regime[row])  # unknown while the novelty test alarms
            if self.model.model.nominal_mask[regime]:
                posteriors = tracked.posteriors[row].copy()
                posteriors[self.model.model.nominal_mask] = -1.0
                regime = int(np.argmax(posteriors))
            payload["regime"] = self.labels[regime]
            opens = event.change if self.jobs is not None else -1
        self._emit(payload)
        return opens

    # --- background diagnoses --------------------------------------------------------------

    def _remember(self, ks, times, values, changes: list[int]) -> None:
        """Feed the open windows, open one per change, keep the last ``hold`` samples.

        ``ks``, ``times``, ``values``: the block's present samples; a change's window starts
        up to ``hold`` samples before the block, so the last ``hold`` samples are kept.
        """
        for window in list(self.windows):
            self._extend(window, ks, times, values)
        keep = self.hold.hold + 1
        joined = tuple(
            np.concatenate([old, new])
            for old, new in zip(self.recent, (ks, times, values), strict=True)
        )
        for change in changes:
            if change - self.diagnosed < self.settings.diagnose_samples:
                continue  # the same episode: a change back and forth within one window
            self.diagnosed = change
            window = _Window(change, next_k=change)
            self.windows.append(window)
            self._extend(window, *joined)
        self.recent = tuple(part[-keep:] for part in joined)

    def _extend(self, window: _Window, ks, times, values) -> None:
        rows = ks >= window.next_k
        ks, times, values = ks[rows], times[rows], values[rows]
        if not len(ks):
            return
        broken = np.flatnonzero(np.diff(np.concatenate([[window.next_k - 1], ks])) != 1)
        stop = int(broken[0]) if broken.size else len(ks)
        need = self.settings.diagnose_samples - window.n
        take = min(stop, need)
        window.times.append(times[:take])
        window.values.append(values[:take])
        window.n += take
        window.next_k = int(ks[take - 1]) + 1 if take else window.next_k
        if window.n >= self.settings.diagnose_samples or stop < len(ks):
            self._close(window)

    def _close(self, window: _Window) -> None:
        self.windows.remove(window)
        if window.n < MIN_DIAGNOSE_SAMPLES:
            self.tally["diagnoses_skipped"] += 1
            self._emit({"event": "diagnosis_skipped", "since": self._time_of(window.start),
                        "samples": window.n, "reason": f"fewer than {MIN_DIAGNOSE_SAMPLES} "
                        "contiguous samples since the change"})  # fmt: skip
            return
        self.jobs.submit(np.concatenate(window.times), np.concatenate(window.values))

    def _finish_windows(self) -> None:
        for window in list(self.windows):
            self._close(window)

    def _poll(self) -> None:
        if self.jobs is not None:
            for event in self.jobs.poll():
                self._emit(event)

    def summary(self, reason: str, seconds: float, source: LineSource | None = None) -> dict:
        """Return the final line: rows read, used, refused by reason, and what happened."""
        parser = self.parser
        refused = {r: parser.counts[r] for r in REASONS if parser.counts[r]}
        return {
            "event": "summary",
            "ended": reason,
            "rows_read": parser.rows_read,
            "rows_used": parser.rows_read - sum(refused.values()),
            "rows_refused": sum(refused.values()),
            "refused": refused,
            "headers": parser.headers,
            **self.tally,
            "rotations": 0 if source is None else source.rotations,
            "diagnoses": None if self.jobs is None else dict(self.jobs.counts),
            "seconds": round(seconds, 3),
        }
