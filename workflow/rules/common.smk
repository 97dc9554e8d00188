"""Helpers shared by the stage files (config validation, library inputs, target lists)."""

import ast
import functools
import os

import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

CONFIG_SCHEMA = os.path.join(workflow.basedir, "workflow", "schemas", "config.schema.yaml")


def config_errors(config, schema_path):
    """Every schema violation as 'key.path: message' (Snakemake's validate shows only one)."""
    with open(schema_path) as handle:
        schema = yaml.safe_load(handle)
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    return [
        f"{'.'.join(str(p) for p in e.absolute_path) or '<top level>'}: {e.message}"
        for e in errors
    ]


try:
    validate(config, CONFIG_SCHEMA)
except WorkflowError as error:
    problems = "\n  ".join(config_errors(config, CONFIG_SCHEMA)) or str(error)
    raise WorkflowError(f"invalid configuration:\n  {problems}") from None


REFERENCE_DIR = "config/reference"
FIGURE_FORMATS = ("png", "pdf")


@functools.lru_cache(maxsize=None)
def _direct_dtwin_imports(path):
    """Files of the dtwin modules that ``path`` imports directly (package __init__s included)."""
    with open(os.path.join(workflow.basedir, path)) as handle:
        tree = ast.parse(handle.read(), filename=path)
    found = []
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            parts = name.split(".")
            if parts[0] != "dtwin":
                continue
            for depth in range(1, len(parts) + 1):
                stem = os.path.join(*parts[:depth])
                for candidate in (f"{stem}.py", os.path.join(stem, "__init__.py")):
                    if os.path.exists(os.path.join(workflow.basedir, candidate)):
                        found.append(candidate)
    return tuple(found)


def dtwin_sources(script):
    """The dtwin library files a script imports, transitively, as rule inputs.

    Snakemake does not track imports, so without this an edit to dtwin/hmm.py would rerun
    nothing. Imports are read from the source (ast), including ones inside functions, and
    every package __init__.py on the way is added because it runs on import. Each file is
    parsed once per Snakemake run (cached).
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


with open(os.path.join(workflow.basedir, "workflow", "artifacts.yaml")) as _handle:
    ARTIFACTS = yaml.safe_load(_handle)
PAPER_ARTIFACTS = ARTIFACTS["paper"]

GAP_CASES = [
    f"{effect}_{number:02d}"
    for effect in config["gap"]["benchmark"]["effects"]
    for number in range(config["gap"]["benchmark"]["cases_per_effect"])
]

ALL_TARGETS = [
    *(path for artifact in PAPER_ARTIFACTS for path in figure_outputs(artifact)),
    *(path for artifact in ARTIFACTS["project"] for path in figure_outputs(artifact)),
    "paper_figures/CLAIMS.md",
    "paper_figures/claims.json",
]


# --- the sensitivity sweep (paper §5, Fig. 11): one job per configuration and replicate ------

SWEEP_POINT = "alpha{alpha}_mA{ma}_mB{mb}_rep{rep}"


wildcard_constraints:
    alpha=r"[0-9.eE+-]+",
    ma=r"[0-9.eE+-]+",
    mb=r"[0-9.eE+-]+",
    rep=r"[0-9]+",
    chunk=r"[0-9]+",


def sweep_value(value):
    """A grid value as it appears in file names: repr of the float, which round-trips exactly."""
    return repr(float(value))


def sensitivity_run_files(sensitivity):
    """The result file of every (alpha, m_A, m_B, replicate) of the configured grid."""
    return expand(
        f"results/sensitivity/{SWEEP_POINT}.json",
        alpha=[sweep_value(v) for v in sensitivity["alphas"]],
        ma=[sweep_value(v) for v in sensitivity["sensor_A_mults"]],
        mb=[sweep_value(v) for v in sensitivity["sensor_B_mults"]],
        rep=range(sensitivity["n_replicates"]),
    )


def sweep_point_of(wildcards):
    """The grid point of one sweep job, from its wildcards (params of sweep_point)."""
    return {
        "alpha": float(wildcards.alpha),
        "m_A": float(wildcards.ma),
        "m_B": float(wildcards.mb),
        "replicate": int(wildcards.rep),
    }


# What one sweep job depends on: not the grid lists (adding an alpha must not rerun the others),
# not correction.method or interval (they only choose what the figure shows).
SENSITIVITY_JOB_PARAMS = {
    "seed": config["sensitivity"]["seed"],
    "hmm": config["sensitivity"]["hmm"],
    "correction": {m: config["sensitivity"]["correction"][m] for m in ("code", "paper")},
    "r_signals": config["sensitivity"]["r_signals"],
}


# --- claims across random draws (issue 12, Fig. 12): one job per chunk of draws ----------------


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


# What a draw depends on: every section of the single-draw run (not n_draws: adding draws must
# not rerun the chunks that exist).
DRAW_SECTIONS = {
    key: config[key]
    for key in ("simulation", "command", "twin", "arx", "faults", "hmm", "correction", "mcda")
}
DRAW_ACF = {k: config["acf"][k] for k in ("ljungbox_lags", "significance", "strong_lag1")}
