"""Shared fixtures: the repository root, the default config and its twin parameters.

Also the Hypothesis profiles. ``ci`` (the default) is derandomized: every run of `make test`
tries the same examples, so CI cannot go red by chance; failures ever found are pinned as
``@example`` on the test. ``fuzz`` (``make fuzz``, or ``HYPOTHESIS_PROFILE=fuzz``) draws fresh
random examples, ``FUZZ_FACTOR`` times as many, for exploration.

And the order of a parallel run: `make test` runs on two pytest-xdist workers (``-n 2``,
``--dist loadfile``: the tests of one file run on one worker, in file order, so the tests that
share a module fixture such as tests/workflow/test_workflow.py's ``workflow_copy`` see it built once
and changed in turn); the files go out in the order of their first test, and
:func:`pytest_collection_modifyitems` puts the longest file first, then the other slow tests.
"""

# ruff: noqa: E402 (the thread variables below are set before the imports that load numpy)

from __future__ import annotations

import os

# One BLAS thread per test process, set before numpy loads OpenBLAS (and inherited by the
# subprocesses the tests start), as a Snakemake job with ``threads: 1`` and the diagnoser
# (``threadpool_limits(1)``) run. Two xdist workers on two cores with two OpenBLAS threads
# each spin on each other: the whitened-ratio test of tests/gap/test_gap_nested.py took
# 20.5 CPU s with two threads and 2.3 with one. Set the variable to override.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import copy
from functools import cache
from pathlib import Path

import pandas as pd
import pytest
import yaml
from hypothesis import settings

from dtwin.params import twin_params_from_mapping

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("fuzz", derandomize=False, database=None, print_blob=True)
HYPOTHESIS_PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
settings.load_profile(HYPOTHESIS_PROFILE)

#: How many more examples each property test draws under the ``fuzz`` profile.
FUZZ_FACTOR = 25


def n_examples(in_ci: int) -> int:
    """Return a property test's example budget: ``in_ci`` in CI, ``FUZZ_FACTOR``× under fuzz."""
    return in_ci * FUZZ_FACTOR if HYPOTHESIS_PROFILE == "fuzz" else in_ci


#: The fixture of the suite's longest file (tests/workflow/test_workflow.py: a complete
#: Snakemake run, then about 250 CPU s of tests on it), which a parallel run starts first.
LONGEST_FIXTURE = "workflow_copy"


def _start_rank(item: pytest.Item) -> int:
    """0 for the tests on the longest file's fixture, 1 for other slow tests, 2 for the rest."""
    if LONGEST_FIXTURE in item.fixturenames:
        return 0
    return 1 if item.get_closest_marker("slow") else 2


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Longest file first, then the other slow tests, so no long test ends a parallel run alone.

    The sort is stable: tests keep their file order within each rank.
    """
    items.sort(key=_start_rank)


REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO / "config" / "reference"


@cache
def _read_config() -> dict:
    return yaml.safe_load((REPO / "config" / "config.yaml").read_text())


def read_config() -> dict:
    """A fresh copy of config/config.yaml, the one source of the paper's numbers in the tests."""
    return copy.deepcopy(_read_config())


def paper_twin() -> dict:
    """config/config.yaml's ``twin:`` section: the paper's twin, the generator's nominal twin."""
    return read_config()["twin"]


@pytest.fixture(scope="session")
def config() -> dict:
    """The default config/config.yaml."""
    return read_config()


@pytest.fixture(scope="session")
def twin(config):
    """The default twin parameters."""
    return twin_params_from_mapping(config["twin"])


@pytest.fixture(scope="session")
def r_pipeline() -> pd.DataFrame:
    """The authors' seed-11 fault-scenario signals (config/reference, r_notes.md §13)."""
    return pd.read_csv(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
