"""The twin file (docs/gap.md §Twin file): its content as :class:`~dtwin.params.TwinParams`.

A twin file is a bare mapping or one under a ``twin:`` key; sections may be missing (the
diagnoser then calibrates that module) and ``discretisation`` may be absent (the diagnoser then
chooses the plant's discretisation on the training part).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from dtwin._validation import DtwinTypeError
from dtwin.params import TwinParams, discretisation_from_mapping, twin_params_from_mapping

__all__ = ["twin_from_mapping", "twin_discretisation"]

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
