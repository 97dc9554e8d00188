"""Twin parameters are validated with messages that name the key."""

from __future__ import annotations

import copy

import pytest

from dtwin._validation import DtwinTypeError, DtwinValueError
from dtwin.params import twin_params_from_mapping


@pytest.mark.parametrize(
    ("path", "value", "error", "message"),
    [
        (("fusion", "alpha"), 1.3, DtwinValueError, r"twin\.fusion\.alpha must be in \[0, 1\]"),
        (("actuator", "tau"), -0.1, DtwinValueError, r"twin\.actuator\.tau must be > 0"),
        (("plant", "m"), "heavy", DtwinTypeError, r"twin\.plant\.m must be a number"),
        (("noise", "plant"), -1.0, DtwinValueError, r"twin\.noise\.plant must be >= 0"),
    ],
)
def test_bad_values_name_the_key(config, path, value, error, message):
    twin = copy.deepcopy(config["twin"])
    twin[path[0]][path[1]] = value
    with pytest.raises(error, match=message):
        twin_params_from_mapping(twin)


def test_missing_and_unknown_keys(config):
    twin = copy.deepcopy(config["twin"])
    del twin["plant"]["k"]
    with pytest.raises(DtwinValueError, match=r"twin\.plant is missing key\(s\): k"):
        twin_params_from_mapping(twin)
    twin = copy.deepcopy(config["twin"])
    twin["plant"]["mass"] = 2.0
    with pytest.raises(DtwinValueError, match="unknown key"):
        twin_params_from_mapping(twin)


def test_partial_twin_allowed_when_asked(config):
    params = twin_params_from_mapping(
        {"dt": 0.01, "plant": config["twin"]["plant"]}, require_all=False
    )
    assert params.plant.k == 4.0 and params.sensor_A is None
    with pytest.raises(DtwinValueError, match="missing key: actuator"):
        twin_params_from_mapping({"dt": 0.01})


def test_twin_sections_come_from_the_module_table():
    """Each TwinParams section's dataclass has exactly the contract's keys, in its order."""
    from dataclasses import fields

    from dtwin.params import _SECTION_FIELDS, TwinParams
    from dtwin.twin.paper_modules import CONTRACTS
    from dtwin.twin.wiring import MODULES

    assert list(_SECTION_FIELDS) == [m.section for m in MODULES] + ["noise"]
    for section, (cls, keys) in _SECTION_FIELDS.items():
        assert tuple(f.name for f in fields(cls)) == keys, section
    assert _SECTION_FIELDS["noise"][1] == tuple(c.section for c in CONTRACTS.values() if c.noise)
    assert [f.name for f in fields(TwinParams)] == ["dt", *_SECTION_FIELDS, "discretisation"]
