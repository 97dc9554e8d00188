"""Typed, frozen settings of the config sections, parsed once at a stage's entry.

``hmm`` (and ``sensitivity.hmm``), ``simulation``, ``arx``, ``acf``, ``correction`` (and the
sweep's two shapings), ``bic``, ``ar_hmm``, ``sensitivity``, ``draws``. A stage (or the figure a
script draws) turns its config section into one of these objects at its entry; everything after
reads the object's attributes, never the raw
mapping, so every fit of the same kind reads the same keys. Library defaults are the dataclass
defaults (they equal the defaults of the library function the settings feed). Every section is
parsed the same way, by a ``from_mapping(raw, section)`` classmethod, which returns an object of
its own class as it is (a stage entry called with settings already parsed does not parse them
again): a missing or unknown key, a wrong type or a value out of range is a
:class:`~dtwin._validation.DtwinValueError` or :class:`~dtwin._validation.DtwinTypeError` naming
the key (``correction.ema_alpha must be in (0, 1] (got 1.3)``). The bounds are those of
``workflow/schemas/config.schema.yaml``; the keys' meanings are in ``docs/config.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import MISSING, asdict, dataclass, fields
from typing import TYPE_CHECKING, Any

from dtwin._validation import (
    DtwinValueError,
    require_in_range,
    require_mapping,
    require_nonnegative,
    require_number,
    require_positive,
    require_seed,
)
from dtwin.arx import ARX_MODULES, ROLLOUT_INITS, ArxOrders

if TYPE_CHECKING:
    from dtwin.sensitivity_sweep import SweepPoint

#: The sweep's two correction shapings (:data:`dtwin.sensitivity_sweep.CORRECTION_METHODS`,
#: equal by test): the sweep's module is imported only to check a grid, so reading a config
#: loads no pandas (the Fig. 1 job loads none).
_SHAPINGS: tuple[str, ...] = ("code", "paper")

__all__ = [
    "EmSettings",
    "HmmSettings",
    "SimulationSettings",
    "AcfSettings",
    "CorrectionSettings",
    "BicSettings",
    "ArHmmSettings",
    "SweepPointSettings",
    "SensitivitySettings",
    "DrawBicSettings",
    "DrawsSettings",
    "ArxSettings",
    "require_keys",
    "section_keys",
]


#: Names of the EM random starts (the keys of :data:`dtwin.hmm.START_METHODS`) and of the EM
#: engines (:data:`dtwin.hmm.ENGINES`); kept here so reading a config imports no EM engine.
_STARTS = ("dirichlet", "kmeans++")
_ENGINES = ("compiled", "hmmlearn")


def _integer(name: str, value: Any, minimum: int) -> int:
    """Return ``value`` as an int ``>= minimum`` (an integral float such as ``30.0`` counts)."""
    number = require_number(name, value)
    if number < minimum or not number.is_integer():
        raise DtwinValueError(f"{name} must be an integer >= {minimum} (got {value!r})")
    return int(number)


def _optional_integer(name: str, value: Any, minimum: int) -> int | None:
    return None if value is None else _integer(name, value, minimum)


def _open_unit(name: str, value: Any) -> float:
    """Return ``value`` as a float in (0, 1), else raise naming config key ``name``."""
    number = require_number(name, value)
    if not 0 < number < 1:
        raise DtwinValueError(f"{name} must be in (0, 1) (got {number})")
    return number


def _integers(section: str, key: str, value: Any) -> tuple[int, ...]:
    """Return list ``value`` of key ``section.key`` as a tuple of ints >= 1 (non-empty)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)) or not value:
        raise DtwinValueError(f"{section}.{key} must be a non-empty list (got {value!r})")
    return tuple(_integer(f"{section}.{key}", item, 1) for item in value)


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
        if isinstance(raw, cls):
            return raw
        raw = require_mapping(section, raw)
        values = asdict(cls())
        if "max_iter" in raw:
            values["max_iter"] = _integer(f"{section}.max_iter", raw["max_iter"], 1)
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
        if isinstance(raw, cls):
            return raw
        raw = require_mapping(section, raw)
        if "n_states" not in raw:
            raise DtwinValueError(f"{section} is missing n_states")
        n_restarts = raw.get("n_restarts", 10)
        return cls(
            n_states=_integer(f"{section}.n_states", raw["n_states"], 1),
            n_restarts=_integer(f"{section}.n_restarts", n_restarts, 1),
            em=EmSettings.from_mapping(raw, section),
        )

    def fit_options(self) -> dict[str, Any]:
        """Return the keyword arguments of :func:`dtwin.hmm.fit_hmm` but ``seed``."""
        return {"n_restarts": self.n_restarts, **self.em.options()}

    def summary(self) -> dict[str, Any]:
        """Return the settings as a figure's JSON records them, in the config's key order.

        ``n_states``, ``n_restarts``, ``max_iter``, ``tol``, ``var_floor``, ``start``; the
        engine is left out (both engines fit the same equations).
        """
        options = {k: v for k, v in self.em.options().items() if k != "engine"}
        return {"n_states": self.n_states, "n_restarts": self.n_restarts, **options}


def require_keys(
    section: str,
    raw: Any,
    required: Sequence[str],
    optional: Sequence[str] = (),
    *,
    others: bool = False,
) -> Mapping[str, Any]:
    """Return ``raw`` once it is a mapping holding every key of ``required``.

    Keys of ``optional`` may be left out; any other key is an error unless ``others``.

    Raises
    ------
    DtwinTypeError
        If ``raw`` is not a mapping.
    DtwinValueError
        If a key is missing or unknown (both named with ``section``).

    Examples
    --------
    >>> require_keys("bic", {"ks": [2], "typo": 1}, ("ks",))
    Traceback (most recent call last):
    ...
    dtwin._validation.DtwinValueError: bic has unknown key(s): typo
    """
    raw = require_mapping(section, raw)
    missing = [name for name in required if name not in raw]
    if missing:
        raise DtwinValueError(f"{section} is missing key(s): {', '.join(missing)}")
    known = {*required, *optional}
    unknown = sorted(str(key) for key in raw if key not in known)
    if unknown and not others:
        raise DtwinValueError(f"{section} has unknown key(s): {', '.join(unknown)}")
    return raw


def section_keys(cls: type, raw: Any, section: str) -> Mapping[str, Any]:
    """Return ``raw`` once it is a mapping holding the fields of dataclass ``cls`` and no other.

    Fields with a default may be left out (:func:`require_keys`).
    """
    required = [f.name for f in fields(cls) if f.default is MISSING]
    optional = [f.name for f in fields(cls) if f.default is not MISSING]
    return require_keys(section, raw, required, optional)


@dataclass(frozen=True)
class SimulationSettings:
    """The ``simulation`` section: length and seed of the paper's run (§3.1).

    Attributes
    ----------
    T : float
        Length of the run, s (``n_steps = round(T / twin.dt)``).
    seed : int
        Seed of the one generator of the command and the asset's noise.
    """

    T: float
    seed: int

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "simulation") -> SimulationSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> SimulationSettings.from_mapping({"T": 20.0, "seed": 11})
        SimulationSettings(T=20.0, seed=11)
        >>> SimulationSettings.from_mapping({"T": 0, "seed": 11})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: simulation.T must be > 0 (got 0.0)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        return cls(
            T=require_positive(f"{section}.T", raw["T"]),
            seed=require_seed(f"{section}.seed", raw["seed"]),
        )


@dataclass(frozen=True)
class AcfSettings:
    """The ``acf`` section: the residual autocorrelation of Fig. 3 (paper §4.1).

    Attributes
    ----------
    nlags : int
        Lags of every ACF, samples (>= 1).
    white_noise_n : int
        Length of panel A's white-noise demo series, samples (>= 10).
    white_noise_seed : int
        Seed of that series.
    ljungbox_lags : tuple of int
        Lags of the Ljung–Box tests, samples (each >= 1).
    significance : float
        Ljung–Box p below this reads "not white", in (0, 1).
    strong_lag1 : float
        Lag-1 ACF above this reads "strongly autocorrelated", in [−1, 1].
    """

    nlags: int
    white_noise_n: int
    white_noise_seed: int
    ljungbox_lags: tuple[int, ...]
    significance: float
    strong_lag1: float

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "acf") -> AcfSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> raw = {"nlags": 30, "white_noise_n": 1000, "white_noise_seed": 42,
        ...        "ljungbox_lags": [10, 20], "significance": 0.01, "strong_lag1": 0.9}
        >>> AcfSettings.from_mapping(raw).ljungbox_lags
        (10, 20)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        return cls(
            nlags=_integer(f"{section}.nlags", raw["nlags"], 1),
            white_noise_n=_integer(f"{section}.white_noise_n", raw["white_noise_n"], 10),
            white_noise_seed=require_seed(f"{section}.white_noise_seed", raw["white_noise_seed"]),
            ljungbox_lags=_integers(section, "ljungbox_lags", raw["ljungbox_lags"]),
            significance=_open_unit(f"{section}.significance", raw["significance"]),
            strong_lag1=require_in_range(f"{section}.strong_lag1", raw["strong_lag1"], -1, 1),
        )


@dataclass(frozen=True)
class CorrectionSettings:
    """The bias correction's shaping (paper §4.3).

    Section ``correction`` and the two shapings of ``sensitivity.correction`` (``code``,
    ``paper``).

    Attributes
    ----------
    kappa : float
        Gain on the estimated bias.
    ema_alpha : float
        Weight of the newest sample in the exponential moving average, in (0, 1].
    rate_max : float
        Largest step of the correction per sample, signal units (>= 0).
    """

    kappa: float
    ema_alpha: float
    rate_max: float

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "correction") -> CorrectionSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> CorrectionSettings.from_mapping({"kappa": 0.8, "ema_alpha": 0.15, "rate_max": 0.05})
        CorrectionSettings(kappa=0.8, ema_alpha=0.15, rate_max=0.05)
        >>> CorrectionSettings.from_mapping({"kappa": 0.8, "ema_alpha": 0, "rate_max": 0.05})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: correction.ema_alpha must be in (0, 1] (got 0.0)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        ema_alpha = require_number(f"{section}.ema_alpha", raw["ema_alpha"])
        if not 0 < ema_alpha <= 1:
            raise DtwinValueError(f"{section}.ema_alpha must be in (0, 1] (got {ema_alpha})")
        return cls(
            kappa=require_number(f"{section}.kappa", raw["kappa"]),
            ema_alpha=ema_alpha,
            rate_max=require_nonnegative(f"{section}.rate_max", raw["rate_max"]),
        )

    def options(self) -> dict[str, float]:
        """Return the keyword arguments ``kappa``, ``ema_alpha``, ``rate_max`` of a correction."""
        return {"kappa": self.kappa, "ema_alpha": self.ema_alpha, "rate_max": self.rate_max}


@dataclass(frozen=True)
class BicSettings:
    """The ``bic`` section: the sweep of the BIC over K (paper §5, Fig. 9).

    Attributes
    ----------
    ks : tuple of int
        The K always fitted (each >= 1).
    n_restarts : int
        EM starts per K (>= 1); the best of the first half is reported beside the best of all.
    k_max : int or None, default None
        Extend K past ``max(ks)`` until the BIC rose ``stop_after_rises`` times in a row, at
        most to ``k_max`` (None: no extension).
    stop_after_rises : int, default 2
        Rises in a row that bracket the minimum (>= 1).
    split_starts : bool, default False
        Also grow the best K − 1 fit by splitting each of its states.
    max_restarts : int or None, default None
        Starts of a K are doubled while its second half still gains, up to this (None: never).
    """

    ks: tuple[int, ...]
    n_restarts: int
    k_max: int | None = None
    stop_after_rises: int = 2
    split_starts: bool = False
    max_restarts: int | None = None

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "bic") -> BicSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> BicSettings.from_mapping({"ks": [2, 3], "n_restarts": 4})
        BicSettings(ks=(2, 3), n_restarts=4, k_max=None, stop_after_rises=2, split_starts=False, max_restarts=None)
        >>> BicSettings.from_mapping({"ks": [2, 0], "n_restarts": 4})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: bic.ks must be an integer >= 1 (got 0)
        """  # noqa: E501
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        split = raw.get("split_starts", False)
        if not isinstance(split, bool):
            raise DtwinValueError(f"{section}.split_starts must be true or false (got {split!r})")
        return cls(
            ks=_integers(section, "ks", raw["ks"]),
            n_restarts=_integer(f"{section}.n_restarts", raw["n_restarts"], 1),
            k_max=_optional_integer(f"{section}.k_max", raw.get("k_max"), 1),
            stop_after_rises=_integer(
                f"{section}.stop_after_rises", raw.get("stop_after_rises", 2), 1
            ),
            split_starts=split,
            max_restarts=_optional_integer(f"{section}.max_restarts", raw.get("max_restarts"), 1),
        )


@dataclass(frozen=True)
class ArHmmSettings:
    """The ``ar_hmm`` section: the AR(1)-emission HMM's BIC sweep (paper §5 future work, Fig. 13).

    Attributes
    ----------
    seed : int
        Entropy of the EM starts: K's starts use ``SeedSequence([seed, K])``.
    ks : tuple of int
        The K always fitted (each >= 1; ``hmm.n_states`` is added by the stage).
    k_max : int
        Past ``max(ks)`` K grows until the BIC rose ``stop_after_rises`` times in a row, at
        most to ``k_max`` (>= 1).
    stop_after_rises : int
        Rises in a row that bracket the minimum (>= 1).
    n_restarts : int
        EM starts per K (>= 1).
    max_iter : int
        EM iteration cap per start (>= 1).
    tol : float
        Relative stopping tolerance of EM (> 0).
    var_floor : float
        Lower bound on every innovation variance, z-units² (> 0).
    engine : str, default "compiled"
        EM engine, ``compiled`` or ``hmmlearn`` (the rule passes ``hmm.engine``); it does not
        change the settings of the fit, so :meth:`summary` leaves it out.
    """

    seed: int
    ks: tuple[int, ...]
    k_max: int
    stop_after_rises: int
    n_restarts: int
    max_iter: int
    tol: float
    var_floor: float
    engine: str = "compiled"

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "ar_hmm") -> ArHmmSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> raw = {"seed": 1, "ks": [2, 3], "k_max": 5, "stop_after_rises": 2,
        ...        "n_restarts": 2, "max_iter": 50, "tol": 1e-6, "var_floor": 1e-6}
        >>> ArHmmSettings.from_mapping(raw).ks
        (2, 3)
        >>> ArHmmSettings.from_mapping({**raw, "tol": 0})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: ar_hmm.tol must be > 0 (got 0.0)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        engine = raw.get("engine", "compiled")
        if engine not in _ENGINES:
            raise DtwinValueError(
                f"{section}.engine must be one of {', '.join(_ENGINES)} (got {engine!r})"
            )
        counts = {
            key: _integer(f"{section}.{key}", raw[key], 1)
            for key in ("k_max", "stop_after_rises", "n_restarts", "max_iter")
        }
        return cls(
            seed=require_seed(f"{section}.seed", raw["seed"]),
            ks=_integers(section, "ks", raw["ks"]),
            **counts,
            tol=require_positive(f"{section}.tol", raw["tol"]),
            var_floor=require_positive(f"{section}.var_floor", raw["var_floor"]),
            engine=engine,
        )

    def summary(self) -> dict[str, Any]:
        """Return the settings as the sweep's ``summary.json`` records them (``engine`` left out).

        Keys ``seed``, ``ks`` (a list), ``k_max``, ``stop_after_rises``, ``n_restarts``,
        ``max_iter``, ``tol``, ``var_floor``.
        """
        values = asdict(self)
        del values["engine"]
        return {**values, "ks": list(self.ks)}


def _flag(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool, else raise naming config key ``name``."""
    if not isinstance(value, bool):
        raise DtwinValueError(f"{name} must be true or false (got {value!r})")
    return value


@dataclass(frozen=True)
class SweepPointSettings:
    """What one point of the sensitivity sweep reads of section ``sensitivity`` (paper §5).

    The rule of a sweep chunk passes these keys only (a change of the grid, the figure's
    method or its interval reruns no point); the whole section parses as well (its other keys
    are ignored here: :class:`SensitivitySettings` checks them).

    Attributes
    ----------
    seed : int
        Seed of the EM starts of replicate 0 (``sensitivity.seed``).
    hmm : HmmSettings
        The HMM of every sweep fit (``sensitivity.hmm``).
    code, paper : CorrectionSettings
        The two shapings of the correction (``sensitivity.correction.code``, ``.paper``).
    r_signals : bool
        Also run each point on R's seed-11 signals (``sensitivity.r_signals``).
    """

    seed: int
    hmm: HmmSettings
    code: CorrectionSettings
    paper: CorrectionSettings
    r_signals: bool

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "sensitivity") -> SweepPointSettings:
        """Return the validated settings of a sweep point from config section ``section``.

        Examples
        --------
        >>> shaping = {"kappa": 0.6, "ema_alpha": 0.15, "rate_max": 5e-4}
        >>> raw = {"seed": 11, "hmm": {"n_states": 4}, "r_signals": False,
        ...        "correction": {"code": shaping, "paper": shaping}}
        >>> SweepPointSettings.from_mapping(raw).hmm.n_states
        4
        >>> SweepPointSettings.from_mapping({**raw, "correction": {"code": shaping}})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: sensitivity.correction is missing key(s): paper
        """
        if isinstance(raw, cls):
            return raw
        raw = require_keys(section, raw, _POINT_KEYS, others=True)
        correction = require_keys(
            f"{section}.correction", raw["correction"], _SHAPINGS, others=True
        )
        code, paper = (
            CorrectionSettings.from_mapping(correction[m], f"{section}.correction.{m}")
            for m in _SHAPINGS
        )
        return cls(
            seed=require_seed(f"{section}.seed", raw["seed"]),
            hmm=HmmSettings.from_mapping(raw["hmm"], f"{section}.hmm"),
            code=code,
            paper=paper,
            r_signals=_flag(f"{section}.r_signals", raw["r_signals"]),
        )


#: Keys of section ``sensitivity`` that one point of the sweep reads, and those of its grid.
_POINT_KEYS = ("seed", "hmm", "correction", "r_signals")
_GRID_KEYS = ("alphas", "sensor_A_mults", "sensor_B_mults", "n_replicates")


@dataclass(frozen=True)
class SensitivitySettings:
    """The ``sensitivity`` section: the sweep of Fig. 11 (paper §5).

    Attributes
    ----------
    alphas : tuple of float
        Fusion weights on sensor A, each in [0, 1].
    sensor_A_mults, sensor_B_mults : tuple of float
        Multipliers (>= 0) of the sensors' noise standard deviations.
    n_replicates : int
        Replicates of every configuration (>= 1).
    method : str
        The correction the figure's first panel and the claims show: ``code`` or ``paper``.
    interval : float
        Probability mass of the central interval over replicates drawn, in (0, 1).
    point : SweepPointSettings
        What every point of the sweep reads (seed, HMM, both shapings, ``r_signals``).
    """

    alphas: tuple[float, ...]
    sensor_A_mults: tuple[float, ...]
    sensor_B_mults: tuple[float, ...]
    n_replicates: int
    method: str
    interval: float
    point: SweepPointSettings

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "sensitivity") -> SensitivitySettings:
        """Return the validated settings of config section ``section``.

        The grid is checked as :func:`dtwin.sensitivity_sweep.sweep_grid` checks it.

        Examples
        --------
        >>> shaping = {"kappa": 0.6, "ema_alpha": 0.15, "rate_max": 5e-4}
        >>> raw = {"alphas": [0.2, 0.8], "sensor_A_mults": [1.0], "sensor_B_mults": [1.0],
        ...        "n_replicates": 1, "seed": 11, "hmm": {"n_states": 4}, "interval": 0.9,
        ...        "r_signals": False,
        ...        "correction": {"method": "code", "code": shaping, "paper": shaping}}
        >>> SensitivitySettings.from_mapping(raw).alphas
        (0.2, 0.8)
        >>> SensitivitySettings.from_mapping({**raw, "alphas": [0.2, 1.2]})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: sensitivity.alphas[1] must be in [0, 1] (got 1.2)
        """
        if isinstance(raw, cls):
            return raw
        raw = require_keys(section, raw, (*_GRID_KEYS, "interval", *_POINT_KEYS))
        correction = require_keys(
            f"{section}.correction", raw["correction"], ("method", *_SHAPINGS)
        )
        method = correction["method"]
        if method not in _SHAPINGS:
            raise DtwinValueError(
                f"{section}.correction.method must be one of {', '.join(_SHAPINGS)} "
                f"(got {method!r})"
            )
        from dtwin.sensitivity_sweep import sweep_grid  # on first use: see _SHAPINGS

        sweep_grid(*(raw[key] for key in _GRID_KEYS))  # checks the grid, naming the key
        return cls(
            alphas=tuple(float(value) for value in raw["alphas"]),
            sensor_A_mults=tuple(float(value) for value in raw["sensor_A_mults"]),
            sensor_B_mults=tuple(float(value) for value in raw["sensor_B_mults"]),
            n_replicates=int(raw["n_replicates"]),
            method=method,
            interval=_open_unit(f"{section}.interval", raw["interval"]),
            point=SweepPointSettings.from_mapping(raw, section),
        )

    def grid(self) -> list[SweepPoint]:
        """Return every point of the sweep (:func:`dtwin.sensitivity_sweep.sweep_grid`)."""
        from dtwin.sensitivity_sweep import sweep_grid  # on first use: see _SHAPINGS

        return sweep_grid(self.alphas, self.sensor_A_mults, self.sensor_B_mults, self.n_replicates)


@dataclass(frozen=True)
class DrawBicSettings:
    """Section ``draws.bic``: K* on the first draws (Fig. 12, Fig. 9's claims across draws).

    Attributes
    ----------
    n_draws : int
        Draws ``0 … n_draws − 1`` get a BIC sweep (>= 0; at most ``draws.n_draws``).
    n_restarts : int
        EM starts per K of each draw's sweep (>= 1).
    max_restarts : int
        Starts of a K are doubled while unstable, up to this (>= 1), as ``bic.max_restarts``.
    chunk_size : int
        Draws per job of the BIC sweeps (>= 1).
    """

    n_draws: int
    n_restarts: int
    max_restarts: int
    chunk_size: int

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "draws.bic") -> DrawBicSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> DrawBicSettings.from_mapping(
        ...     {"n_draws": 10, "n_restarts": 4, "max_restarts": 32, "chunk_size": 5}
        ... ).n_draws
        10
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        return cls(
            n_draws=_integer(f"{section}.n_draws", raw["n_draws"], 0),
            **{
                key: _integer(f"{section}.{key}", raw[key], 1)
                for key in ("n_restarts", "max_restarts", "chunk_size")
            },
        )


@dataclass(frozen=True)
class DrawsSettings:
    """The ``draws`` section: the paper's single-draw claims on N random draws (Fig. 12).

    Attributes
    ----------
    n_draws : int
        Random draws (>= 1); draw 0 uses the configured seeds.
    chunk_size : int
        Draws per job (>= 1).
    interval : float
        Level of the Wilson interval of each claim's share of draws, in (0, 1).
    bic : DrawBicSettings
        K* on the first draws (``draws.bic``).
    """

    n_draws: int
    chunk_size: int
    interval: float
    bic: DrawBicSettings

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "draws") -> DrawsSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> bic = {"n_draws": 10, "n_restarts": 4, "max_restarts": 32, "chunk_size": 5}
        >>> raw = {"n_draws": 20, "chunk_size": 10, "interval": 0.95, "bic": bic}
        >>> DrawsSettings.from_mapping(raw).bic.n_restarts
        4
        >>> DrawsSettings.from_mapping({**raw, "interval": 95})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: draws.interval must be in (0, 1) (got 95.0)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        return cls(
            n_draws=_integer(f"{section}.n_draws", raw["n_draws"], 1),
            chunk_size=_integer(f"{section}.chunk_size", raw["chunk_size"], 1),
            interval=_open_unit(f"{section}.interval", raw["interval"]),
            bic=DrawBicSettings.from_mapping(raw["bic"], f"{section}.bic"),
        )


@dataclass(frozen=True)
class ArxSettings:
    """The ``arx`` section: the ARX surrogates of paper §3.2, Eq. (22).

    Attributes
    ----------
    orders : mapping of module name to ArxOrders
        The lag orders of every module the twin replaces by an ARX model (``M0, M1, M2a,
        M2b``: :attr:`dtwin.twin.wiring.Module.surrogate` ``"arx"``), in the section's order.
    train_frac : float, default 0.5
        Fraction of the samples, from the start, the models are fitted on, in (0, 1] (the
        paper: the first half).
    rollout_init : str, default "physics"
        Rollout start: ``physics`` (the first physics samples) or ``zeros``.
    """

    orders: Mapping[str, ArxOrders]
    train_frac: float = 0.5
    rollout_init: str = "physics"

    @classmethod
    def from_mapping(cls, raw: Any, section: str = "arx") -> ArxSettings:
        """Return the validated settings of config section ``section``.

        Examples
        --------
        >>> order = {"na": 1, "nb": 1, "d": 0}
        >>> raw = {"orders": {"M0": order, "M1": {"na": 2, "nb": 2}, "M2a": order, "M2b": order}}
        >>> ArxSettings.from_mapping(raw).orders["M1"]
        ArxOrders(na=2, nb=2, d=0)
        >>> ArxSettings.from_mapping({**raw, "train_frac": 0})
        Traceback (most recent call last):
        ...
        dtwin._validation.DtwinValueError: arx.train_frac must be in (0, 1] (got 0.0)
        """
        if isinstance(raw, cls):
            return raw
        raw = section_keys(cls, raw, section)
        orders = require_keys(f"{section}.orders", raw["orders"], ARX_MODULES)
        train_frac = require_number(f"{section}.train_frac", raw.get("train_frac", 0.5))
        if not 0 < train_frac <= 1:
            raise DtwinValueError(f"{section}.train_frac must be in (0, 1] (got {train_frac})")
        rollout_init = raw.get("rollout_init", "physics")
        if rollout_init not in ROLLOUT_INITS:
            raise DtwinValueError(
                f"{section}.rollout_init must be one of {', '.join(ROLLOUT_INITS)} "
                f"(got {rollout_init!r})"
            )
        return cls(
            orders={
                str(name): _arx_orders(f"{section}.orders.{name}", spec)
                for name, spec in orders.items()
            },
            train_frac=train_frac,
            rollout_init=rollout_init,
        )


def _arx_orders(section: str, raw: Any) -> ArxOrders:
    """Return one module's :class:`dtwin.arx.ArxOrders` (``na >= 0``, ``nb >= 1``, ``d >= 0``)."""
    raw = require_keys(section, raw, ("na", "nb"), ("d",))
    return ArxOrders(
        na=_integer(f"{section}.na", raw["na"], 0),
        nb=_integer(f"{section}.nb", raw["nb"], 1),
        d=_integer(f"{section}.d", raw.get("d", 0), 0),
    )
