"""Rule = script = library function: rule ``X`` runs ``scripts/X.py``, which calls a dtwin
function named ``X`` (docs/architecture.md §Names). The scripts listed in ``PENDING`` do not yet;
the list may only shrink."""

from __future__ import annotations

import ast
import re

from tests.conftest import REPO

SCRIPTS = sorted((REPO / "scripts").glob("*.py"))

#: Scripts whose rule calls a library function of another name (the stage function's name
#: predates the rule's): shrink this, never grow it.
PENDING = {
    "ar_hmm_sweep",
    "bic_draws",
    "claims",
    "claims_draws",
    "fault_regimes",
    "fit_surrogates",
    "gap_cases",
    "gap_diagnoses",
    "mcda_actions",
    "nominal_regimes",
    "residuals",
    "simulate",
    "sweep_chunk",
}


def _called_dtwin_names(path) -> set[str]:
    """Names imported from dtwin by a script and called in it."""
    tree = ast.parse(path.read_text())
    imported = {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("dtwin")
        for alias in node.names
    }
    called = {
        node.func.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    }
    return imported & called


def test_every_script_is_a_rule():
    rules = set()
    for smk in (REPO / "workflow" / "rules").glob("*.smk"):
        rules |= set(re.findall(r"^rule (\w+):", smk.read_text(), flags=re.MULTILINE))
    assert {path.stem for path in SCRIPTS} <= rules


def test_each_script_calls_the_library_function_of_its_rule():
    mismatched = {p.stem for p in SCRIPTS if p.stem not in _called_dtwin_names(p)}
    assert mismatched - PENDING == set(), "rule = script = library function"
    assert PENDING - mismatched == set(), "now matching: remove from PENDING"
