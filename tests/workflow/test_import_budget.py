"""Import budgets of the rules' scripts: a light rule does not load the heavy libraries.

Each Snakemake job is a fresh Python process, so what a script imports is paid once per job
(cold: scikit-learn + hmmlearn ~1.8 s, scipy.signal ~1.5 s, statsmodels ~1 s, matplotlib.pyplot
~0.9 s). The budget is a set of modules, not seconds: the script's top-level imports run in a
fresh interpreter (forked after loading :data:`PRELOADED`, which every script loads) and
``sys.modules`` must not hold any module the budget forbids.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

#: Modules no figure needs: EM engines and signal processing belong to the stage rules.
MODEL_FITTING = ("sklearn", "hmmlearn", "numba", "scipy.signal", "statsmodels")
#: hmmlearn and scikit-learn: the reference EM engine, which no rule loads by default.
REFERENCE_ENGINE = ("sklearn", "hmmlearn")
#: Plotting, which a table rule never needs.
PLOTTING = ("matplotlib",)

#: script -> modules it must not load (representative figure, table, sweep and gap rules).
BUDGETS = {
    "bic_sweep": (*MODEL_FITTING, "dtwin.hmm", "scipy", *PLOTTING),  # joins two tables
    "claims": (*MODEL_FITTING, "scipy.stats"),
    "fig01_pipeline": (*MODEL_FITTING, "scipy.stats"),
    "fig03_residual_acf": (*MODEL_FITTING, "scipy.stats"),
    "fig06_correction_distributions": (*MODEL_FITTING, "scipy.stats"),
    "fig07_fault_posteriors": (*MODEL_FITTING, "scipy.stats"),
    "fig08_feature_separability": (*MODEL_FITTING, "scipy.stats", "scipy.linalg"),
    "fig09_bic": (*MODEL_FITTING, "scipy.stats"),
    "fig11_sensitivity": (*MODEL_FITTING, "scipy"),
    "fit_surrogates": (*MODEL_FITTING, "scipy.stats", *PLOTTING),
    "mcda_actions": (*MODEL_FITTING, *PLOTTING, "scipy"),
    "residuals": (*MODEL_FITTING, "scipy.stats", *PLOTTING),
    "simulate": (*MODEL_FITTING, "scipy.stats", *PLOTTING),
    "sweep_chunk": ("sklearn", "hmmlearn", "statsmodels", *PLOTTING),
    "targeted_intervention": (*MODEL_FITTING, "scipy.stats", *PLOTTING),
    # the HMM jobs: the compiled engine, no hmmlearn or scikit-learn (hmmlearn only if it falls
    # back or hmm.engine says so, imported then)
    "ar_hmm_sweep": (*REFERENCE_ENGINE, "statsmodels", "scipy.stats", *PLOTTING),
    "bic_draws": (*REFERENCE_ENGINE, "statsmodels", *PLOTTING),
    "bic_sweep_dataset": (*REFERENCE_ENGINE, "statsmodels", "scipy.stats", *PLOTTING),
    "fault_regimes": (*REFERENCE_ENGINE, "statsmodels", "scipy.stats", *PLOTTING),
    "nominal_regimes": (*REFERENCE_ENGINE, "statsmodels", "scipy.stats", *PLOTTING),
    "gap_cases": ("sklearn", "hmmlearn", "statsmodels", *PLOTTING),
}
#: fig09's imports plus the HMM fitting's engines (compiled and hmmlearn, the reference): what
#: the meta-test adds to a light script.
HEAVIER_FIG09 = "\nfrom dtwin.hmm import fit_hmm\nimport dtwin._em_kernels, dtwin._em_reference\n"


def top_level_imports(source: str) -> str:
    """The import statements at the top level of a script, as code to run elsewhere."""
    tree = ast.parse(source)
    return "\n".join(
        ast.unparse(node) for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))
    )


#: What every budgeted script loads and no budget forbids: numpy, pandas, dtwin's start-up and
#: writers. One fresh interpreter loads them once and forks a child per script, which runs the
#: script's imports and reports ``sys.modules`` (each child is a fresh interpreter that had
#: loaded these first; test_the_shared_start_loads_nothing_a_budget_forbids checks the premise).
PRELOADED = ("numpy", "pandas", "dtwin._script", "dtwin.artifacts")

#: Groups of scripts that all load a heavier module, which a group's start (a child of the
#: shared start) loads once before forking the group's scripts: a preloaded module can only add
#: to ``sys.modules``, so it cannot hide a forbidden import, and
#: test_each_group_start_loads_nothing_its_scripts_forbid checks that it adds nothing forbidden.
#: Saves each figure script its matplotlib and each Hungarian mapping its scipy.optimize.
GROUPS = {
    "dtwin.figures._style": tuple(
        name for name in (*BUDGETS, "fig09_bic+fit_hmm") if name.startswith("fig")
    ),
    "dtwin.regime_matching": ("ar_hmm_sweep", "bic_draws", "fault_regimes"),
}

#: ``python -c`` code: argv = an output folder and the modules to preload; stdin = ``[[group
#: module, {name: code}], ...]`` (group module ``""``: fork from the shared start); stdout =
#: ``{name: sorted modules}``, with ``""`` for the shared start and each group module for its
#: group's start.
FORK_PER_SCRIPT = """
import json, os, sys
folder, preload = sys.argv[1], sys.argv[2:]


def record(name):
    with open(os.path.join(folder, name + ".json"), "w") as out:
        json.dump(sorted(sys.modules), out)


def run_child(body):
    pid = os.fork()
    if pid == 0:
        status = 1
        try:
            body()
            status = 0
        finally:
            sys.stderr.flush()
            os._exit(status)
    return pid


def fork_scripts(codes):
    def script(name, code):
        exec(compile(code, name, "exec"), {"__name__": "__budget__"})
        record(name)

    children = {name: run_child(lambda: script(name, code)) for name, code in codes.items()}
    return [name for name, pid in children.items() if os.waitpid(pid, 0)[1] != 0]


def group(module, codes):
    __import__(module)
    record(module)
    failed = fork_scripts(codes)
    if failed:
        print(f"imports failed: {failed}", file=sys.stderr)
        raise SystemExit(1)


for module in preload:
    __import__(module)
record("")
groups = json.loads(sys.stdin.read())
starts = {m: run_child(lambda: group(m, codes)) for m, codes in groups if m}
failed = [name for m, codes in groups if not m for name in fork_scripts(codes)]
failed += [m for m, pid in starts.items() if os.waitpid(pid, 0)[1] != 0]
if failed:
    sys.exit(f"imports failed: {failed}")
names = [""] + [m for m, _ in groups if m] + [name for _, codes in groups for name in codes]
print(json.dumps({name: json.load(open(os.path.join(folder, name + ".json"))) for name in names}))
"""


def run_python(*args: str, stdin: str | None = None) -> str:
    """Stdout of a fresh interpreter run with ``args`` in the repository (Agg backend);
    fails the test with its stderr if it exits non-zero."""
    done = subprocess.run(
        [sys.executable, *args],
        input=stdin,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def modules_loaded(sources: dict[str, str], folder: Path) -> dict[str, set[str]]:
    """The modules loaded by each source's top-level imports (key ``""``: the shared start;
    each :data:`GROUPS` module: its group's start)."""
    codes = {name: top_level_imports(source) for name, source in sources.items()}
    grouped = {name for names in GROUPS.values() for name in names}
    groups = [["", {n: c for n, c in codes.items() if n not in grouped}]]
    groups += [
        [module, {n: codes[n] for n in names if n in codes}] for module, names in GROUPS.items()
    ]
    stdout = run_python("-c", FORK_PER_SCRIPT, str(folder), *PRELOADED, stdin=json.dumps(groups))
    return {name: set(modules) for name, modules in json.loads(stdout).items()}


@pytest.fixture(scope="module")
def loaded(tmp_path_factory) -> dict[str, set[str]]:
    """Modules loaded by each budgeted script (and fig09 made heavier), run side by side."""
    sources = {name: (REPO / "scripts" / f"{name}.py").read_text() for name in BUDGETS}
    sources["fig09_bic+fit_hmm"] = sources["fig09_bic"] + HEAVIER_FIG09
    return modules_loaded(sources, tmp_path_factory.mktemp("budgets"))


def over_budget(modules: set[str], forbidden: tuple[str, ...]) -> list[str]:
    """The forbidden packages (or sub-packages) found among ``modules``."""
    return sorted(
        name for name in forbidden if any(m == name or m.startswith(f"{name}.") for m in modules)
    )


@pytest.mark.parametrize("script", sorted(BUDGETS))
def test_script_stays_within_its_import_budget(loaded, script):
    assert not over_budget(loaded[script], BUDGETS[script])


def test_a_heavy_import_added_to_a_light_script_breaks_its_budget(loaded):
    """The check sees a heavy import however deep: here scikit-learn through hmmlearn."""
    assert over_budget(loaded["fig09_bic+fit_hmm"], BUDGETS["fig09_bic"]) == [
        "hmmlearn",
        "numba",
        "scipy.stats",
        "sklearn",
    ]


def test_the_shared_start_loads_nothing_a_budget_forbids(loaded):
    every_forbidden = tuple({name for names in BUDGETS.values() for name in names})
    assert {"numpy", "pandas"} <= loaded[""]
    assert not over_budget(loaded[""], every_forbidden)


@pytest.mark.parametrize("module", sorted(GROUPS))
def test_each_group_start_loads_nothing_its_scripts_forbid(loaded, module):
    for script in GROUPS[module]:
        forbidden = BUDGETS[script.partition("+")[0]]
        assert not over_budget(loaded[module], forbidden), (module, script)


def test_every_budgeted_script_exists():
    missing = [name for name in BUDGETS if not (REPO / "scripts" / f"{name}.py").exists()]
    assert not missing


def test_the_pipeline_diagram_loads_no_pandas():
    """Fig. 1 reads no table: its job, and the artifact writers every job loads, skip pandas
    (~0.3 CPU-s a process). Checked in a fresh interpreter, as the forked children above
    start with pandas loaded."""
    code = top_level_imports((REPO / "scripts" / "fig01_pipeline.py").read_text())
    probe = "\nimport sys\nprint('pandas' in sys.modules)"
    assert run_python("-c", code + probe).split() == ["False"]
