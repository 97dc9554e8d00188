"""The library's layers and size limits, as the README's Layout section states them.

Layers of ``dtwin/`` (who may import whom):

- concept modules (``dtwin/*.py``): one paper concept each; import only other concept modules
  and the helpers (``_validation``, ``artifacts``); never a stage, figure, reference or gap
  module, never ``yaml`` (no config files) and never Snakemake;
- stages (``dtwin/stages/``): config section → concept calls; may import concepts and R's
  column maps and loaders, never figures, gap or the crosschecks;
- figures (``dtwin/figures/``): draw and judge the paper's claims from tables they are given;
  never a stage, never the model-fitting modules (hmmlearn, ``dtwin.hmm``'s fits,
  ``dtwin.mcda``'s runs, ``dtwin.arx``/``dtwin.surrogate``, scipy.signal) and never a loader of
  R's files;
- reference (``dtwin/reference/``): everything about the R code; its crosschecks run our
  stages on R's signals, so it sits above the stages; never a figure or gap module;
- gap (``dtwin/gap/``): the diagnoser; never a stage, figure or reference module (it draws
  its own figure in the shared style, ``dtwin.figures._style``).
"""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

import pytest

from tests.conftest import REPO

LIBRARY = REPO / "dtwin"
#: Front ends and shared helpers: not a layer of their own.
HELPERS = {"__init__", "__main__", "_validation", "_script", "artifacts", "claims", "cli"}
MAX_FUNCTION_LINES = 80
#: Imports a layer may make although a forbidden prefix covers them.
ALLOWED = {"gap": ("dtwin.figures._style",)}

FORBIDDEN = {
    "concept": ("dtwin.stages", "dtwin.figures", "dtwin.reference", "dtwin.gap", "yaml"),
    "stages": (
        "dtwin.figures",
        "dtwin.gap",
        "dtwin.reference.arx_crosscheck",
        "dtwin.reference.bic_crosscheck",
        "dtwin.reference.correction_crosscheck",
        "dtwin.reference.em_crosscheck",
        "dtwin.reference.hungarian_crosscheck",
        "dtwin.reference.mcda_crosscheck",
        "dtwin.reference.sweep_crosscheck",
    ),
    "figures": (
        "dtwin.stages",
        "dtwin.gap",
        "dtwin.reference.loaders",
        "dtwin.reference.crosschecks",
        "dtwin.arx.fit_arx",
        "dtwin.arx.simulate_arx",
        "dtwin.surrogate",
        "dtwin.mcda.run_mcda",
        "dtwin.mcda.topsis",
        "hmmlearn",
        "scipy.signal",
    ),
    "reference": ("dtwin.figures", "dtwin.gap"),
    "gap": ("dtwin.stages", "dtwin.figures", "dtwin.reference"),
}


def layer_of(path: Path) -> str | None:
    """The layer of a library file, or None for the front ends and helpers."""
    parts = path.relative_to(LIBRARY).parts
    if len(parts) > 1:
        return parts[0]
    return None if path.stem in HELPERS else "concept"


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at any depth of the file (lazy imports included)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


LIBRARY_FILES = sorted(LIBRARY.rglob("*.py"))


@pytest.mark.parametrize("path", LIBRARY_FILES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_each_layer_imports_only_what_it_may(path):
    layer = layer_of(path)
    if layer is None:
        return
    bad = sorted(
        name
        for name in imported_modules(path)
        for prefix in FORBIDDEN[layer]
        if (name == prefix or name.startswith(prefix + "."))
        and not any(name.startswith(ok) for ok in ALLOWED.get(layer, ()))
    )
    assert not bad, f"{layer} module imports {bad}"


def test_no_two_library_files_share_a_name():
    names = Counter(path.name for path in LIBRARY_FILES if path.name != "__init__.py")
    assert [name for name, count in names.items() if count > 1] == []


def _length_without_docstring(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    length = node.end_lineno - node.lineno + 1
    first = node.body[0]
    is_docstring = isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
    if is_docstring and isinstance(first.value.value, str):
        length -= first.end_lineno - first.lineno + 1
    return length


def test_every_library_function_is_short():
    long = []
    for path in LIBRARY_FILES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = _length_without_docstring(node)
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(REPO)}::{node.name} ({lines} lines)")
    assert long == [], f"functions over {MAX_FUNCTION_LINES} lines (docstring excluded): {long}"


def test_no_citation_outside_the_repository():
    """Docstrings cite config/reference/r_notes.md and docs/gap.md, which a clone has."""
    cited = [
        path.relative_to(REPO).as_posix()
        for path in LIBRARY_FILES
        if "REFERENCE.md" in path.read_text() or "issue #5" in path.read_text()
    ]
    assert cited == []
