"""Artifact checks and atomic output writing.

Every figure rule writes ``paper_figures/<artifact>.json``::

    {"artifact": "fig03_residual_acf", "files": ["fig03_residual_acf.png", ...],
     "metrics": {...}, "checks": [{"id": ..., "kind": ..., "statement": ..., "expected": ...,
                                   "observed": ..., "passed": ...}]}

``kind`` is ``validity`` (the artifact is sound; a failure fails the rule), ``claim`` (a
statement of the paper, reported honestly, never failing the run), ``target`` (one of the
project's own goals, reported the same way) or ``crosscheck`` (agreement with the authors' R code
on the same inputs).

Writes are atomic: a temporary file in the target folder, then :func:`os.replace`, so a
killed job never leaves a half-written output behind (:func:`atomic_write`); a folder of outputs
is written the same way (:func:`atomic_write_folder`). All atomic writing of dtwin is here.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

from dtwin._validation import DtwinValueError

__all__ = [
    "CHECK_KINDS",
    "Check",
    "FigureArtifact",
    "ArtifactValidityError",
    "validity_finite",
    "validity_probabilities",
    "validity_files_nonempty",
    "atomic_write",
    "atomic_write_folder",
    "write_csv",
    "write_json",
    "write_artifact",
    "to_jsonable",
    "load_yaml",
    "REPLICATES_METRIC",
]

#: ``validity`` (the artifact is sound; a failure fails the rule), ``claim`` (a statement of the
#: paper), ``target`` (the project's own goal), ``crosscheck`` (agreement with the R code).
CHECK_KINDS: tuple[str, ...] = ("validity", "claim", "target", "crosscheck")

#: Metrics key of an artifact that judged its claims again on each replicate of its runs
#: (Fig. 11's sweep, :func:`dtwin.figures._fig11_claims.claims_across_replicates`):
#: ``{"n_replicates", "replicate0_is_figure", "verdicts": {check id: [bool per replicate]}}``;
#: the claims rule (:func:`dtwin.claims.summarise_claims`) turns it into "holds in k of R".
REPLICATES_METRIC = "claims_across_replicates"


class ArtifactValidityError(DtwinValueError):
    """An artifact failed one of its validity checks."""


@dataclass
class FigureArtifact:
    """A drawn figure (a matplotlib Figure) with the numbers behind it and its checks.

    ``paper_figure`` names the paper's figure it reproduces (``"Fig. 5"``, or ``None``),
    ``caption`` says in one line how it differs from the paper and why (draw, optimiser,
    method or the paper's code), ``provenance`` what it is drawn from; all three go in the
    JSON under ``"figure"`` rather than in the figure's title.
    """

    name: str
    figure: Any
    metrics: dict[str, Any]
    checks: list[Check] = field(default_factory=list)
    paper_figure: str | None = None
    caption: str = ""
    provenance: str = ""

    def figure_info(self) -> dict[str, Any]:
        """Return the JSON's ``"figure"`` entry: paper figure, caption, provenance, size (in)."""
        size = getattr(self.figure, "get_size_inches", lambda: (None, None))()
        return {
            "paper_figure": self.paper_figure,
            "caption": self.caption,
            "provenance": self.provenance,
            "size_in": [round(float(v), 3) for v in size] if size[0] is not None else None,
        }


@dataclass(frozen=True)
class Check:
    """One check of an artifact (see the module docstring for the JSON shape).

    ``reference`` optionally holds the authors' R number for the same quantity and ``note`` a
    one-line reason (why a claim does not reproduce, or what a deviation means); both are
    shown in ``paper_figures/CLAIMS.md``.
    """

    id: str
    kind: str
    statement: str
    expected: Any
    observed: Any
    passed: bool
    reference: Any = None
    note: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in CHECK_KINDS:
            raise DtwinValueError(f"check kind must be one of {CHECK_KINDS} (got {self.kind!r})")


def validity_finite(check_id: str, what: str, values: Any) -> Check:
    """Return a validity check that ``values`` (array-like or DataFrame) are all finite."""
    array = np.asarray(values, dtype=float)
    n_bad = int((~np.isfinite(array)).sum())
    return Check(
        id=check_id,
        kind="validity",
        statement=f"{what} are all finite",
        expected="0 non-finite values",
        observed=f"{n_bad} non-finite of {array.size}",
        passed=n_bad == 0 and array.size > 0,
    )


def validity_probabilities(check_id: str, what: str, posteriors: Any) -> Check:
    """Return a validity check that every row of ``posteriors`` (T, K) is a distribution.

    Entries must lie in [0, 1] and rows sum to 1 within 1e-9.
    """
    posteriors = np.asarray(posteriors, dtype=float)
    sums = posteriors.sum(axis=1)
    worst = float(np.max(np.abs(sums - 1.0))) if len(sums) else float("nan")
    low, high = float(posteriors.min()), float(posteriors.max())
    return Check(
        id=check_id,
        kind="validity",
        statement=f"{what} are probabilities: within [0, 1], every row sums to 1",
        expected="range within [0, 1]; max |row sum - 1| <= 1e-9",
        observed={"min": low, "max": high, "max_abs_row_sum_error": worst},
        passed=bool(low >= -1e-12 and high <= 1 + 1e-12 and worst <= 1e-9),
    )


def validity_files_nonempty(paths: Iterable[str | os.PathLike]) -> Check:
    """Return a validity check that every file exists and is non-empty."""
    sizes = {Path(p).name: (Path(p).stat().st_size if Path(p).exists() else 0) for p in paths}
    return Check(
        id="files_nonempty",
        kind="validity",
        statement="every output file exists and is non-empty",
        expected="size > 0 bytes",
        observed=sizes,
        passed=bool(sizes) and all(size > 0 for size in sizes.values()),
    )


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> None:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it to ``path``.

    The temporary file keeps ``path``'s suffix so writers that infer the format from the
    name (matplotlib) behave. On any error the temporary file is removed.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp_path = tempfile.mkstemp(
        dir=target.parent, prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}"
    )
    os.close(handle)
    try:
        write(tmp_path)
        os.replace(tmp_path, target)
    except BaseException:
        if os.path.exists(tmp_path):
            os.remove(tmp_path)
        raise


def atomic_write_folder(out_dir: str | os.PathLike, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp_dir)`` on a fresh folder beside ``out_dir``, then rename it into place.

    An existing ``out_dir`` is replaced only if it holds nothing but files this tool writes
    (the files ``write`` produces); otherwise :class:`DtwinValueError`. On any error the
    temporary folder is removed, so ``out_dir`` is either the old folder or the new one.
    """
    target = Path(out_dir)
    if target.exists() and not target.is_dir():
        raise DtwinValueError(f"--out {target} exists and is not a folder")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp"))
    try:
        write(tmp)
        produced = {p.name for p in tmp.iterdir()}
        if target.exists():
            foreign = {p.name for p in target.iterdir()} - produced
            if foreign:
                raise DtwinValueError(
                    f"--out {target} exists and holds other files ({', '.join(sorted(foreign))}); "
                    "choose a new folder"
                )
            backup = target.with_name(f".{target.name}.old")
            shutil.rmtree(backup, ignore_errors=True)
            os.replace(target, backup)
            os.replace(tmp, target)
            shutil.rmtree(backup, ignore_errors=True)
        else:
            os.replace(tmp, target)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_csv(table: pd.DataFrame, path: str | os.PathLike, float_format: str = "%.12g") -> None:
    """Write ``table`` as CSV atomically, without index, floats with 12 significant digits.

    A table of plain cells (float64 columns, NaN an empty field; int64 columns; text columns of
    plain words; plain column names) is formatted row by row, one ``%`` per row: the bytes of
    ``DataFrame.to_csv`` at a quarter of its time (``tests/concepts/test_artifacts.py``); any
    other table goes through ``to_csv``.
    """
    text = _plain_table_csv(table, float_format)
    if text is not None:
        atomic_write(path, lambda tmp: Path(tmp).write_text(text))
        return
    atomic_write(path, lambda tmp: table.to_csv(tmp, index=False, float_format=float_format))


def _plain_table_csv(table: pd.DataFrame, float_format: str) -> str | None:
    """Return ``table.to_csv(index=False, float_format=...)``'s text, or None if not plain.

    Plain: at least one row and two columns (``to_csv`` quotes a lone empty field), names and
    texts of :data:`_PLAIN_NAME`'s characters (written unquoted; texts may be empty),
    ``float_format`` a ``%.<p>g``, float64 columns without infinities (NaN: an empty field),
    int64 columns and text columns (str cells only).
    """
    names = [str(name) for name in table.columns]
    if len(table) == 0 or len(names) < 2 or not all(_PLAIN_NAME.fullmatch(n) for n in names):
        return None
    if not _G_FORMAT.fullmatch(float_format):
        return None
    import pandas as pd  # the caller has it loaded (its table)

    fields, floats, codes, texts = [], [], [], []
    for j in range(table.shape[1]):
        column = table.iloc[:, j]
        if column.dtype == np.float64:
            fields.append(float_format)
            floats.append(column.to_numpy())
            continue
        text = column.dtype != np.int64
        if text and not pd.api.types.is_string_dtype(column.dtype):  # object or str
            return None
        code, uniques = pd.factorize(column.to_numpy(), use_na_sentinel=False)
        words = [str(u) for u in uniques]
        if text and not all(isinstance(u, str) and _PLAIN_TEXT.fullmatch(u) for u in uniques):
            return None
        fields.append("%s")
        codes.append(code.astype(np.int64) + len(texts))
        texts += words
    n = len(table)
    values = np.column_stack(floats) if floats else np.zeros((n, 0))
    if np.isinf(values).any():
        return None
    choices = np.column_stack(codes) if codes else np.zeros((n, 0), dtype=np.int64)
    line = ",".join(fields) + "\n"
    return ",".join(names) + "\n" + "".join(_row_texts(line, values, choices, texts, range(n)))


def _row_texts(line: str, values, choices, texts, rows) -> list[str]:
    """Return ``line % cells`` for each of ``rows``; a NaN is an empty field."""
    fields = line[:-1].split(",")
    out = []
    for r in rows:
        numbers, words = iter(values[r].tolist()), iter(choices[r].tolist())
        cells = [texts[next(words)] if f == "%s" else next(numbers) for f in fields]
        if any(c != c for c in cells):  # NaN
            cells = [c if f == "%s" else "" if c != c else f % c
                     for f, c in zip(fields, cells, strict=True)]  # fmt: skip
            out.append(",".join(cells) + "\n")
        else:
            out.append(line % tuple(cells))
    return out


_PLAIN_NAME = re.compile(r"[A-Za-z0-9_:|+.-]+")
_PLAIN_TEXT = re.compile(r"[A-Za-z0-9_:|+.-]*")
_G_FORMAT = re.compile(r"%\.(1[0-7]|[1-9])g")


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, tuples and non-finite floats to plain JSON values.

    Non-finite floats become ``None`` (JSON has no NaN), so the files stay strict JSON.
    """
    if isinstance(value, Mapping):
        return {str(key): to_jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def write_json(payload: Mapping[str, Any], path: str | os.PathLike) -> None:
    """Write ``payload`` as indented, key-ordered strict JSON, atomically."""
    text = json.dumps(to_jsonable(payload), indent=2, allow_nan=False) + "\n"

    def write(tmp: str) -> None:
        Path(tmp).write_text(text, encoding="utf-8")

    atomic_write(path, write)


def write_artifact(
    path: str | os.PathLike,
    artifact: str,
    files: Sequence[str | os.PathLike],
    metrics: Mapping[str, Any],
    checks: Sequence[Check],
    figure: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write the artifact JSON and raise if a validity check failed.

    A files-non-empty validity check is appended automatically; ``figure`` (paper figure,
    caption, provenance: :meth:`FigureArtifact.figure_info`) is written under ``"figure"``.
    The JSON is written in every case (so the failing numbers can be read), then
    :class:`ArtifactValidityError` is raised for failed validity checks, which makes
    Snakemake fail the job and remove its outputs.

    Returns
    -------
    dict
        The payload that was written.
    """
    all_checks = [*checks, validity_files_nonempty(files)]
    payload = {
        "artifact": artifact,
        "files": [Path(f).name for f in files],
        **({"figure": dict(figure)} if figure is not None else {}),
        "metrics": dict(metrics),
        "checks": [asdict(check) for check in all_checks],
    }
    write_json(payload, path)
    failed = [c.id for c in all_checks if c.kind == "validity" and not c.passed]
    if failed:
        raise ArtifactValidityError(f"{artifact}: validity check(s) failed: {', '.join(failed)}")
    return to_jsonable(payload)


def load_yaml(path: str | os.PathLike) -> Any:
    """Return the parsed content of a YAML file (a reference-number file, a twin file)."""
    import yaml

    with open(path, encoding="utf-8") as handle:
        return yaml.safe_load(handle)
