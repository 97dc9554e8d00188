"""The library's layers and size limits, as the README's Layout section states them.

Layers of ``dtwin/`` (who may import whom, directly or through any chain of dtwin imports):

- concept modules (``dtwin/*.py``): one paper concept each; import only other concept modules,
  the twin package and the helpers (``_validation``, ``artifacts``); never a stage, figure,
  reference, gap or gapbench module, never a front end (``cli``, ``_script``, ``claims``), never
  ``yaml`` (no config files) and never Snakemake;
- stages (``dtwin/stages/``): config section → concept calls; may import concepts and R's
  column maps and loaders, never figures, gap or the crosschecks;
- figures (``dtwin/figures/``): draw and judge the paper's claims from tables they are given;
  never a stage, never the model-fitting modules (hmmlearn, ``dtwin.hmm``, ``dtwin.hmm_ar``,
  ``dtwin.mcda``'s runs, ``dtwin.arx``/``dtwin.surrogate``, scipy.signal) and never a loader of
  R's files or a crosscheck;
- reference (``dtwin/reference/``): everything about the R code; its crosschecks run our
  stages on R's signals, so it sits above the stages; never a figure or gap module;
- gap (``dtwin/gap/``): the diagnoser; never a stage, figure or reference module (it draws
  its own figure in the shared style, ``dtwin.figures._style``) and never its benchmark;
- gapbench (``dtwin/gapbench/``): the diagnoser's benchmark (generated cases, their scores);
  may import the diagnoser, never a stage, figure or reference module. No other layer imports it.
- twin (``dtwin/twin/``): a twin as data (the module table, blocks, expressions, simulation)
  and the paper's six modules (wiring, contract, exact plant, force loops); the bottom layer
  that concepts, gap, gapbench and monitor read. It imports only itself and the root helpers
  (``_validation``, ``_jit``, ``_lfilter``), and of third-party packages numpy, scipy, numba
  and fmpy (an FMU module's reader);
- monitor (``dtwin/monitor/``): ``dtwin regimes`` and ``dtwin monitor`` on a user's twin; may
  import concepts, the twin package and the diagnoser (and draw in the shared style), never a
  stage, figure, reference or gapbench module. Only the command line imports it.

Every forbidden dtwin name is checked against each file's imports and those of every dtwin
module it reaches (a name a package re-exports lazily, dtwin/_lazy.py, counts as an import of
the module that defines it); a forbidden third-party package (``yaml``, Snakemake, hmmlearn,
scipy.signal) against the file's own imports, since one deeper down may be imported lazily (what
a rule's script loads at run time is measured by tests/workflow/test_import_budget.py). A compute
rule (a script that publishes no artifact) never reaches a figure module, so a label edit in a
figure reruns that figure and ``claims`` only. The library carries no issue numbers and no
dated measurements (history lives in commit messages).
"""

from __future__ import annotations

import ast
import re
import sys
from collections import Counter
from functools import cache
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO

LIBRARY = REPO / "dtwin"
#: Front ends and shared helpers: not a layer of their own.
HELPERS = {
    "__init__",
    "__main__",
    "_validation",
    "_script",
    "_job_server",
    "artifacts",
    "claims",
    "cli",
}
MAX_FUNCTION_LINES = 80
#: Imports a layer may make although a forbidden prefix covers them: the gap diagnoser draws its
#: report in the shared style; Fig. 11 compares its rebuilt R inputs itself (numpy and pandas only).
ALLOWED = {
    "gap": ("dtwin.figures._style", "dtwin.figures._print_check"),
    "gapbench": ("dtwin.figures._style", "dtwin.figures._print_check"),
    "figures": ("dtwin.reference.sweep_crosscheck",),
}
#: The shared drawing style, which rules that draw no artifact may use (a diagnosis's gap.png).
SHARED_STYLE = {"__init__.py", "_style.py", "_print_check.py"}

FORBIDDEN = {
    "concept": (
        "dtwin.stages",
        "dtwin.figures",
        "dtwin.reference",
        "dtwin.gap",
        "dtwin.gapbench",
        "dtwin.claims",
        "dtwin.cli",
        "dtwin._script",
        "yaml",
        "snakemake",
    ),
    "stages": (
        "dtwin.figures",
        "dtwin.gap",
        "dtwin.gapbench",
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
        "dtwin.gapbench",
        "dtwin.reference.loaders",
        "dtwin.reference.arx_crosscheck",
        "dtwin.reference.bic_crosscheck",
        "dtwin.reference.correction_crosscheck",
        "dtwin.reference.em_crosscheck",
        "dtwin.reference.hungarian_crosscheck",
        "dtwin.reference.mcda_crosscheck",
        "dtwin.reference.sweep_crosscheck",
        "dtwin.hmm",
        "dtwin.hmm_ar",
        "dtwin.arx.fit_arx",
        "dtwin.arx.simulate_arx",
        "dtwin.surrogate",
        "dtwin.mcda.run_mcda",
        "dtwin.mcda.topsis",
        "hmmlearn",
        "scipy.signal",
    ),
    "reference": ("dtwin.figures", "dtwin.gap", "dtwin.gapbench"),
    "gap": ("dtwin.stages", "dtwin.figures", "dtwin.reference", "dtwin.gapbench"),
    "gapbench": ("dtwin.stages", "dtwin.figures", "dtwin.reference"),
    "twin": (
        "dtwin.stages",
        "dtwin.figures",
        "dtwin.reference",
        "dtwin.gap",
        "dtwin.gapbench",
        "dtwin.hmm",
        "dtwin.claims",
        "dtwin.cli",
        "yaml",
        "snakemake",
    ),
    "monitor": (
        "dtwin.stages",
        "dtwin.figures",
        "dtwin.reference",
        "dtwin.gapbench",
        "dtwin.claims",
        "dtwin.cli",
        "dtwin._script",
        "snakemake",
    ),
}
# dtwin regimes and dtwin monitor (dtwin/monitor/): only the command line imports them
for _layer in FORBIDDEN:
    if _layer != "monitor":
        FORBIDDEN[_layer] += ("dtwin.monitor",)
ALLOWED["monitor"] = ("dtwin.figures._style", "dtwin.figures._print_check")


def layer_of(path: Path) -> str | None:
    """The layer of a library file, or None for the front ends and helpers."""
    parts = path.relative_to(LIBRARY).parts
    if len(parts) > 1:
        return parts[0]
    return None if path.stem in HELPERS else "concept"


@cache
def imported_modules(path: Path) -> frozenset[str]:
    """Every module a file imports, at any depth of the file (lazy imports included).

    Cached: the layer checks walk the same files from every module that reaches them.
    """
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return frozenset(names)


LIBRARY_FILES = sorted(LIBRARY.rglob("*.py"))


def module_files(name: str) -> list[Path]:
    """The library files importing ``name`` runs: every package ``__init__`` on the way, the module.

    ``dtwin.a.b`` → ``dtwin/__init__.py``, ``dtwin/a/__init__.py``, ``dtwin/a/b.py``; an
    imported member (``dtwin.a.b.f``) resolves to its module. Not a dtwin name: ``[]``.
    """
    parts = name.split(".")
    if parts[0] != "dtwin":
        return []
    found = []
    for depth in range(1, len(parts) + 1):
        stem = REPO.joinpath(*parts[:depth])
        for candidate in (stem.with_suffix(".py"), stem / "__init__.py"):
            if candidate.is_file():
                found.append(candidate)
    package = REPO.joinpath(*parts[:-1]) / "__init__.py"
    exported = lazy_exports(package).get(parts[-1]) if package.is_file() else None
    # dtwin.gap re-exports the function diagnose of its module dtwin.gap.diagnose
    return found + module_files(exported) if exported not in (None, name) else found


@cache
def lazy_exports(package: Path) -> dict[str, str]:
    """The names a package re-exports lazily (its ``_EXPORTS``, dtwin/_lazy.py): name → module.

    ``from dtwin import fit_hmm`` runs dtwin/hmm.py on first use, so it counts as importing it.
    """
    for node in ast.parse(package.read_text()).body:
        target = node.targets[0] if isinstance(node, ast.Assign) else getattr(node, "target", None)
        if isinstance(target, ast.Name) and target.id == "_EXPORTS":
            return ast.literal_eval(node.value)
    return {}


@cache
def reached(path: Path) -> frozenset[Path]:
    """Every library file that importing ``path`` can run (lazy imports included), transitively."""
    seen: set[Path] = set()
    pending = [path]
    while pending:
        for name in imported_modules(pending.pop()):
            for found in module_files(name):
                if found not in seen:
                    seen.add(found)
                    pending.append(found)
    return frozenset(seen)


def test_a_lazily_re_exported_name_counts_as_an_import_of_its_module(tmp_path):
    """A figure importing ``fit_hmm`` through dtwin's lazy re-exports reaches dtwin/hmm.py."""
    figure = tmp_path / "figure.py"
    figure.write_text("from dtwin import fit_hmm\nfrom dtwin.gapbench import generate_case\n")
    assert {LIBRARY / "hmm.py", LIBRARY / "gapbench" / "generator.py"} <= reached(figure)


def _forbidden_imports(path: Path, layer: str) -> list[str]:
    """Forbidden names ``path`` imports, and forbidden dtwin names of any module it reaches.

    Beyond the file itself only dtwin modules count: a third-party import deeper down may be
    lazy (``scipy.signal`` on first use), which tests/workflow/test_import_budget.py measures at
    run time.
    """
    return sorted(
        f"{name} (in {found.relative_to(REPO).as_posix()})"
        for found in {path, *reached(path)}
        for name in imported_modules(found)
        for prefix in FORBIDDEN[layer]
        if (found == path or prefix.startswith("dtwin."))
        and (name == prefix or name.startswith(prefix + "."))
        and not any(name.startswith(ok) for ok in ALLOWED.get(layer, ()))
    )


@pytest.mark.parametrize("path", LIBRARY_FILES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_each_layer_imports_only_what_it_may(path):
    layer = layer_of(path)
    if layer is None:
        return
    bad = _forbidden_imports(path, layer)
    assert not bad, f"{layer} module reaches {bad}"


#: What the twin package may import besides the standard library: itself and the root helpers
#: (``dtwin._lazy`` runs with ``dtwin/__init__.py``), numpy, scipy, numba and fmpy.
TWIN_DTWIN_IMPORTS = (
    "dtwin.twin",
    "dtwin._validation",
    "dtwin._jit",
    "dtwin._lfilter",
    "dtwin._lazy",
)
TWIN_PACKAGES = {"numpy", "scipy", "numba", "fmpy"}


@pytest.mark.parametrize(
    "path", sorted((LIBRARY / "twin").rglob("*.py")), ids=lambda p: p.relative_to(REPO).as_posix()
)
def test_the_twin_package_imports_only_itself_the_helpers_and_numerics(path):
    """The bottom layer: no paper concept (params, command, physics), no pandas, no yaml."""
    outside = sorted(
        f"{name} (in {found.relative_to(REPO).as_posix()})"
        for found in {path, *reached(path)}
        for name in imported_modules(found)
        if name.partition(".")[0] == "dtwin"
        and not any(name == ok or name.startswith(ok + ".") for ok in TWIN_DTWIN_IMPORTS)
    )
    third_party = sorted(
        name
        for name in imported_modules(path)
        if name.partition(".")[0] not in {"dtwin", *TWIN_PACKAGES, *sys.stdlib_module_names}
    )
    assert outside == [] and third_party == []


def _names_something(dotted: str) -> bool:
    """Whether a dotted dtwin name is a module of the library or a top-level name defined in one."""
    *parents, last = dotted.split(".")
    stem = REPO.joinpath(*parents, last)
    if stem.with_suffix(".py").is_file() or (stem / "__init__.py").is_file():
        return True
    owner = module_files(".".join(parents))
    pattern = rf"^(def|class) {last}\b|^{last}\s*[:=]"
    return bool(owner) and re.search(pattern, owner[-1].read_text(), re.M) is not None


def test_every_forbidden_dtwin_name_exists():
    """A rule against a module that no longer exists checks nothing."""
    stale = sorted(
        prefix
        for prefixes in (*FORBIDDEN.values(), *ALLOWED.values())
        for prefix in prefixes
        if prefix.startswith("dtwin.") and not _names_something(prefix)
    )
    assert stale == []


def _compute_scripts() -> list[Path]:
    """Scripts of the rules that publish no artifact (and are not the report's ``claims``)."""
    listed = yaml.safe_load((REPO / "workflow" / "artifacts.yaml").read_text())
    publishing = {name for names in listed.values() for name in names} | {"claims"}
    return [p for p in sorted((REPO / "scripts").glob("*.py")) if p.stem not in publishing]


@pytest.mark.parametrize("script", _compute_scripts(), ids=lambda p: p.stem)
def test_compute_rules_never_import_figure_modules(script):
    figures = sorted(
        p.relative_to(REPO).as_posix()
        for p in reached(script)
        if p.is_relative_to(LIBRARY / "figures") and p.name not in SHARED_STYLE
    )
    assert figures == [], f"{script.name} reaches {figures}"


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
        if "REFERENCE.md" in path.read_text()
    ]
    assert cited == []


#: An issue number (the word issue, then a number) or a date: history, not specification.
ISSUE_NUMBER = r"\bissues? #?\d+"
HISTORY = re.compile(ISSUE_NUMBER + r"|\b20\d\d-\d\d-\d\d\b", re.IGNORECASE)
#: Every file of code: the library, scripts, workflow, tests, benchmarks and configuration.
CODE_FILES = [
    REPO / "Snakefile",
    *sorted(
        path
        for folder in ("dtwin", "scripts", "workflow", "tests", "benchmarks", "config")
        for path in (REPO / folder).rglob("*")
        if path.suffix in (".py", ".smk", ".yaml", ".json") and path.is_file()
    ),
]


def test_the_library_carries_no_issue_numbers_or_dated_measurements():
    found = [
        f"{path.relative_to(REPO).as_posix()}:{number}: {match.group(0)}"
        for path in LIBRARY_FILES
        for number, line in enumerate(path.read_text().splitlines(), 1)
        for match in [HISTORY.search(line)]
        if match
    ]
    assert found == []


def test_no_code_cites_an_issue_number():
    """Scripts, rules, tests and configuration say what they do, not which issue asked."""
    pattern = re.compile(ISSUE_NUMBER, re.IGNORECASE)
    found = [
        f"{path.relative_to(REPO).as_posix()}:{number}: {match.group(0)}"
        for path in CODE_FILES
        for number, line in enumerate(path.read_text().splitlines(), 1)
        for match in [pattern.search(line)]
        if match
    ]
    assert found == []


#: Packages whose code treats modules by their role (dtwin.twin.wiring.ROLES), never by their name.
ROLE_DISPATCHED = ("gap", "gapbench")
MODULE_NAME = re.compile(r"^M\d[a-z]?$")


def _names_a_module(node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and bool(MODULE_NAME.match(node.value))
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return any(_names_a_module(element) for element in node.elts)
    return False


def test_no_code_compares_with_a_module_name():
    """``name == "M1"`` hides the plant behind a label: ask the wiring table for the role."""
    found = [
        f"{path.relative_to(REPO).as_posix()}:{node.lineno}"
        for package in ROLE_DISPATCHED
        for path in sorted((LIBRARY / package).rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Compare)
        and any(_names_a_module(side) for side in (node.left, *node.comparators))
    ]
    assert found == []
