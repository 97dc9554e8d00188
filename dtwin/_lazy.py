"""Lazy re-exports of a package's public names (PEP 562), written once.

``dtwin`` and ``dtwin.gapbench`` re-export names that live in heavier modules; a name is
imported on its first use, so importing the package stays cheap and a script pays only for the
modules it uses.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Return the ``__getattr__`` and ``__dir__`` of a package that re-exports names lazily.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (``"dtwin.gapbench"``).
    exports : mapping of str to str
        Each public name → the module that defines it.

    Returns
    -------
    (getattr, dir)
        The package's module-level ``__getattr__`` (imports the defining module on first use;
        AttributeError for any other name) and ``__dir__`` (the package's globals and the
        exports, sorted).

    Examples
    --------
    >>> getattr_, dir_ = lazy_exports("dtwin", {"SIGNALS": "dtwin.twin.wiring"})
    >>> getattr_("SIGNALS")[:2]
    ('u_cmd', 'u_act')
    """

    def get_export(name: str) -> Any:
        if name in exports:
            return getattr(importlib.import_module(exports[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def names() -> list[str]:
        return sorted([*vars(sys.modules[package]), *exports])

    return get_export, names
