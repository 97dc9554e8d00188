"""Shared fixtures: the repository root, the default config and its twin parameters."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml

from dtwin.params import twin_params_from_mapping

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
    """The authors' seed-11 fault-scenario signals (config/reference, REFERENCE.md §13)."""
    return pd.read_csv(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
