"""The ``dtwin`` command line: a thin front end over the library.

Subcommands::

    dtwin diagnose RECORDING.csv --twin TWIN.yaml --out DIR [--calibrate] [--train-frac 0.5]
    dtwin generate EFFECT --seed N --out DIR [--magnitude M] [--n-samples N] [--module M]
    dtwin regimes RECORDING.csv --twin TWIN.yaml --out DIR [--k K | --k-max K] [--nominal T0:T1]
    dtwin monitor --twin TWIN.yaml --regimes DIR/regimes.json [--follow FILE] [--every N]

Bad input gets a one-line message on stderr and exit status 2, never a traceback; an unexpected
failure gets exit status 3 (set ``DTWIN_DEBUG=1`` for the traceback). No Python warning reaches
the terminal: a warning raised while diagnosing becomes a line in the report's notes (and in
``diagnosis.json``), and every warning is logged at INFO (shown with ``--verbose``). Output
folders are written into a temporary folder beside ``DIR`` and renamed into place, so ``DIR`` is
never half-written (:func:`dtwin.artifacts.atomic_write_folder`, beside
:func:`~dtwin.artifacts.atomic_write`).
Like the Snakemake scripts it is a front end: it parses arguments and the twin file, then calls
the library (:func:`dtwin.gap.diagnose`, :func:`dtwin.gapbench.generate_case`), which reads the
recording itself (:func:`dtwin.gap.read_recording`).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import threading
import time
import warnings
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main", "build_parser", "load_twin_file", "warning_notes"]

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 3
#: ``--train-frac`` default with ``--heldout``: the recording's rest is the choosing part.
HELDOUT_TRAIN_FRAC = 0.7

logger = logging.getLogger("dtwin.cli")


class CliError(Exception):
    """A bad input, reported in one line."""


def load_twin_file(path: str | os.PathLike):
    """Return the parsed YAML content of a twin file (any YAML value; validated later).

    Read as strict, safe YAML (:func:`dtwin.gap.twin_file.load_twin_text`: no aliases,
    duplicate keys or merge keys, at most 1 MB, ``1e-5`` a number).
    """
    from dtwin._validation import DtwinValueError
    from dtwin.gap.twin_file import load_twin_text

    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError as error:
        raise CliError(f"twin file not found: {path}") from error
    except (OSError, UnicodeDecodeError) as error:
        raise CliError(f"twin file could not be read: {path}: {error}") from error
    try:
        return load_twin_text(text)
    except DtwinValueError as error:
        message = str(error)
        if message.startswith("twin file is not valid YAML: "):
            message = message.replace(
                "twin file is not valid YAML: ", f"twin file is not valid YAML: {path}: ", 1
            )
        raise CliError(message) from error


def _read_heldout(path: str, columns=None):
    """Read ``--heldout`` like the recording; its errors name it as the held-out file."""
    from dtwin._validation import DtwinValueError
    from dtwin.gap.recording import read_recording

    try:
        return read_recording(path, columns=columns)
    except DtwinValueError as error:
        raise CliError(f"held-out {error}") from error


def warning_notes(caught: Sequence[warnings.WarningMessage]) -> list[str]:
    """Return one report note per distinct warning in ``caught`` (category, message, origin).

    Examples
    --------
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     for _ in range(2):
    ...         warnings.warn_explicit("overflow", RuntimeWarning, "dtwin/gap/noise.py", 94)
    >>> warning_notes(caught)  # doctest: +NORMALIZE_WHITESPACE
    ['warning while diagnosing (the numbers it touches may be unreliable):
      RuntimeWarning: overflow (noise.py:94, 2 times)']
    """
    counts = Counter(
        (w.category.__name__, str(w.message), Path(w.filename).name, w.lineno) for w in caught
    )
    return [
        "warning while diagnosing (the numbers it touches may be unreliable): "
        f"{category}: {message} ({filename}:{line}{f', {n} times' if n > 1 else ''})"
        for (category, message, filename, line), n in counts.items()
    ]


def _with_warning_notes(result, caught: Sequence[warnings.WarningMessage]):
    """Return the diagnosis with one note per distinct warning caught while it was made."""
    notes = warning_notes(caught)
    return dataclasses.replace(result, notes=(*result.notes, *notes)) if notes else result


def _diagnose(args: argparse.Namespace) -> int:
    from dtwin.gap.twin_file import is_table

    twin_content = load_twin_file(args.twin)
    if is_table(twin_content):
        return _diagnose_table(args, twin_content)
    from dtwin.artifacts import atomic_write_folder  # the paper's diagnoser: not for a table
    from dtwin.gap.diagnose import diagnose
    from dtwin.gap.recording import read_recording
    from dtwin.gap.report import write_report
    from dtwin.gap.twin_file import twin_discretisation, twin_from_mapping

    recording = read_recording(args.recording)
    heldout = None
    if args.heldout is not None:
        heldout = _read_heldout(args.heldout)
    train_frac = args.train_frac
    if train_frac is None:
        train_frac = HELDOUT_TRAIN_FRAC if heldout is not None else 0.5
    twin = twin_from_mapping(twin_content, dt=recording.dt)
    result = diagnose(
        recording,
        twin,
        calibrate=args.calibrate,
        train_frac=train_frac,
        discretisation=twin_discretisation(twin_content),
        heldout=heldout,
    )
    result = _with_warning_notes(result, getattr(args, "warnings_caught", ()))
    atomic_write_folder(args.out, lambda tmp: write_report(result, tmp))
    own = result.own_shrink_pct
    shrink = (
        f", removes {own:.0f} % of the gap a linear re-fit leaves (own share, scoring part)"
        if own is not None
        else ""
    )
    print(f"{result.module or '-'}: {result.effect}{shrink} -> {args.out}")
    return 0


def _diagnose_table(args: argparse.Namespace, twin_content) -> int:
    """``dtwin diagnose`` with a twin table (``modules:``): docs/gap.md §Twin file."""
    from dtwin.artifacts import atomic_write_folder
    from dtwin.gap.recording import read_recording
    from dtwin.gap.table_diagnose import diagnose_table
    from dtwin.gap.table_report import write_table_report
    from dtwin.gap.twin_file import table_file
    from dtwin.twin.table import check_recorded

    table = table_file(twin_content, base_dir=os.path.dirname(os.path.abspath(args.twin)))
    columns = (*table.signals, *table.exogenous)
    recording = read_recording(args.recording, columns=columns)
    check_recorded(table, recording.signals)
    heldout = None
    if args.heldout is not None:
        heldout = _read_heldout(args.heldout, columns)
    train_frac = args.train_frac or (HELDOUT_TRAIN_FRAC if heldout is not None else 0.5)
    result = diagnose_table(
        recording, table, calibrate=args.calibrate, train_frac=train_frac, heldout=heldout
    )
    atomic_write_folder(args.out, lambda tmp: write_table_report(result, tmp))
    where = " + ".join(result.modules) or "-"
    at = f" at {result.at}" if result.at else ""
    own = result.own_shrink_pct
    shrink = f", removes {own:.0f} % of the gap a re-fitted twin leaves" if own is not None else ""
    print(f"{where}: {result.effect}{at}{shrink} -> {args.out}")
    return 0


def _nominal_twin(path: str) -> dict:
    """Return the ``twin:`` section of a twin file or config (the nominal twin of a case).

    The file's twin must be complete (every module's section and ``noise``); it is checked as
    the diagnoser checks a twin file, errors naming the key.
    """
    from dtwin.params import twin_params_from_mapping

    content = load_twin_file(path)
    if isinstance(content, dict) and isinstance(content.get("twin"), dict):
        content = content["twin"]
    if not isinstance(content, dict):
        raise CliError(f"twin file must hold a mapping: {path}")
    twin_params_from_mapping(content)
    return content


def _generate(args: argparse.Namespace) -> int:
    import yaml

    from dtwin.artifacts import atomic_write_folder, write_csv, write_json
    from dtwin.gapbench.rigs import (
        HARD_RIG_PREFIX,
        RIG_PREFIX,
        generate_any_case,
        generate_hard_rig_case,
        generate_rig_case,
    )

    rigs = {RIG_PREFIX: generate_rig_case, HARD_RIG_PREFIX: generate_hard_rig_case}
    prefix = next((p for p in rigs if args.effect.startswith(p)), None)
    if prefix is not None:
        case = rigs[prefix](
            args.effect[len(prefix) :],
            args.seed,
            magnitude=args.magnitude,
            n_samples=args.n_samples,
        )
    else:
        case = generate_any_case(
            args.effect,
            args.seed,
            magnitude=args.magnitude,
            module=args.module,
            n_samples=args.n_samples,
            nominal=_nominal_twin(args.twin),
        )

    def write(folder: Path) -> None:
        write_csv(case.recording, folder / "recording.csv")
        (folder / "twin.yaml").write_text(yaml.safe_dump(case.twin, sort_keys=False))
        write_json(case.key, folder / "key.json")

    atomic_write_folder(args.out, write)
    print(f"{args.effect} (seed {args.seed}) -> {args.out}")
    return 0


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"must be a number (got {text!r})") from error
    if not 0.05 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0.05, 1] (got {value})")
    return value


def _case_types() -> list[str]:
    """Return every case type ``dtwin generate`` knows (imports the benchmark: ~2 s)."""
    from dtwin.gapbench.generator import ALL_CASE_EFFECTS
    from dtwin.gapbench.rigs import HARD_RIG_EFFECTS, HARD_RIG_PREFIX, RIG_EFFECTS, RIG_PREFIX

    rig_types = [RIG_PREFIX + effect for effect in RIG_EFFECTS]
    rig_types += [HARD_RIG_PREFIX + effect for effect in HARD_RIG_EFFECTS]
    return [*ALL_CASE_EFFECTS, *rig_types]


class _CaseTypes:
    """``generate``'s choices, listed only when argparse asks (not for ``dtwin diagnose``)."""

    def __contains__(self, value: object) -> bool:
        return value in _case_types()

    def __iter__(self):
        return iter(_case_types())


def build_parser() -> argparse.ArgumentParser:
    """Return the ``dtwin`` argument parser (one subparser per subcommand)."""
    parser = argparse.ArgumentParser(
        prog="dtwin", description="Find, explain and mitigate error in modular digital twins."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    diag = sub.add_parser(
        "diagnose",
        help="diagnose the sim-to-real gap of a recording",
        description="Where the gap lies, which unmodelled effect causes it, how far it shrinks.",
    )
    diag.add_argument("recording", help="RECORDING.csv: column t and module signals")
    diag.add_argument("--twin", required=True, help="TWIN.yaml: the twin's parameters")
    diag.add_argument("--out", required=True, help="output folder (written atomically)")
    diag.add_argument(
        "--calibrate", action="store_true", help="fit each module's linear twin first"
    )
    diag.add_argument(
        "--train-frac",
        type=_fraction,
        default=None,
        help="training fraction, at most 0.95 (default 0.5; 0.7 with --heldout, the rest of "
        "the recording then chooses and the held-out file scores)",
    )
    diag.add_argument(
        "--heldout",
        default=None,
        metavar="RECORDING2.csv",
        help="a separate validation experiment: the scoring part (every shrink is measured on it)",
    )
    diag.set_defaults(run=_diagnose)

    gen = sub.add_parser(
        "generate",
        help="generate a recording with a withheld effect (recording.csv, twin.yaml, key.json)",
    )
    gen.add_argument(
        "effect",
        choices=_CaseTypes(),
        metavar="EFFECT",  # argparse lists choices for a metavar: only when help is shown
        help="the case type, one of: %(choices)s",
    )
    gen.add_argument("--seed", type=int, required=True)
    gen.add_argument("--out", required=True)
    gen.add_argument("--magnitude", type=float, default=None, help="0 (faint) to 1 (strong)")
    gen.add_argument("--module", default=None, help="module for multi-module effects")
    gen.add_argument("--n-samples", type=int, default=None)
    gen.add_argument(
        "--twin",
        default="config/config.yaml",
        help="TWIN.yaml or a config with a twin: section: the nominal twin of a paper-asset case "
        "(default config/config.yaml, the paper's; a rig case has its own)",
    )
    gen.set_defaults(run=_generate)

    from dtwin.monitor.commands import add_commands  # dtwin regimes, dtwin monitor

    add_commands(sub)
    return parser


#: Seconds after which a run shows its current step on stderr (docs/gap.md §Speed), and how
#: often it looks.
PROGRESS_AFTER, PROGRESS_EVERY = 3.0, 0.5


class _ProgressLine(logging.Handler):
    """Show the library's current step on stderr once a command has run ``PROGRESS_AFTER`` s.

    The steps are the INFO records of ``dtwin.gap.diagnose.progress``; a daemon thread checks
    every half second and prints ``dtwin <command>: <elapsed> s: <step>`` when the step has
    changed, so a short run prints nothing and a long one a line per step (any step shorter
    than the half second may go unseen).
    """

    def __init__(self, command: str) -> None:
        super().__init__(logging.INFO)
        self.command, self.step, self.shown = command, "reading the input", None
        self.start = time.monotonic()
        self.done = threading.Event()
        self.source = logging.getLogger("dtwin.gap.diagnose.progress")

    def __enter__(self) -> _ProgressLine:
        self.source.setLevel(logging.INFO)
        self.source.addHandler(self)
        self.source.propagate = logger.isEnabledFor(logging.INFO)  # --verbose logs them too
        threading.Thread(target=self._beat, daemon=True).start()
        return self

    def __exit__(self, *exc) -> None:
        self.done.set()
        self.source.removeHandler(self)
        self.source.propagate = True

    def emit(self, record: logging.LogRecord) -> None:
        self.step = record.getMessage()

    def _beat(self) -> None:
        while not self.done.wait(PROGRESS_EVERY):
            elapsed = time.monotonic() - self.start
            if elapsed >= PROGRESS_AFTER and self.step != self.shown:
                self.shown = self.step
                print(f"dtwin {self.command}: {elapsed:.0f} s: {self.step}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``dtwin`` command line and return its exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not progress_wanted():
        return _run(args)
    with _ProgressLine(args.command):
        return _run(args)


def progress_wanted() -> bool:
    """Return whether to show progress lines: stderr is a terminal (a person is waiting).

    Redirected stderr (a log, a pipeline, a test) stays empty on success and holds one line on
    an error, as scripts reading it expect.
    """
    return sys.stderr.isatty()


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command; bad input becomes one line on stderr and exit status 2."""
    from dtwin._validation import DtwinTypeError, DtwinValueError

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            args.warnings_caught = caught  # `diagnose` turns them into report notes
            try:
                return args.run(args)
            finally:
                for message in warning_notes(caught):
                    logger.info(message)
    except (CliError, DtwinValueError, DtwinTypeError) as error:
        print(f"dtwin {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:
        print(f"dtwin {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as error:  # a bug: still one line, unless debugging
        if os.environ.get("DTWIN_DEBUG"):
            raise
        print(
            f"dtwin {args.command}: internal error: {type(error).__name__}: {error} "
            "(set DTWIN_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
