"""numba's ``njit`` when numba is installed, otherwise the plain Python function.

numba is pinned in ``requirements.lock``, but ``dtwin`` installed without it (``pip install
--no-deps``, an older environment) must still diagnose and fit: the force loop then runs the
same arithmetic in Python (slower), and the EM engine ``compiled`` falls back to hmmlearn, the
reference engine (:func:`dtwin._multistart.available_engine`). Checking for numba does not
import it (importing it costs ~0.5 s).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from typing import Any

__all__ = ["HAVE_NUMBA", "njit"]

#: Whether numba can be imported in this environment.
HAVE_NUMBA: bool = importlib.util.find_spec("numba") is not None


def njit(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Return ``numba.njit(**options)``, or the identity decorator when numba is missing."""
    if HAVE_NUMBA:
        from numba import njit as numba_njit

        return numba_njit(**options)
    return lambda function: function
