"""Lazy re-exports of a package's public names (PEP 562), written once.

``dtwin`` and ``dtwin.gapbench`` re-export names that live in heavier modules; a name is
imported on its first use, so importing the package stays cheap and a script pays only for the
modules it uses.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable, Collection, Mapping
from typing import Any

__all__ = ["lazy_exports", "keep_exports"]


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


def keep_exports(package: str, names: Collection[str]) -> None:
    """Keep ``package.NAME`` the re-exported object when the submodule ``package.NAME`` loads.

    Importing a submodule binds it on its package (``import dtwin.gap.diagnose`` sets
    ``dtwin.gap.diagnose`` to the module). A package that re-exported a function of that name
    eagerly rebound it at once; a lazy one would keep the module, and ``from dtwin.gap import
    diagnose`` would return it. For ``names``, that binding is skipped, so the attribute stays
    unset until its first use resolves it through the package's ``__getattr__`` (the
    function), as before. The submodule stays importable by name (``sys.modules``,
    :func:`importlib.import_module`).

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : collection of str
        Exported names that are also the names of the package's submodules.
    """
    shadowed = frozenset(names)

    class _Package(types.ModuleType):
        def __setattr__(self, name: str, value: Any) -> None:
            if (
                name in shadowed
                and isinstance(value, types.ModuleType)
                and value.__name__ == f"{package}.{name}"
            ):
                return
            super().__setattr__(name, value)

    sys.modules[package].__class__ = _Package
