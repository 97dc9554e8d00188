"""``dtwin diagnose`` in the background: the window since a change, without stalling the stream.

Specification: docs/monitor.md §Diagnoses. :class:`DiagnosisJobs` writes a window of samples
as a recording (``t`` and the twin's signals) and runs ``python -m dtwin diagnose`` on it in a
child process, one at a time (the others wait in turn: a diagnosis takes seconds of a core);
:meth:`DiagnosisJobs.poll` collects the finished ones without waiting, :meth:`~DiagnosisJobs.
wait` waits for all (end of input), :meth:`~DiagnosisJobs.cancel` ends the children it started
(an interrupt). Each finished job becomes one event: the answer's module, effect and where it
attaches (``diagnosis.json``), or the one-line error.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DiagnosisJob", "DiagnosisJobs"]

#: Keys of ``diagnosis.json`` copied into the diagnosis event.
ANSWER_KEYS = ("module", "modules", "effect", "at", "params", "confidence", "raw_shrink_pct")


@dataclass
class DiagnosisJob:
    """One window to diagnose: its times, its recording and, once started, its process."""

    since: float
    until: float
    folder: Path
    n_samples: int
    process: subprocess.Popen | None = field(default=None, repr=False)


class DiagnosisJobs:
    """Background diagnoses (module docstring).

    Parameters
    ----------
    twin : path
        The twin file ``dtwin diagnose`` reads.
    columns : sequence of str
        The signals of a window's rows (after ``t``).
    keep : path, optional
        Folder that keeps every window and its answer (``diagnosis_<n>/``); default a
        temporary folder removed at :meth:`close`.
    """

    def __init__(self, twin, columns, keep=None):
        self.twin, self.columns = str(twin), tuple(columns)
        self.root = Path(keep) if keep is not None else Path(tempfile.mkdtemp(prefix="dtwin-"))
        self.root.mkdir(parents=True, exist_ok=True)
        self.keep = keep is not None
        self.waiting: deque[DiagnosisJob] = deque()
        self.running: DiagnosisJob | None = None
        self.counts = {"started": 0, "written": 0, "failed": 0, "cancelled": 0}

    def submit(self, t: np.ndarray, values: np.ndarray) -> DiagnosisJob:
        """Queue the window ``t`` (n,), ``values`` (n, n_columns); start it if nothing runs."""
        number = sum(self.counts.values()) + len(self.waiting) + (self.running is not None)
        folder = self.root / f"diagnosis_{number + 1}"
        folder.mkdir(parents=True, exist_ok=True)
        table = np.column_stack([t, values])
        header = ",".join(("t", *self.columns))
        np.savetxt(folder / "window.csv", table, delimiter=",", header=header, comments="",
                   fmt="%.17g")  # fmt: skip
        job = DiagnosisJob(float(t[0]), float(t[-1]), folder, len(t))
        self.waiting.append(job)
        self._start_next()
        return job

    def _start_next(self) -> None:
        if self.running is not None or not self.waiting:
            return
        job = self.waiting.popleft()
        command = [sys.executable, "-m", "dtwin", "diagnose", str(job.folder / "window.csv"),
                   "--twin", self.twin, "--out", str(job.folder / "answer")]  # fmt: skip
        with open(job.folder / "log.txt", "w") as log:
            job.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        self.running = job
        self.counts["started"] += 1

    def _event(self, job: DiagnosisJob) -> dict[str, Any]:
        event: dict[str, Any] = {"event": "diagnosis", "since": job.since, "until": job.until,
                                 "samples": job.n_samples}  # fmt: skip
        answer = job.folder / "answer" / "diagnosis.json"
        if job.process.returncode == 0 and answer.exists():
            content = json.loads(answer.read_text())
            event.update({key: content.get(key) for key in ANSWER_KEYS if key in content})
            self.counts["written"] += 1
            if self.keep:
                event["report"] = str(job.folder / "answer" / "report.md")
        else:
            lines = (job.folder / "log.txt").read_text().strip().splitlines()
            event["error"] = lines[-1] if lines else f"exit status {job.process.returncode}"
            self.counts["failed"] += 1
        return event

    def poll(self) -> list[dict[str, Any]]:
        """Return the events of the jobs finished since the last call (never waits)."""
        events = []
        while self.running is not None and self.running.process.poll() is not None:
            events.append(self._event(self.running))
            self.running = None
            self._start_next()
        return events

    def wait(self) -> list[dict[str, Any]]:
        """Wait for every queued and running job; return their events."""
        events = []
        while self.running is not None:
            self.running.process.wait()
            events.extend(self.poll())
        return events

    def cancel(self) -> None:
        """End the running child (started here) and drop the queue."""
        if self.running is not None and self.running.process.poll() is None:
            self.running.process.terminate()
            self.running.process.wait()
            self.counts["cancelled"] += 1
        self.counts["cancelled"] += len(self.waiting)
        self.running = None
        self.waiting.clear()

    def close(self) -> None:
        """Remove the temporary folder (kept with ``keep``)."""
        if not self.keep:
            shutil.rmtree(self.root, ignore_errors=True)
