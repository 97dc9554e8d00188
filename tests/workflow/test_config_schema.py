"""The config schema documents every key (description, x-unit) and still validates as before."""

from __future__ import annotations

import copy
import importlib.util
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
CONFIG = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())


def _resolve(node: dict[str, Any]) -> dict[str, Any]:
    """Merge a node with its ``$ref`` target (and the targets of its ``allOf`` refs)."""
    merged: dict[str, Any] = {}
    refs = [node.get("$ref")] + [part.get("$ref") for part in node.get("allOf", [])]
    for ref in filter(None, refs):
        target: Any = SCHEMA
        for part in ref.removeprefix("#/").split("/"):
            target = target[part]
        merged.update(_resolve(target))
    merged.update(node)
    return merged


def _leaves(value: Any, path: tuple[str, ...] = ()):
    """Every leaf key path of the config; a list is one leaf (``faults.schedule``)."""
    if isinstance(value, dict):
        for key, child in value.items():
            yield from _leaves(child, (*path, str(key)))
    else:
        yield path


def _node_path(path: tuple[str, ...]) -> list[tuple[str, dict[str, Any]]]:
    """The schema nodes along ``path`` (each resolved), from the first key to the leaf."""
    nodes = []
    node = _resolve(SCHEMA)
    for key in path:
        node = _resolve(node["properties"][key])
        nodes.append((key, node))
    return nodes


def _documented(node: dict[str, Any]) -> bool:
    description = node.get("description")
    unit = node.get("x-unit")
    return isinstance(description, str) and bool(description.strip()) and bool(unit)


CONFIG_KEYS = sorted(_leaves(CONFIG))


def test_config_has_keys():
    assert len(CONFIG_KEYS) > 100


@pytest.mark.parametrize("path", CONFIG_KEYS, ids=".".join)
def test_every_config_key_is_documented(path):
    for depth, (_key, node) in enumerate(_node_path(path)):
        where = ".".join(path[: depth + 1])
        assert _documented(node), f"{where} has no description or x-unit"


def _schema_properties(node: Any, where: str = ""):
    """Every property of the schema (sections, leaves, array items, inside definitions)."""
    if isinstance(node, dict):
        for key, child in node.get("properties", {}).items():
            yield f"{where}.{key}".lstrip("."), child
            yield from _schema_properties(child, f"{where}.{key}")
        for key, child in node.get("definitions", {}).items():
            yield from _schema_properties(child, f"definitions.{key}")
        if isinstance(node.get("items"), dict):
            yield from _schema_properties(node["items"], f"{where}[]")


def test_every_schema_property_is_documented():
    undocumented = [where for where, node in _schema_properties(SCHEMA) if not _documented(node)]
    assert undocumented == []


def test_default_config_validates():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    assert list(jsonschema.Draft202012Validator(SCHEMA).iter_errors(CONFIG)) == []


def _negative_mass(config):
    config["twin"]["plant"]["m"] = -1.0


def _missing_var_floor(config):
    del config["hmm"]["var_floor"]


def _unknown_fusion_key(config):
    config["twin"]["fusion"]["beta"] = 0.1


@pytest.mark.parametrize(
    ("breaks", "path", "word"),
    [
        (_negative_mass, ["twin", "plant", "m"], "less than or equal to the minimum"),
        (_missing_var_floor, ["hmm"], "var_floor"),
        (_unknown_fusion_key, ["twin", "fusion"], "beta"),
    ],
)
def test_broken_config_is_rejected_with_its_path(breaks, path, word):
    """The documentation keywords did not weaken the validation (bounds, required, extras)."""
    config = copy.deepcopy(CONFIG)
    breaks(config)
    errors = list(jsonschema.Draft202012Validator(SCHEMA).iter_errors(config))
    assert [list(e.absolute_path) for e in errors] == [path]
    assert word in errors[0].message


def test_config_doc_is_generated():
    """docs/config.md is what docs/make_config_doc.py writes (rerun it after a schema edit)."""
    spec = importlib.util.spec_from_file_location(
        "make_config_doc", ROOT / "docs" / "make_config_doc.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    expected = module.render(SCHEMA, CONFIG)
    assert (ROOT / "docs" / "config.md").read_text() == expected
