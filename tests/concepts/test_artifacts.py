"""Atomic writing (dtwin.artifacts): a writer that fails halfway leaves the old output intact."""

from __future__ import annotations

import numpy as np
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


def _long_table() -> pd.DataFrame:
    """posteriors.csv's shape: settling rows of NaN, text and int columns, 2,000 rows."""
    rng = np.random.default_rng(5)
    n = 2000
    p = rng.dirichlet(np.ones(3), n)
    p[:40] = np.nan
    p[1000, 1] = np.nan
    return pd.DataFrame({"t": np.arange(n) * 0.02, "settling": (np.arange(n) < 40).astype(int),
                         "regime": np.array(["settling", "S1", "unknown"], dtype=object)[
                             rng.integers(0, 3, n)],
                         "filtered_S1": p[:, 0], "M1:x|filtered": p[:, 1] * 1e-200,
                         "z": rng.normal(size=n) * 1e5})  # fmt: skip


@pytest.mark.parametrize(
    "table",
    [
        pd.DataFrame(  # a recording: finite floats of every size and sign, -0.0 included
            {
                "t": [0.0, 0.001, 0.002, 1e-17],
                "u_act": [-0.0, 1e16, -3.25e-300, 123456789.123456789],
                "x": [1 / 3, -2 / 3, 5e-324, 1e308],
            }
        ),
        pd.DataFrame({"t": [0.0, 1.0], "x": [float("nan"), 2.0]}),  # NaN: an empty field
        pd.DataFrame({"n": [1, 2], "x": [0.5, 1.5]}),  # an int column
        pd.DataFrame({"a b": [0.5], "c": [1.0]}),  # a name to quote
        pd.DataFrame({"x": pd.Series([], dtype=float)}),  # no rows
        pd.DataFrame({"x": [1.5, float("inf")], "y": [1.0, 2.0]}),  # an infinity: to_csv's
        pd.DataFrame(
            {"t": [0.0, 0.5], "regime": ["settling", ""], "M0:u|twin": [np.nan, -0.0], "n": [0, 1]}
        ),  # text, int, NaN and a name with : and |
        _long_table(),  # NaN rows among full ones
    ],
)
def test_write_csv_gives_the_bytes_of_to_csv(tmp_path, table):
    """The plain-float fast path of write_csv writes what DataFrame.to_csv writes."""
    write_csv(table, tmp_path / "fast.csv")
    table.to_csv(tmp_path / "pandas.csv", index=False, float_format="%.12g")
    assert (tmp_path / "fast.csv").read_bytes() == (tmp_path / "pandas.csv").read_bytes()
