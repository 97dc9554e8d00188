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

#: Names of the EM random starts (the keys of :data:`dtwin.hmm.START_METHODS`) and of the EM
#: engines (:data:`dtwin.hmm.ENGINES`); kept here so reading a config imports no EM engine.
_STARTS = ("dirichlet", "kmeans++")
_ENGINES = ("compiled", "hmmlearn")


def _count(section: str, raw: Mapping[str, Any], key: str, minimum: int) -> int:
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise DtwinValueError(f"{section}.{key} must be an integer >= {minimum} (got {value!r})")
    return value


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
    start : str, default "dirichlet"
        Random start of every EM run (:data:`dtwin.hmm.START_METHODS`): depmixS4's
        ``dirichlet`` or ``kmeans++``.
    engine : str, default "compiled"
        EM engine (:func:`dtwin.hmm.fit_hmm`): ``compiled`` (numba kernels) or ``hmmlearn``
        (the reference; same equations).
    """

    max_iter: int = 500
    tol: float = 1e-8
    var_floor: float = 1e-3
    start: str = "dirichlet"
    engine: str = "compiled"

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "hmm") -> EmSettings:
        """Return the EM options of config section ``section`` (other keys are ignored).

        Examples
        --------
        >>> EmSettings.from_mapping({"seed": 1, "tol": 1e-6}).tol
        1e-06
        """
        raw = require_mapping(section, raw)
        values = asdict(cls())
        if "max_iter" in raw:
            values["max_iter"] = _count(section, raw, "max_iter", 1)
        for key in ("tol", "var_floor"):
            if key in raw:
                values[key] = require_positive(f"{section}.{key}", raw[key])
        for key, names in (("start", _STARTS), ("engine", _ENGINES)):
            if key in raw:
                if raw[key] not in names:
                    raise DtwinValueError(
                        f"{section}.{key} must be one of {', '.join(names)} (got {raw[key]!r})"
                    )
                values[key] = raw[key]
        return cls(**values)

    def options(self) -> dict[str, Any]:
        """Return the keyword arguments ``max_iter``, ``tol``, ``var_floor``, ``start``, ``engine``.

        (Of :func:`dtwin.hmm.fit_hmm` and :func:`dtwin.hmm.bic_by_k`.)
        """
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
    em : EmSettings
        The EM options (``max_iter``, ``tol``, ``var_floor``).
    """

    n_states: int
    n_restarts: int = 10
    em: EmSettings = EmSettings()

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "hmm") -> HmmSettings:
        """Return the settings of config section ``section`` (its other keys are ignored).

        Examples
        --------
        >>> HmmSettings.from_mapping({"n_states": 4, "var_floor": 0.01}).em.var_floor
        0.01
        >>> HmmSettings.from_mapping({"n_states": 4, "tol": 0}, "sensitivity.hmm")
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: sensitivity.hmm.tol must be > 0 (got 0.0)
        """
        raw = require_mapping(section, raw)
        if "n_states" not in raw:
            raise DtwinValueError(f"{section} is missing n_states")
        n_restarts = _count(section, raw, "n_restarts", 1) if "n_restarts" in raw else 10
        return cls(
            n_states=_count(section, raw, "n_states", 1),
            n_restarts=n_restarts,
            em=EmSettings.from_mapping(raw, section),
        )

    def fit_options(self) -> dict[str, Any]:
        """Return the keyword arguments of :func:`dtwin.hmm.fit_hmm` but ``seed``."""
        return {"n_restarts": self.n_restarts, **self.em.options()}
