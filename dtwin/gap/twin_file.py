"""The twin file (docs/gap.md §Twin file): its text, and its content as a twin.

A twin file has one of two shapes. The paper's ``twin:`` shape is read as
:class:`~dtwin.params.TwinParams` (:func:`twin_from_mapping`): a bare mapping or one under a
``twin:`` key; sections may be missing (the diagnoser then calibrates that module) and
``discretisation`` may be absent (the diagnoser then chooses the plant's discretisation on the
training part). A file with a ``modules:`` key is a **twin table** (:func:`is_table`,
:func:`table_file`, :mod:`dtwin.twin.table`).

:func:`load_twin_text` reads the text as YAML, safely and strictly, as a user writes numbers:

- a text larger than :data:`MAX_TWIN_BYTES` (1 MB) is refused before parsing;
- a key repeated in one mapping is refused, naming the key and its line (PyYAML would keep the
  last silently); so is a merge key ``<<``;
- aliases (``*name``) are refused, so an alias bomb ("billion laughs") fails at its first alias,
  before anything is expanded; anchors alone are harmless;
- nesting deeper than :data:`MAX_TWIN_DEPTH` levels is refused;
- scientific notation without a dot or without an exponent sign (``1e-5``, ``2E3``, ``1.0e5``),
  a string under YAML 1.1, is a float;
- a syntax error is one line: ``twin file is not valid YAML: line 3, column 5: <problem>``.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from typing import Any

import yaml

from dtwin._validation import DtwinTypeError, DtwinValueError
from dtwin.params import TwinParams, discretisation_from_mapping, twin_params_from_mapping
from dtwin.twin.table import TwinTable, table_from_mapping

__all__ = [
    "MAX_TWIN_BYTES",
    "MAX_TWIN_DEPTH",
    "twin_from_mapping",
    "twin_discretisation",
    "load_twin_text",
    "is_table",
    "table_file",
]

#: Largest twin file, bytes (UTF-8).
MAX_TWIN_BYTES = 1_000_000
#: Deepest nesting of a twin file's YAML (mappings and lists).
MAX_TWIN_DEPTH = 50

logger = logging.getLogger(__name__)


def twin_from_mapping(mapping: Any, dt: float | None = None) -> TwinParams:
    """Return :class:`TwinParams` from a twin file's content (docs/gap.md §Twin file).

    The content is a bare mapping or one under a ``twin:`` key. Sections may be missing (the
    diagnoser then calibrates that module); ``dt`` may be missing if given here (the
    recording's). An empty file is an empty mapping.
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, Mapping):
        raise DtwinTypeError(f"twin file must be a mapping (got {type(mapping).__name__})")
    if "twin" in mapping:
        if set(mapping) - {"twin"}:
            extra = ", ".join(sorted(set(mapping) - {"twin"}))
            logger.info("twin file: ignoring top-level keys beside 'twin': %s", extra)
        mapping = mapping["twin"] if mapping["twin"] is not None else {}
        if not isinstance(mapping, Mapping):
            raise DtwinTypeError(f"twin must be a mapping (got {type(mapping).__name__})")
    mapping = dict(mapping)
    if "dt" not in mapping and dt is not None:
        mapping["dt"] = dt
    return twin_params_from_mapping(mapping, require_all=False)


def twin_discretisation(mapping: Any) -> str | None:
    """Return the twin file's ``discretisation`` (docs/gap.md §Twin file), or None.

    ``euler`` (the paper's twin), ``zoh``, ``foh`` or ``bandlimited``; None (absent) lets the
    diagnoser choose among the four on the training part. :func:`twin_from_mapping` keeps the
    same value in ``TwinParams.discretisation``.
    """
    if isinstance(mapping, Mapping) and isinstance(mapping.get("twin"), Mapping):
        mapping = mapping["twin"]
    if not isinstance(mapping, Mapping):
        return None
    return discretisation_from_mapping(mapping, prefix="twin file")


class _TwinLoader(yaml.SafeLoader):
    """PyYAML's safe loader without aliases or duplicate keys, with ``1e-5`` as a float."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise DtwinValueError(
                f"twin file: line {event.start_mark.line + 1}: aliases ('*{event.anchor}') are "
                "not allowed in a twin file (write the value out)"
            )
        self._depth += 1
        if self._depth > MAX_TWIN_DEPTH:
            line = self.peek_event().start_mark.line + 1
            raise DtwinValueError(
                f"twin file: line {line}: nested more than {MAX_TWIN_DEPTH} levels deep"
            )
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen: set = set()
        for key_node, _ in node.value:
            line = key_node.start_mark.line + 1
            if key_node.tag == "tag:yaml.org,2002:merge":
                raise DtwinValueError(f"twin file: line {line}: merge keys (<<) are not allowed")
            key = self.construct_object(key_node, deep=True)
            try:
                repeated = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: PyYAML's own error follows
                continue
            if repeated:
                raise DtwinValueError(f"twin file: line {line}: duplicate key '{key}'")
        return super().construct_mapping(node, deep=deep)


_TwinLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def load_twin_text(text: str) -> Any:
    r"""Return the content of a twin file's text, read as strict, safe YAML (module docstring).

    Parameters
    ----------
    text : str
        The file's text.

    Returns
    -------
    Any
        The YAML value (a mapping for a valid twin file); None for an empty text.

    Raises
    ------
    DtwinValueError
        A text over 1 MB, a duplicate or merge key, an alias, too deep a nesting, or invalid
        YAML, in one line.

    Examples
    --------
    >>> load_twin_text("dt: 4.0\nmodules: {pump: {params: {tau: 1e-5}}}")
    {'dt': 4.0, 'modules': {'pump': {'params': {'tau': 1e-05}}}}
    >>> load_twin_text("a: 1\na: 2")
    Traceback (most recent call last):
    ...
    dtwin._validation.DtwinValueError: twin file: line 2: duplicate key 'a'
    """
    if not isinstance(text, str):
        raise DtwinTypeError(f"twin file text must be a string (got {type(text).__name__})")
    if len(text) > MAX_TWIN_BYTES or len(text.encode("utf-8")) > MAX_TWIN_BYTES:
        raise DtwinValueError(f"twin file is larger than {MAX_TWIN_BYTES // 1_000_000} MB")
    loader = _TwinLoader(text)
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = error.problem or error.context or "invalid"
        raise DtwinValueError(f"twin file is not valid YAML: {where}{problem}") from None
    except yaml.YAMLError as error:
        first = (str(error).strip().splitlines() or ["invalid"])[0]
        raise DtwinValueError(f"twin file is not valid YAML: {first}") from None
    except RecursionError:
        raise DtwinValueError("twin file is nested too deeply") from None
    finally:
        loader.dispose()


def is_table(mapping: Any) -> bool:
    """Return whether a twin file's content is a twin table rather than the ``twin:`` shape.

    A table has a ``modules`` key, at the top level or under ``twin:``.

    Examples
    --------
    >>> is_table({"modules": {}}), is_table({"twin": {"modules": {}}}), is_table({"twin": {}})
    (True, True, False)
    """
    if not isinstance(mapping, Mapping):
        return False
    inner = mapping.get("twin")
    return "modules" in mapping or (isinstance(inner, Mapping) and "modules" in inner)


def table_file(mapping: Any, dt: float | None = None, base_dir: str | None = None) -> TwinTable:
    """Return the :class:`~dtwin.twin.table.TwinTable` of a twin file's content.

    Parameters
    ----------
    mapping : Any
        The content (:func:`load_twin_text`); a table (:func:`is_table`).
    dt : float, optional
        Sample period, s, when the file gives none (the recording's).
    base_dir : str, optional
        The twin file's folder (an FMU module's path is relative to it).

    Raises
    ------
    dtwin.twin.table.TwinTableError
        One line naming the module, the key and the token (:mod:`dtwin.twin.table`).
    """
    return table_from_mapping(mapping, dt=dt, base_dir=base_dir)
