"""``dtwin regimes`` and ``dtwin monitor``: their arguments and their runs (the CLI's part).

Specification: docs/monitor.md. :func:`add_commands` adds both subcommands to the ``dtwin``
parser (:func:`dtwin.cli.build_parser`); bad input raises :class:`dtwin._validation.
DtwinValueError`, which the CLI turns into one line on standard error and exit status 2. Heavy
modules are imported when a command runs, not when the parser is built.
"""

from __future__ import annotations

import argparse
import inspect
import json
import signal
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_commands", "load_twin", "parse_stretch"]


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"must be an integer (got {text!r})") from error
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 (got {value})")
    return value


def parse_stretch(text: str) -> tuple[float, float]:
    """Return ``(t0, t1)`` of ``--nominal T0:T1`` (seconds, ``t0 < t1``).

    Examples
    --------
    >>> parse_stretch("0:600.5")
    (0.0, 600.5)
    """
    try:
        t0, t1 = (float(part) for part in text.split(":"))
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"must be T0:T1 in seconds (got {text!r})") from error
    if not t0 < t1:
        raise argparse.ArgumentTypeError(f"must have T0 < T1 (got {text!r})")
    return t0, t1


def _read_text(path: str, what: str) -> str:
    from dtwin._validation import DtwinValueError

    try:
        return Path(path).read_text(encoding="utf-8")
    except FileNotFoundError as error:
        raise DtwinValueError(f"{what} not found: {path}") from error
    except (OSError, UnicodeDecodeError) as error:
        raise DtwinValueError(f"{what} could not be read: {path}: {error}") from error


def _yaml_file(path: str, what: str) -> Any:
    from dtwin._validation import DtwinValueError
    from dtwin.gap.twin_file import load_twin_text

    try:
        return load_twin_text(_read_text(path, what))
    except DtwinValueError as error:
        raise DtwinValueError(f"{what} {path}: {error}") from error


def load_twin(path: str, dt: float | None):
    """Return the twin table of a twin file (a ``modules:`` table, or the ``twin:`` shape)."""
    from dtwin.gap.twin_file import is_table, table_file, twin_from_mapping
    from dtwin.twin.paper_chain import paper_table

    content = _yaml_file(path, "twin file")
    if not is_table(content):
        return paper_table(twin_from_mapping(content, dt=dt))
    if "base_dir" in inspect.signature(table_file).parameters:  # a module's file beside the twin
        return table_file(content, dt=dt, base_dir=str(Path(path).resolve().parent))
    return table_file(content, dt=dt)


def _actions(path: str | None):
    from dtwin.monitor.action_table import action_table_from_mapping

    return None if path is None else action_table_from_mapping(_yaml_file(path, "actions file"))


def _regimes(args: argparse.Namespace) -> int:
    from dtwin.artifacts import atomic_write_folder
    from dtwin.gap.recording import read_recording
    from dtwin.monitor.batch_regimes import regimes_of
    from dtwin.monitor.regime_model import REGIME_EM, RegimeSettings
    from dtwin.monitor.regimes_report import write_regimes_report
    from dtwin.twin.table import check_recorded

    actions = _actions(args.actions)
    table = load_twin(args.twin, None)
    recording = read_recording(args.recording, columns=(*table.signals, *table.exogenous))
    check_recorded(table, recording.signals)
    table = load_twin(args.twin, recording.dt)
    settings = RegimeSettings(
        n_states=args.k, k_max=args.k_max, n_restarts=args.restarts, seed=args.seed,
        em=REGIME_EM,
    )  # fmt: skip
    result = regimes_of(
        recording, table, nominal=args.nominal, calibrate=args.calibrate, settings=settings,
        actions=actions, hold=args.hold,
    )  # fmt: skip
    atomic_write_folder(args.out, lambda tmp: write_regimes_report(result, tmp))
    model = result.regime_fit.model
    nominal = [lab for lab, n in zip(model.labels, model.nominal_mask, strict=True) if n]
    print(f"K = {model.n_states} regimes (nominal: {', '.join(nominal)}), settling "
          f"{result.settling} samples -> {args.out}")  # fmt: skip
    return 0


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _monitor(args: argparse.Namespace) -> int:
    from dtwin._validation import DtwinValueError
    from dtwin.monitor.background import DiagnosisJobs
    from dtwin.monitor.live import Monitor, MonitorSettings
    from dtwin.monitor.model_file import monitor_model_from_mapping
    from dtwin.monitor.row_stream import LineSource

    try:
        raw = json.loads(_read_text(args.regimes, "regimes file"))
    except json.JSONDecodeError as error:
        raise DtwinValueError(f"regimes file {args.regimes} is not JSON: {error}") from error
    dt = raw.get("dt") if isinstance(raw, dict) else None
    table = load_twin(args.twin, float(dt) if isinstance(dt, (int, float)) else None)
    model = monitor_model_from_mapping(raw, table, _actions(args.actions))
    settings = MonitorSettings(args.every, args.hold, args.max_gap, args.diagnose_samples)
    jobs = None
    if not args.no_diagnose:
        jobs = DiagnosisJobs(args.twin, [c for c in _columns(model)], keep=args.diagnoses)
    header = None if args.columns is None else args.columns.split(",")
    source = LineSource(follow=args.follow) if args.follow else LineSource(stream=sys.stdin)
    monitor = Monitor(model, table, settings, sys.stdout, sys.stderr, jobs, header)
    # SIGINT too: a process started with SIGINT ignored (a test runner's worker, a shell's
    # background job) inherits the ignore, and Python then raises no KeyboardInterrupt
    previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        summary = monitor.run(source)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if jobs is not None:
            jobs.close()
    return 0 if summary["ended"] == "end_of_input" else 130


def _columns(model) -> list[str]:
    return list(dict.fromkeys(s for u in model.units for s in (*u.inputs, *u.outputs)))


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``regimes`` and ``monitor`` to the ``dtwin`` subcommands."""
    reg = sub.add_parser(
        "regimes",
        help="fit the paper's regime model to a recording of your twin (regimes.json for monitor)",
        description="Residuals of a twin table, a Gaussian HMM over them (K by BIC), nominal and "
        "unknown regimes, posteriors, the posterior-weighted correction, actions per regime.",
    )
    reg.add_argument("recording", help="RECORDING.csv: column t and the twin's signals")
    reg.add_argument("--twin", required=True, help="TWIN.yaml (a modules: table or twin: shape)")
    reg.add_argument("--out", required=True, help="output folder (written atomically)")
    group = reg.add_mutually_exclusive_group()
    group.add_argument("--k", type=_positive, default=None, help="number of regimes K")
    group.add_argument("--k-max", type=_positive, default=8, help="largest K of the BIC sweep")
    reg.add_argument("--nominal", type=parse_stretch, default=None, metavar="T0:T1",
                     help="the nominal stretch, s (default: the first half)")  # fmt: skip
    reg.add_argument("--actions", default=None, metavar="ACTIONS.yaml")
    reg.add_argument("--calibrate", action="store_true", help="fit the twin's params freely")
    reg.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    reg.add_argument("--restarts", type=_positive, default=5, help="EM starts per K")
    reg.add_argument("--hold", type=_positive, default=10, help="samples a change must hold")
    reg.set_defaults(run=_regimes)

    mon = sub.add_parser(
        "monitor",
        help="follow a live stream of rows: regime, corrected outputs, action, events",
        description="One JSON line per sample on stdout; stream problems on stderr.",
    )
    mon.add_argument("--twin", required=True, help="TWIN.yaml, the twin regimes.json was fitted on")
    mon.add_argument("--regimes", required=True, metavar="DIR/regimes.json")
    mon.add_argument("--actions", default=None, metavar="ACTIONS.yaml",
                     help="replaces the actions of regimes.json")  # fmt: skip
    mon.add_argument("--follow", default=None, metavar="FILE",
                     help="read a file being appended (rotation tolerated), not stdin")  # fmt: skip
    mon.add_argument("--every", type=_positive, default=1, help="one sample line per N samples")
    mon.add_argument("--hold", type=_positive, default=None,
                     help="samples a change must hold (default: regimes.json's)")  # fmt: skip
    mon.add_argument("--max-gap", type=int, default=10, help="most missing samples bridged")
    mon.add_argument("--columns", default=None, metavar="t,u,...",
                     help="the columns of a stream without a header line")  # fmt: skip
    mon.add_argument("--no-diagnose", action="store_true", help="no background diagnoses")
    mon.add_argument("--diagnose-samples", type=_positive, default=1000,
                     help="samples since a change a background diagnosis runs on")  # fmt: skip
    mon.add_argument("--diagnoses", default=None, metavar="DIR",
                     help="keep every diagnosis window and answer in DIR")  # fmt: skip
    mon.set_defaults(run=_monitor)
