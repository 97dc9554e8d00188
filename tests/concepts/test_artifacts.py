"""Atomic writing (dtwin.artifacts): a writer that fails halfway leaves the old output intact."""

from __future__ import annotations

import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.artifacts import atomic_write, atomic_write_folder, write_csv, write_json


class _DiskFullError(OSError):
    """Stands in for a write that fails after part of the output was written."""


def _fail_halfway(path) -> None:
    with open(path, "w") as handle:
        handle.write("half of the new content")
    raise _DiskFullError("no space left on device")


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("old content\n")
    with pytest.raises(_DiskFullError):
        atomic_write(target, _fail_halfway)
    assert target.read_text() == "old content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_the_writers_replace_the_file_in_one_step(tmp_path):
    write_csv(pd.DataFrame({"a": [1.5]}), tmp_path / "t.csv")
    write_json({"b": 2}, tmp_path / "t.json")
    assert (tmp_path / "t.csv").read_text() == "a\n1.5\n"
    assert (tmp_path / "t.json").read_text().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "t.json"]


def test_a_failed_folder_write_keeps_the_old_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.md").write_text("old report")

    def write(folder):
        (folder / "report.md").write_text("new report, half")
        raise _DiskFullError("no space left on device")

    with pytest.raises(_DiskFullError):
        atomic_write_folder(out, write)
    assert (out / "report.md").read_text() == "old report"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_folder_holding_other_files_is_never_replaced(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "thesis.tex").write_text("months of work")
    with pytest.raises(DtwinValueError, match="holds other files"):
        atomic_write_folder(out, lambda folder: (folder / "report.md").write_text("x"))
    assert (out / "thesis.tex").read_text() == "months of work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
