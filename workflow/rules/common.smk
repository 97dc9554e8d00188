"""Helpers shared by the stage files (config validation, library inputs, target lists)."""

import functools
import os
import re
import sys

import jsonschema
import yaml
from snakemake.exceptions import WorkflowError

CONFIG_SCHEMA = os.path.join(workflow.basedir, "workflow", "schemas", "config.schema.yaml")
# libyaml's loader when PyYAML has it (7x faster on the schema; the same documents).
YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml(path):
    """The YAML document at ``path`` (safe loading)."""
    with open(path) as handle:
        return yaml.load(handle, Loader=YAML_LOADER)


def config_errors(config, schema_path):
    """Every schema violation as 'key.path: message' (Snakemake's validate shows only one).

    The schema sets no defaults, so plain jsonschema validation is all Snakemake's validate
    would do here (without building its reference registry on every start).
    """
    validator = jsonschema.Draft202012Validator(load_yaml(schema_path))
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    return [
        f"{'.'.join(str(p) for p in e.absolute_path) or '<top level>'}: {e.message}"
        for e in errors
    ]


_CONFIG_PROBLEMS = config_errors(config, CONFIG_SCHEMA)
if _CONFIG_PROBLEMS:
    raise WorkflowError("invalid configuration:\n  " + "\n  ".join(_CONFIG_PROBLEMS))


REFERENCE_DIR = "config/reference"

# Scheduling on two cores: Snakemake starts the ready job of highest priority first. The chain
# to the BIC sweeps (simulate -> ... -> bic_sweep_dataset -> fig09) is the paper DAG's critical
# path, so it never waits behind a figure or a sweep chunk; in `make figures` the draws' jobs
# (the longest, ready at once: they read only the config) start first, the longest first rule.
# Within the chain, the longer remaining path goes first: bic_r_signals of the fault features
# (ready at once) takes one core while the other runs simulate -> fit_surrogates -> residuals ->
# nominal_regimes (short) -> fault_regimes -> the fault features' BIC sweep (the longest sweep);
# the nominal residuals' sweeps (on R's signals and on ours) then run on the core the first frees,
# instead of holding up the fault chain.
PRIORITY_CRITICAL_PATH = 10
PRIORITY_TWIN = PRIORITY_CRITICAL_PATH + 3  # simulate, fit_surrogates, residuals, nominal_regimes
PRIORITY_FAULT_FIT = PRIORITY_CRITICAL_PATH + 2  # fault_regimes
PRIORITY_DRAWS = 20
# Off the critical path, the sweep's chunks (the longest jobs left, a few CPU-s each) start before
# the figures and the small table jobs, so those short jobs are what evens out the two cores at
# the end of the run.
PRIORITY_SWEEP = 1


def bic_sweep_priority(wildcards):
    """Priority of a data set's BIC sweep (ours or on R's signals): the fault features' first."""
    return PRIORITY_CRITICAL_PATH + (wildcards.dataset == "fault_features")

FIGURE_FORMATS = ("png", "pdf")


# `from dtwin.x import a, b` (also parenthesised over several lines) and `import dtwin.x`, at any
# indentation (imports inside functions count). A regular expression, not ast.parse: the scan
# runs on every Snakemake start, and parsing ~100 files cost ~0.8 s of a 3 s no-op run.
_FROM_IMPORT = re.compile(r"^[ \t]*from[ \t]+(dtwin[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)", re.M)
_PLAIN_IMPORT = re.compile(r"^[ \t]*import[ \t]+(dtwin[\w.]*(?:[ \t]*,[ \t]*[\w.]+)*)", re.M)


def _imported_names(source):
    """Dotted names of the dtwin modules (and imported members) a source file imports."""
    names = []
    for module, members in _FROM_IMPORT.findall(source):
        members = re.sub(r"#[^\n]*", "", members).strip("() \t\n")
        names.append(module)
        names += [f"{module}.{m.split()[0]}" for m in members.split(",") if m.strip()]
    for group in _PLAIN_IMPORT.findall(source):
        names += [name.split()[0] for name in group.split(",") if name.strip()]
    return names


@functools.lru_cache(maxsize=None)
def _library_files():
    """The .py files under dtwin/, relative to the workflow's folder: listed once per run, so
    the candidates below are set lookups (one stat each cost ~9,000 stats a start)."""
    base = workflow.basedir
    found = set()
    for root, folders, files in os.walk(os.path.join(base, "dtwin")):
        folders[:] = [folder for folder in folders if folder != "__pycache__"]
        paths = (os.path.join(root, name) for name in files if name.endswith(".py"))
        found.update(os.path.relpath(path, base) for path in paths)
    return frozenset(found)


@functools.lru_cache(maxsize=None)
def _direct_dtwin_imports(path):
    """Files of the dtwin modules that ``path`` imports directly (package __init__s included)."""
    with open(os.path.join(workflow.basedir, path)) as handle:
        source = handle.read()
    library = _library_files()
    found = []
    for name in _imported_names(source):
        parts = name.split(".")
        if parts[0] != "dtwin":
            continue
        for depth in range(1, len(parts) + 1):
            stem = os.path.join(*parts[:depth])
            for candidate in (f"{stem}.py", os.path.join(stem, "__init__.py")):
                if candidate in library:
                    found.append(candidate)
    return tuple(found)


def dtwin_sources(script):
    """The dtwin library files a script imports, transitively, as rule inputs.

    Snakemake does not track imports, so without this an edit to dtwin/hmm.py would rerun
    nothing. Imports are read from the source (the regular expressions above), including ones
    inside functions, and every package __init__.py on the way is added because it runs on
    import. Each file is read once per Snakemake run (cached).
    """
    seen, pending = set(), [script]
    while pending:
        for candidate in _direct_dtwin_imports(pending.pop()):
            if candidate not in seen:
                seen.add(candidate)
                pending.append(candidate)
    return sorted(seen)


def figure_outputs(artifact):
    """The PNG, PDF and JSON of one paper artifact."""
    return [f"paper_figures/{artifact}.{ext}" for ext in (*FIGURE_FORMATS, "json")]


ARTIFACTS = load_yaml(os.path.join(workflow.basedir, "workflow", "artifacts.yaml"))
PAPER_ARTIFACTS = ARTIFACTS["paper"]


ALL_TARGETS = [
    *(path for artifact in PAPER_ARTIFACTS for path in figure_outputs(artifact)),
    *(path for artifact in ARTIFACTS["project"] for path in figure_outputs(artifact)),
    "paper_figures/CLAIMS.md",
    "paper_figures/claims.json",
]


# --- batches: the sweep and the gap benchmark run as chunks (Snakemake scattergather) ---------
# One job per chunk pays the interpreter start-up (~1.2 CPU-s of imports) once for many items.
# `--set-scatter sweep=N gap=N` sets the number of chunks (at most one per item; 0 = one item
# per chunk, as profiles/slurm does). Chunk i-of-n holds the i-th of n contiguous, near-equal
# slices of the item list; every item runs from its own seed, so outputs do not depend on n.
# Two sweep chunks: one per core of the default profile (PRIORITY_SWEEP starts them early).


scattergather:
    sweep=2,
    gap=4,


def chunk_names(name, n_items):
    """The scatter items ("1-of-n" …) of process ``name`` for ``n_items`` items."""
    requested = len(getattr(scatter, name)("{scatteritem}"))
    n = n_items if requested == 0 else min(requested, n_items)
    return [f"{i}-of-{n}" for i in range(1, n + 1)]


def chunk_of(items, scatteritem):
    """The items of chunk ``scatteritem`` ("i-of-n"): the i-th of n contiguous slices."""
    index, n = (int(part) for part in scatteritem.split("-of-"))
    return items[(index - 1) * len(items) // n : index * len(items) // n]


# --- the sensitivity sweep (paper §5, Fig. 11): chunks of (alpha, m_A, m_B, replicate) points --


def sweep_points(sensitivity):
    """Every grid point as a dict, in dtwin.sensitivity_sweep.sweep_grid order (α fastest)."""
    return [
        {"alpha": float(alpha), "m_A": float(m_a), "m_B": float(m_b), "replicate": rep}
        for rep in range(sensitivity["n_replicates"])
        for m_b in sensitivity["sensor_B_mults"]
        for m_a in sensitivity["sensor_A_mults"]
        for alpha in sensitivity["alphas"]
    ]


SWEEP_POINTS = sweep_points(config["sensitivity"])


def sweep_chunk_files():
    """The result file of every chunk of the configured grid."""
    return expand(
        "results/sensitivity/chunks/{scatteritem}.json",
        scatteritem=chunk_names("sweep", len(SWEEP_POINTS)),
    )


def points_of_chunk(wildcards):
    """The grid points of one sweep chunk (params of sweep_chunk)."""
    return chunk_of(SWEEP_POINTS, wildcards.scatteritem)


def sweep_chunk_runtime(wildcards):
    """Minutes a sweep chunk may take: 5 per point (one point takes ~2 s)."""
    return 5 * len(points_of_chunk(wildcards))


# What a sweep point depends on besides its own values: not correction.method or interval (they
# only choose what the figure shows).
SENSITIVITY_JOB_PARAMS = {
    "seed": config["sensitivity"]["seed"],
    "hmm": {**config["sensitivity"]["hmm"], "engine": config["hmm"]["engine"]},
    "correction": {m: config["sensitivity"]["correction"][m] for m in ("code", "paper")},
    "r_signals": config["sensitivity"]["r_signals"],
}


# --- the gap benchmark (docs/gap.md §Cases and rules): chunks of generated cases ---------------


def gap_cases_per_type(case_type):
    """Cases of one gap case type: ``cases_per_arm_effect`` for an arm's ``<arm>__<effect>``."""
    benchmark = config["gap"]["benchmark"]
    return benchmark["cases_per_arm_effect" if "__" in case_type else "cases_per_effect"]


GAP_CASES = [
    f"{effect}_{number:02d}"
    for effect in config["gap"]["benchmark"]["effects"]
    for number in range(gap_cases_per_type(effect))
]


def gap_chunks():
    """The scatter items of the gap benchmark's chunks."""
    return chunk_names("gap", len(GAP_CASES))


def gap_chunk_cases(scatteritem):
    """The case names of gap chunk ``scatteritem`` ("i-of-n"): every n-th case from the i-th.

    Dealt round robin, not in contiguous slices, so every chunk holds a like mix of case types
    (the harder rigs, last in the list, cost ~5x a paper-asset case: a slice of them was the
    last chunk to finish on two cores).
    """
    index, n = (int(part) for part in scatteritem.split("-of-"))
    return GAP_CASES[index - 1 :: n]


def gap_cases_of_chunk(wildcards):
    """The case names of one gap chunk (params of gap_cases and gap_diagnoses)."""
    return gap_chunk_cases(wildcards.scatteritem)


def gap_chunk_runtime(wildcards):
    """Minutes a gap chunk may take: 2 per case (one case takes seconds)."""
    return 2 * len(gap_cases_of_chunk(wildcards))


def gap_case_files(kind, name):
    """``results/gap/<kind>/<chunk>/<case>/<name>`` of every case, in GAP_CASES order."""
    chunk = {case: item for item in gap_chunks() for case in gap_chunk_cases(item)}
    return [f"results/gap/{kind}/{chunk[case]}/{case}/{name}" for case in GAP_CASES]


# --- claims across random draws (Fig. 12): one job per chunk of draws ----------------


wildcard_constraints:
    chunk=r"[0-9]+",


def draw_chunks(draws):
    """The chunk numbers of the configured draws (chunk c holds draws c*size … (c+1)*size − 1)."""
    return range(-(-draws["n_draws"] // draws["chunk_size"]))


def draw_chunk_files(draws):
    """The result file of every chunk of draws."""
    return expand("results/draws/chunk{chunk}.json", chunk=draw_chunks(draws))


def draws_of_chunk(wildcards):
    """The draw numbers of one chunk (params of claims_draws: a chunk reruns only if they change)."""
    size, n_draws = config["draws"]["chunk_size"], config["draws"]["n_draws"]
    first = int(wildcards.chunk) * size
    return list(range(first, min(first + size, n_draws)))


def bic_draw_count(draws):
    """The draws that get a BIC sweep: draws.bic.n_draws, at most draws.n_draws."""
    return min(draws["bic"]["n_draws"], draws["n_draws"])


def bic_draw_chunk_files(draws):
    """The result file of every chunk of BIC sweeps (K* across draws)."""
    size = draws["bic"]["chunk_size"]
    chunks = range(-(-bic_draw_count(draws) // size))
    return expand("results/draws/bic/chunk{chunk}.json", chunk=chunks)


def bic_draws_of_chunk(wildcards):
    """The draw numbers of one chunk of BIC sweeps (params of bic_draws)."""
    size = config["draws"]["bic"]["chunk_size"]
    first = int(wildcards.chunk) * size
    return list(range(first, min(first + size, bic_draw_count(config["draws"]))))


# What a draw depends on: every section of the single-draw run (not n_draws: adding draws must
# not rerun the chunks that exist). dtwin.stages.draws.REGIME_SECTIONS and DRAW_SECTIONS.
REGIME_SECTIONS = ("simulation", "command", "twin", "arx", "faults", "hmm")
DRAW_SECTIONS = {key: config[key] for key in (*REGIME_SECTIONS, "correction", "mcda")}
# What a draw's BIC sweep depends on: the draw up to its fault HMM (K* reads no correction or
# MCDA, so changing them reruns no sweep).
DRAW_REGIME_SECTIONS = {key: config[key] for key in REGIME_SECTIONS}
DRAW_ACF = {k: config["acf"][k] for k in ("ljungbox_lags", "significance", "strong_lag1")}
# A draw's BIC sweep: Fig. 9's K range and stopping rule with the per-draw EM starts.
DRAW_BIC = {
    **{k: config["bic"][k] for k in ("ks", "k_max", "stop_after_rises", "split_starts")},
    "n_restarts": config["draws"]["bic"]["n_restarts"],
    "max_restarts": config["draws"]["bic"]["max_restarts"],
}


# --- the warm job server (dtwin/_job_server.py) -------------------------------------------------
# Started when jobs are about to run on this machine: its process forks one child per job, so each
# job skips the interpreter's start-up (imports and the EM kernels' cache loads: 0.4-1.4 CPU-s a
# job). It imports what the run's scripts import one module at a time, in the order the jobs
# start, and forks the jobs that start meanwhile with what it has loaded by then.
# `--config job_server=False` turns it off; jobs on a cluster run in their own process as before.
# Besides the dtwin modules the scripts import: Snakemake's script preamble (first: every job
# runs it), and what matplotlib loads when a figure is saved.
JOB_SERVER_PREAMBLE = ("snakemake.script", "snakemake.logging", "snakemake.iocontainers")
JOB_SERVER_PRELOAD = (
    "matplotlib.backends.backend_agg",
    "matplotlib.backends.backend_pdf",
    "fontTools.subset",
)
# Not preloaded although a script names it: the hmmlearn reference engine (with scikit-learn),
# which a job imports only if hmm.engine asks for it or the compiled EM falls back.
JOB_SERVER_SKIP = ("dtwin._em_reference",)
# Modules whose warm_up() the server runs once after the imports: the EM kernels' and the force
# loop's cache loads, and a figure drawn in the set's style (matplotlib's fonts, mathtext parser
# and writers; dtwin.figures._style.warm_up).
JOB_SERVER_WARM_UP = ("dtwin._em_kernels", "dtwin.twin._force_kernels", "dtwin.figures._style")


def expected_start_order(jobs):
    """``jobs`` in the order Snakemake starts them on one core: the ready job of highest priority
    first (ties by rule name), a job ready once every job it depends on has run."""
    jobs = set(jobs)
    waiting = {job: set(workflow.dag.dependencies[job]) & jobs for job in jobs}
    order = []
    while waiting:
        ready = [job for job, deps in waiting.items() if not deps]
        job = min(ready, key=lambda job: (-job.priority, job.rule.name, str(job.wildcards)))
        order.append(job)
        del waiting[job]
        for deps in waiting.values():
            deps.discard(job)
    return order


def job_server_modules(jobs):
    """The dtwin modules the scripts of ``jobs`` import (dotted names), in the order the jobs
    need them (:func:`expected_start_order`; a script's new modules sorted by name)."""
    modules = {}
    for job in expected_start_order(jobs):
        if job.rule.script:
            script = os.path.join("scripts", os.path.basename(job.rule.script))
            for path in dtwin_sources(script):
                name = path[: -len(".py")].replace(os.sep, ".").removesuffix(".__init__")
                modules.setdefault(name, None)
    return [name for name in modules if name not in JOB_SERVER_SKIP]


def start_job_server():
    """Start the job server for the jobs this run will run (local runs only)."""
    if not config.get("job_server", True) or not workflow.local_exec:
        return
    from dtwin._job_server import start_server

    modules = job_server_modules(workflow.dag.needrun_jobs())
    if modules:
        warm_up = [name for name in JOB_SERVER_WARM_UP if name in modules]
        start_server([*JOB_SERVER_PREAMBLE, *modules, *JOB_SERVER_PRELOAD], warm_up)


def stop_job_server():
    """Stop the job server, if this run started one."""
    if "dtwin._job_server" in sys.modules:
        sys.modules["dtwin._job_server"].stop_server()


onstart:
    start_job_server()


onsuccess:
    stop_job_server()


onerror:
    stop_job_server()
