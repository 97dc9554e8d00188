"""Benchmark cases on disk, many per process: generate a case's files, diagnose a case folder.

The workflow runs the gap benchmark (docs/gap.md §Cases and rules) in chunks of cases, one
process per chunk, so a chunk pays the interpreter start-up once. Each case is written to and
read back from its own folder exactly as a case run alone would be (the recording goes through
its CSV before it is diagnosed), so the files and the diagnoses do not depend on the chunking.

Folder of one case: ``recording.csv`` (t in s, signals in the twin's units), ``twin.yaml`` (the
nominal twin), ``key.json`` (the truth; the diagnoser never reads it); folder of one diagnosis:
``diagnosis.json`` and ``report.md`` (:func:`dtwin.gap.report.write_report` without
``gap.png``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from dtwin.artifacts import atomic_write, write_csv, write_json

__all__ = ["diagnose_case_folder", "write_case_folder"]


def write_case_folder(
    case: str,
    benchmark: Mapping[str, Any],
    nominal: Mapping[str, Any],
    folder: str | os.PathLike,
) -> None:
    """Generate one withheld-effect case and write its three files into ``folder``.

    Parameters
    ----------
    case : str
        Case name ``<effect>_<NN>`` (:func:`dtwin.gapbench.generator.case_spec` picks the effect and
        the seed; ``rig_<effect>`` cases come from the rig family).
    benchmark : mapping
        The ``gap.benchmark`` config section (``effects``, ``first_seed``, ``miscalibration``,
        ``noise_error``).
    nominal : mapping
        The nominal twin of a paper-asset case: config ``twin`` (a rig family's case has its own).
    folder : path
        Created if missing; ``recording.csv``, ``twin.yaml`` and ``key.json`` are each written
        atomically.
    """
    from dtwin.gapbench.generator import case_spec
    from dtwin.gapbench.rigs import generate_any_case

    spec = case_spec(case, benchmark["effects"], benchmark["first_seed"])
    generated = generate_any_case(
        spec["effect"],
        spec["seed"],
        miscalibration=benchmark["miscalibration"],
        noise_error=benchmark["noise_error"],
        nominal=nominal,
    )
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_csv(generated.recording, folder / "recording.csv")
    twin_text = yaml.safe_dump(generated.twin, sort_keys=False)
    atomic_write(folder / "twin.yaml", lambda tmp: Path(tmp).write_text(twin_text))
    write_json({"case": case, **generated.key}, folder / "key.json")


def _diagnose_table_folder(case_folder, twin_content, out_folder, calibrate, train_frac, settings):
    """Diagnose a case whose twin is a table (a family case) into ``out_folder``, no figure."""
    from dtwin.gap.recording import read_recording
    from dtwin.gap.table_diagnose import diagnose_table
    from dtwin.gap.table_report import write_table_report
    from dtwin.gap.twin_file import table_file

    table = table_file(twin_content, base_dir=Path(case_folder))
    columns = (*table.signals, *table.exogenous)
    recording = read_recording(Path(case_folder) / "recording.csv", columns=columns)
    result = diagnose_table(
        recording, table, calibrate=calibrate, train_frac=train_frac, settings=settings
    )
    Path(out_folder).mkdir(parents=True, exist_ok=True)
    write_table_report(result, out_folder, figure=False)


def diagnose_case_folder(
    case_folder: str | os.PathLike,
    diagnose_settings: Mapping[str, Any],
    out_folder: str | os.PathLike,
) -> None:
    """Diagnose the recording of one case folder, as ``dtwin diagnose`` does, into ``out_folder``.

    Parameters
    ----------
    case_folder : path
        Holds ``recording.csv`` and ``twin.yaml`` (:func:`write_case_folder`); ``key.json`` is
        not read.
    diagnose_settings : mapping
        The ``gap.diagnose`` config section: ``train_frac``, ``calibrate`` and the decision
        constants of :class:`dtwin.gap.results.GapSettings`.
    out_folder : path
        Created if missing; receives ``diagnosis.json`` and ``report.md``
        (:func:`dtwin.gap.report.write_report` without the figure: the benchmark reads the
        JSON only, and ``gap.png`` cost as much as the diagnosis; ``dtwin diagnose`` on the
        case folder draws it).
    """
    from dtwin.gap import GapSettings, diagnose, twin_discretisation, twin_from_mapping
    from dtwin.gap.recording import read_recording
    from dtwin.gap.report import write_report
    from dtwin.gap.twin_file import is_table

    settings = dict(diagnose_settings)
    train_frac = settings.pop("train_frac")
    calibrate = bool(settings.pop("calibrate"))
    twin_content = yaml.safe_load((Path(case_folder) / "twin.yaml").read_text())
    if is_table(twin_content):
        gap_settings = GapSettings.from_mapping(settings)
        _diagnose_table_folder(
            case_folder, twin_content, out_folder, calibrate, train_frac, gap_settings
        )
        return
    recording = read_recording(Path(case_folder) / "recording.csv")
    twin = twin_from_mapping(twin_content, dt=recording.dt)
    result = diagnose(
        recording,
        twin,
        calibrate=calibrate,
        train_frac=train_frac,
        settings=GapSettings.from_mapping(settings),
        discretisation=twin_discretisation(twin_content),
    )
    Path(out_folder).mkdir(parents=True, exist_ok=True)
    write_report(result, out_folder, figure=False)
