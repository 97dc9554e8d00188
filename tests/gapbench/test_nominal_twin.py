"""The paper's twin has one source, config/config.yaml: the generator takes it as an argument.

The rule ``gap_cases`` passes config ``twin`` (its ``params:``), ``dtwin generate`` reads
``--twin`` (default config/config.yaml) and the tests read the config (tests/conftest.py).
"""

from __future__ import annotations

import ast
import inspect

import pytest

from dtwin._validation import DtwinValueError
from dtwin.gapbench.generator import NOMINAL_KEYS, generate_case
from tests.conftest import REPO, paper_twin

#: A mapping literal naming this many of the twin's module sections is a copy of the twin.
SECTIONS = {"actuator", "plant", "sensor_A", "sensor_B", "fusion", "kpi"}
COPY_AT = 3


def _twin_literals(path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Dict):
            keys = {k.value for k in node.keys if isinstance(k, ast.Constant)}
            if len(keys & SECTIONS) >= COPY_AT:
                found.append(f"{path.relative_to(REPO).as_posix()}:{node.lineno}")
    return found


def test_no_code_copies_the_twin():
    """A twin written out in code drifts from config/config.yaml: read the config instead."""
    files = [
        p
        for folder in ("dtwin", "scripts", "tests", "benchmarks")
        for p in (REPO / folder).rglob("*.py")
    ]
    assert [place for path in sorted(files) for place in _twin_literals(path)] == []


def test_the_generator_has_no_twin_of_its_own():
    assert inspect.signature(generate_case).parameters["nominal"].default is inspect.Parameter.empty


def test_the_generator_reads_the_twin_it_is_given_and_names_what_is_missing():
    twin = paper_twin()
    case = generate_case("none", 1, n_samples=300, nominal=twin)
    assert list(case.twin["twin"]) == [*NOMINAL_KEYS, "discretisation"]
    assert {k: case.twin["twin"][k] for k in NOMINAL_KEYS if k != "noise"} == {
        k: twin[k] for k in NOMINAL_KEYS if k != "noise"
    }
    del twin["kpi"]
    with pytest.raises(DtwinValueError, match="kpi"):
        generate_case("none", 1, n_samples=300, nominal=twin)
