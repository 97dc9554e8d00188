"""Typed, frozen settings of config sections, parsed once at a stage's entry.

A stage turns its config section into one of these objects first; everything after reads the
object, so every fit of the same kind reads the same keys. Library defaults are the
dataclass defaults (they equal the defaults of the library function the settings feed).
Errors name the config key (``hmm.var_floor must be > 0 (got 0)``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from dtwin._validation import DtwinValueError, require_mapping, require_positive

__all__ = ["EmSettings", "HmmSettings"]


def _count(section: str, raw: Mapping[str, Any], key: str, minimum: int) -> int:
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise DtwinValueError(f"{section}.{key} must be an integer >= {minimum} (got {value!r})")
    return value


def _em_values(raw: Mapping[str, Any], section: str, defaults: Mapping[str, Any]) -> dict:
    values = {}
    for key, default in defaults.items():
        if key not in raw:
            values[key] = default
        elif key in ("n_states", "n_restarts", "max_iter"):
            values[key] = _count(section, raw, key, 1)
        else:
            values[key] = require_positive(f"{section}.{key}", raw[key])
    return values


@dataclass(frozen=True)
class EmSettings:
    """The EM options of every HMM fit: the part of section ``hmm`` a K sweep needs.

    Attributes
    ----------
    max_iter : int, default 500
        EM iteration cap per start (depmixS4 ``maxit``).
    tol : float, default 1e-8
        Relative stopping tolerance of EM.
    var_floor : float, default 1e-3
        Lower bound on every emission variance, z-units².
    """

    max_iter: int = 500
    tol: float = 1e-8
    var_floor: float = 1e-3

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "hmm") -> EmSettings:
        """Return the EM options of config section ``section`` (other keys are ignored).

        Examples
        --------
        >>> EmSettings.from_mapping({"seed": 1, "tol": 1e-6}).tol
        1e-06
        """
        raw = require_mapping(section, raw)
        return cls(**_em_values(raw, section, asdict(cls())))

    def options(self) -> dict[str, Any]:
        """Return the keyword arguments ``max_iter``, ``tol``, ``var_floor`` of the fit."""
        return asdict(self)


@dataclass(frozen=True)
class HmmSettings:
    """The Gaussian HMM's settings: config section ``hmm`` or ``sensitivity.hmm``.

    Attributes
    ----------
    n_states : int
        Number of hidden states K (paper: 4).
    n_restarts : int, default 10
        Random EM starts per fit; the best log-likelihood is kept.
    max_iter : int, default 500
        EM iteration cap per start (depmixS4 ``maxit``).
    tol : float, default 1e-8
        Relative stopping tolerance of EM.
    var_floor : float, default 1e-3
        Lower bound on every emission variance, z-units².
    """

    n_states: int
    n_restarts: int = 10
    max_iter: int = 500
    tol: float = 1e-8
    var_floor: float = 1e-3

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "hmm") -> HmmSettings:
        """Return the settings of config section ``section`` (its other keys are ignored).

        Examples
        --------
        >>> HmmSettings.from_mapping({"n_states": 4, "var_floor": 0.01}).var_floor
        0.01
        >>> HmmSettings.from_mapping({"n_states": 4, "tol": 0}, "sensitivity.hmm")
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: sensitivity.hmm.tol must be > 0 (got 0.0)
        """
        raw = require_mapping(section, raw)
        if "n_states" not in raw:
            raise DtwinValueError(f"{section} is missing n_states")
        values = _em_values(raw, section, asdict(cls(n_states=1)))
        return cls(**values)

    def fit_options(self) -> dict[str, Any]:
        """Return the keyword arguments of :func:`dtwin.hmm.fit_hmm` but ``seed``."""
        return {
            "n_restarts": self.n_restarts,
            "max_iter": self.max_iter,
            "tol": self.tol,
            "var_floor": self.var_floor,
        }

    def em_options(self) -> dict[str, Any]:
        """Return the EM options alone (``max_iter``, ``tol``, ``var_floor``)."""
        return EmSettings(self.max_iter, self.tol, self.var_floor).options()
