"""Shared fixtures: the repository root, the default config and its twin parameters.

Also the Hypothesis profiles. ``ci`` (the default) is derandomized: every run of `make test`
tries the same examples, so CI cannot go red by chance; failures ever found are pinned as
``@example`` on the test. ``fuzz`` (``make fuzz``, or ``HYPOTHESIS_PROFILE=fuzz``) draws fresh
random examples, ``FUZZ_FACTOR`` times as many, for exploration.
"""

from __future__ import annotations

import os
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


REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO / "config" / "reference"


@pytest.fixture(scope="session")
def config() -> dict:
    """The default config/config.yaml."""
    return yaml.safe_load((REPO / "config" / "config.yaml").read_text())


@pytest.fixture(scope="session")
def twin(config):
    """The default twin parameters."""
    return twin_params_from_mapping(config["twin"])


@pytest.fixture(scope="session")
def r_pipeline() -> pd.DataFrame:
    """The authors' seed-11 fault-scenario signals (config/reference, r_notes.md §13)."""
    return pd.read_csv(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
