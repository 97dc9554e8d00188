"""The generator's nominal twin is the paper's twin of config/config.yaml (one set of numbers)."""

from __future__ import annotations

from dtwin.gapbench.generator import NOMINAL_TWIN


def test_the_generators_nominal_twin_is_the_configs(config):
    """NOMINAL_TWIN is a copy (the library reads no config file): it must not drift from it."""
    twin = {key: value for key, value in config["twin"].items() if key != "discretisation"}
    assert twin == NOMINAL_TWIN
