"""The sim-to-real gap diagnoser: where the gap lies, which effect causes it, how far it shrinks.

:func:`diagnose` implements docs/gap.md in three steps (§Where, §Which, §How far).

1. **Where.** Each module whose input and output are recorded is driven with its *recorded*
   input; its local gap (:mod:`dtwin.gap.localise`) is compared with the largest gap its noise
   explains (:mod:`dtwin.gap.noise`), both on the training and choosing parts. Twins are
   never calibrated exactly, so the comparison uses the gap left after re-fitting the module's
   own linear parameters inside ``calibration_tolerance`` of their nominal values on the
   training part: a gap such a re-fit removes is calibration slack, not a sim-to-real gap. A
   module above its threshold has a gap; the *source* is the one furthest above. The chain
   shows which other gaps are only inherited.
2. **Which.** Every candidate of a module with a gap (:mod:`dtwin.gap.effects`, plus
   ``parameter_mismatch``) is fitted on the training part together with the module's linear
   parameters (:mod:`dtwin.gap.fit`), then scored on the **choosing part** by
   ``n_eff·ln(MSE) + p·ln(n_eff)`` (BIC with the effective sample size of the module's noise,
   so that slowly varying noise is not counted as independent evidence). The lowest score
   wins; ``unexplained`` if it removes less than ``min_share`` of the choosing part's excess
   gap; ``none`` if no module has a gap. ``confidence`` is the winner's BIC weight.
3. **How far.** On the **scoring part**, never used for a decision, three shrinks:
   ``raw_shrink_pct`` (whole error), ``own_shrink_pct`` (the effect's own share: the excess
   gap left by the twin with only its linear parameters re-fitted on the same training data,
   against the excess left with the effect) and ``excess_shrink_pct`` (the excess over the
   module's one noise floor, ``√(gap² − floor²)``, with ``excess_clipped`` when that reaches
   100 %); the chain re-run with the effect added gives ``kpi_shrink_pct``.

Every decision is taken before the scoring part (where the gap lies: training and choosing
parts; which candidate and ``unexplained``: the choosing part); every reported shrink on the
scoring part (docs/gap.md §Interface).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from dtwin._validation import DtwinTypeError, DtwinValueError, require_in_range
from dtwin.exact_plant import EXACT_HOLDS
from dtwin.gap.confidence import calibrated_confidence
from dtwin.gap.effects import (
    NONE,
    PARAMETER_MISMATCH,
    UNEXPLAINED,
    Effect,
    Scales,
    effect_by_name,
    effects_for_module,
    quantization_variance,
    quantizer_log_density,
)
from dtwin.gap.fit import CandidateFit, calibrate_linear, fit_candidate, linear_typical
from dtwin.gap.intervals import parameter_intervals
from dtwin.gap.localise import (
    ModuleModel,
    module_inputs,
    normalised_rms,
    run_chain,
    upstream_modules,
)
from dtwin.gap.models import (
    LINEAR_PARAMS,
    MIN_HORIZON,
    ModuleData,
    plant_bandwidth_hz,
    plant_horizon,
    plant_state_from_position,
    plant_windows,
    simulate_module,
    window_noise_gain,
)
from dtwin.gap.noise import (
    NoiseFloor,
    data_noise_floor,
    effective_samples,
    gap_threshold,
    reconcile_noise_floor,
    spectral_noise_floor,
    twin_noise_floor,
)
from dtwin.gap.oe_reference import output_error_reference
from dtwin.gap.recording import Recording, diagnosable_modules
from dtwin.modules import EULER
from dtwin.params import TwinParams, discretisation_from_mapping, twin_params_from_mapping
from dtwin.wiring import MODULES, module_by_name

__all__ = [
    "GapSettings",
    "ModuleReport",
    "CandidateReport",
    "Diagnosis",
    "DT_TOLERANCE",
    "twin_from_mapping",
    "twin_discretisation",
    "join_heldout",
    "diagnose",
]

logger = logging.getLogger(__name__)
#: The diagnoser's steps, at INFO (``dtwin diagnose`` shows the current one on stderr once a
#: run has taken a few seconds: docs/gap.md §Speed).
progress = logging.getLogger(f"{__name__}.progress")

#: Largest relative disagreement between the recording's dt and ``twin.dt``.
DT_TOLERANCE = 0.01
#: Calibration fits of the exact plant's window search, at most (docs/gap.md §Gaps).
WINDOW_ROUNDS = 3
#: Relative change of the window under which its search stops.
WINDOW_SETTLED = 0.1


@dataclass(frozen=True)
class GapSettings:
    """Decision constants of the diagnoser (the ``gap.diagnose`` config section).

    See docs/gap.md §Settings; their roles in §Where and §Which.

    Attributes
    ----------
    noise_tolerance : float, default 0.10
        Relative uncertainty of the twin's noise levels.
    calibration_tolerance : float, default 0.05
        Relative band around each nominal linear parameter that counts as "calibrated"
        (a bias's band is this fraction of the output's standard deviation).
    significance : float, default 0.01
        Probability that noise alone exceeds the threshold (a one-sided test).
    min_gap : float, default 0.005
        Smallest normalised excess gap (``√(gap² − floor²)``) worth reporting, whatever the
        noise.
    min_share : float, default 0.5
        Share of the choosing part's excess gap the best candidate must remove to explain it.
    min_linear_share : float, default 0.75
        The same for a candidate of linear form (``parameter_mismatch``, a sensor gain): the
        twin re-fitted inside its own model class is exact when such a candidate is the answer,
        so it leaves little but noise (right answers of the arms' benchmark seeds removed
        75.5–100 %, n = 72; backlash or hysteresis read as one removed 50–75 %, docs/gap.md
        §Which).
    choose_frac : float, default 0.5
        Share of the samples after the training part that is the **choosing part** (every
        decision: where, which, ``unexplained``); the rest is the **scoring part** (every
        reported gap after an effect and every shrink). Ignored with a separate held-out
        recording: that recording is the scoring part, the samples of the first recording after
        its training part the choosing part (docs/gap.md §Interface).
    """

    noise_tolerance: float = 0.10
    calibration_tolerance: float = 0.05
    significance: float = 0.01
    min_gap: float = 0.005
    min_share: float = 0.5
    min_linear_share: float = 0.75
    choose_frac: float = 0.5

    def __post_init__(self) -> None:
        require_in_range("gap.noise_tolerance", self.noise_tolerance, 0.0, 1.0)
        require_in_range("gap.calibration_tolerance", self.calibration_tolerance, 0.0, 1.0)
        require_in_range("gap.significance", self.significance, 1e-9, 0.5)
        require_in_range("gap.min_gap", self.min_gap, 0.0, 1.0)
        require_in_range("gap.min_share", self.min_share, 0.0, 1.0)
        require_in_range("gap.min_linear_share", self.min_linear_share, 0.0, 1.0)
        require_in_range("gap.choose_frac", self.choose_frac, 0.1, 0.9)

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any] | None) -> GapSettings:
        """Return settings from a mapping of the attribute names (missing keys keep defaults)."""
        mapping = dict(mapping or {})
        unknown = sorted(set(mapping) - set(cls.__dataclass_fields__))
        if unknown:
            raise DtwinValueError(f"gap.diagnose has unknown key(s): {', '.join(unknown)}")
        return cls(**{k: float(v) for k, v in mapping.items()})


@dataclass(frozen=True)
class ModuleReport:
    """What the diagnoser found for one module (gaps normalised as in :mod:`~.localise`).

    ``gap_calibrated``, ``threshold`` and ``n_eff`` are measured on the training and the
    choosing part together (they decide where the gap lies), ``gap_before`` on the choosing
    part (candidates' shares start from it); ``scoring_gap_before``,
    ``scoring_gap_refit`` (the twin with only its linear parameters re-fitted, source module
    only), ``scoring_gap_after`` (with the chosen effect), ``chain_gap`` and
    ``chain_gap_after`` on the scoring part (docs/gap.md §How far).
    """

    name: str
    status: str
    reason: str
    calibrated: bool = False
    gap_before: float | None = None
    gap_calibrated: float | None = None
    scoring_gap_before: float | None = None
    scoring_gap_refit: float | None = None
    scoring_gap_after: float | None = None
    chain_gap: float | None = None
    chain_gap_after: float | None = None
    noise_floor: float | None = None
    noise_floor_twin: float | None = None
    noise_floor_data: float | None = None
    threshold: float | None = None
    n_eff: float | None = None
    lin_nominal: dict[str, float] | None = None
    lin_used: dict[str, float] | None = None
    discretisation: str | None = None
    horizon_samples: int | None = None
    reference_gap: float | None = None
    discretisation_training_gap: dict[str, float] | None = None


@dataclass(frozen=True)
class CandidateReport:
    """One fitted candidate: chosen on the choosing part, scored on the scoring part.

    ``choosing_gap``, ``choosing_share_pct`` (excess removed, against the candidate's own
    floor), ``score`` and ``weight`` come from the choosing part; ``scoring_gap_after`` and the
    three shrinks (``raw_shrink_pct``, ``own_shrink_pct``, ``excess_shrink_pct`` with
    ``excess_clipped``) from the scoring part (docs/gap.md §Which, §How far).
    """

    module: str
    effect: str
    params: dict[str, float]
    lin: dict[str, float]
    n_params: int
    choosing_gap: float
    choosing_share_pct: float
    scoring_gap_after: float
    raw_shrink_pct: float
    own_shrink_pct: float
    excess_shrink_pct: float
    excess_clipped: bool
    score: float
    weight: float


@dataclass(frozen=True)
class Diagnosis:
    """The diagnosis of one recording (the content of ``diagnosis.json``).

    ``module`` is the source module or None; ``effect`` an effect name, ``"none"`` or
    ``"unexplained"``. The three shrinks (docs/gap.md §How far) are percentages on the scoring
    part, None when no effect was added: ``raw_shrink_pct`` (whole error, ``gap_before`` →
    ``gap_after``), ``own_shrink_pct`` (the effect's own share: excess of the twin with only
    its linear parameters re-fitted, ``gap_refit``, → ``gap_after``) and ``excess_shrink_pct``
    (excess over the module's one noise floor; ``excess_clipped`` when the gap after is within
    the floor, i.e. 100 %). ``also_needed`` lists the other modules with a gap of their own
    (:func:`_other_gaps`: a second effect is needed). ``twin_discretisation`` is the plant's
    discretisation the twin declares (None: chosen on the training part; the one used is
    ``modules["M1"].discretisation``). ``series`` holds scoring-part time series of the source
    module for the figure. ``free_run_rms_before`` and ``free_run_rms_after`` are RMS errors
    in the recording's units of the source module (M1 when there is none) simulated over the
    scoring part from its first sample, with the linear twin and with the chosen effect
    (:func:`_free_run_rms`; None for an integrating or unstable plant). ``param_intervals``
    gives a 95 % interval of every fitted parameter of the answer (:func:`_answer_intervals`).
    ``confidence`` is the probability that the answer is right, the winner's ``bic_weight``
    mapped by :func:`dtwin.gap.confidence.calibrated_confidence`.
    """

    module: str | None
    effect: str
    params: dict[str, float]
    confidence: float | None
    gap_before: float | None
    gap_refit: float | None
    gap_after: float | None
    raw_shrink_pct: float | None
    own_shrink_pct: float | None
    excess_shrink_pct: float | None
    excess_clipped: bool | None
    kpi_shrink_pct: float | None
    kpi_signal: str | None
    modules: dict[str, ModuleReport]
    candidates: list[CandidateReport]
    n_samples: int
    n_train: int
    n_choose: int
    dt: float
    train_frac: float
    calibrated: tuple[str, ...]
    notes: tuple[str, ...]
    settings: GapSettings
    also_needed: tuple[dict[str, Any], ...] = ()
    twin_discretisation: str | None = None
    free_run_rms_before: float | None = None
    free_run_rms_after: float | None = None
    param_intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    bic_weight: float | None = None
    series: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def shrink_pct(self) -> float | None:
        """The headline shrink: ``own_shrink_pct`` (``shrink_pct`` of ``dtwin.gap/1`` readers)."""
        return self.own_shrink_pct


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


# --- helpers ----------------------------------------------------------------------------


def _nominal_lin(name: str, twin: TwinParams) -> dict[str, float] | None:
    section = getattr(twin, module_by_name(name).section)
    if section is None:
        return None
    return {key: float(getattr(section, key)) for key in LINEAR_PARAMS[name]}


def _module_data(
    name: str, rec: Recording, t: np.ndarray, layout: _Layout, scheme: str = EULER
) -> ModuleData:
    """Return the module's recorded signals; the plant's state estimate follows ``scheme``."""
    inputs = module_inputs(name, rec.signals, rec.dt)
    module = module_by_name(name)
    output = rec.signals[module.output]
    velocity, position, lead = inputs.get("v"), None, 0
    if name == "M1":
        position, velocity, lead = plant_state_from_position(
            output, rec.dt, scheme, layout.restarts
        )
    return ModuleData(
        name,
        inputs,
        output,
        rec.dt,
        t,
        velocity,
        None,
        scheme,
        restarts=layout.restarts,
        position=position,
        lead=lead,
    )


def _scales(
    data: ModuleData,
    n_train: int,
    noise_std: float,
    lin: Mapping[str, float],
    simulated: np.ndarray | None = None,
) -> Scales:
    """Return the module's data scales; an exact plant's velocity scale from ``simulated``.

    A velocity differentiated from a noisy position sampled hundreds of times per period is
    mostly noise (its spread was 10× the plant's on rigs at 700 samples per period), which
    made the friction's smoothing velocity too wide to fit; the calibrated twin's simulated
    position (noise-free, NaN on unscored warm-up samples) differentiates cleanly.
    """
    first_input = next(iter(data.inputs.values()))[:n_train]
    output = data.output
    velocity_std = float(np.std(data.velocity)) if data.name == "M1" else 0.0
    if simulated is not None and data.name == "M1" and data.discretisation != EULER:
        with np.errstate(invalid="ignore"):
            speed = np.gradient(simulated[:n_train]) / data.dt
        if np.isfinite(speed).sum() > 10:
            velocity_std = float(np.nanstd(speed))
    return Scales(
        input_max=float(np.max(np.abs(first_input))) or 1.0,
        input_std=float(np.std(first_input)) or 1.0,
        output_std=float(np.std(output)) or 1.0,
        velocity_std=velocity_std or 1.0,
        duration=float(data.t[-1] - data.t[0]) or 1.0,
        dt=data.dt,
        noise_std=float(noise_std),
        stiffness=float(lin.get("k", 0.0)) or 1.0,
        mass=float(lin.get("m", 0.0)) or 1.0,
        output_mean=float(np.mean(output[:n_train])),
    )


def _check_inputs_vary(rec: Recording, names: list[str], n_train: int) -> None:
    for name in names:
        module = module_by_name(name)
        for signal in module.inputs:
            if signal not in rec.signals:
                continue
            values = rec.signals[signal]
            for label, part in (("recording", values), ("training part", values[:n_train])):
                spread = float(np.ptp(part))
                if spread <= 1e-12 * max(1.0, float(np.max(np.abs(part)))):
                    raise DtwinValueError(
                        f"recording column '{signal}' (input of {name}) must vary over the "
                        f"{label} (got the constant {part[0]:g}); nothing can be identified"
                    )


def _in_band_bounds(lin: Mapping[str, float], typical: Mapping[str, float], tol: float) -> dict:
    bounds = {}
    for key, value in lin.items():
        half = tol * (abs(value) if key != "bias" and value != 0 else typical[key])
        half = max(half, 1e-12 * typical[key])
        low, high = value - half, value + half
        if key == "alpha":
            low, high = max(low, 0.0), min(high, 1.0)
            if high <= low:
                low, high = max(0.0, high - 1e-9), min(1.0, low + 1e-9)
        bounds[key] = (low, high)
    return bounds


def _excess(gap: float, floor: float) -> float:
    return math.sqrt(max(gap * gap - floor * floor, 0.0))


def _shrink(before: float, after: float) -> float:
    if before <= 0:
        return 0.0
    return 100.0 * (1.0 - after / before)


def _effect_params(effect: Effect | None, fit: CandidateFit, nominal, tol) -> dict[str, float]:
    if effect is not None and effect.name != PARAMETER_MISMATCH:
        return dict(zip(effect.params, fit.theta, strict=True))
    if nominal is None:
        return dict(fit.lin)
    moved = {}
    for key, value in nominal.items():
        fitted = fit.lin[key]
        scale = abs(value) if value != 0 else 1.0
        moved[key] = abs(fitted - value) / scale
    beyond = {k: fit.lin[k] for k, r in moved.items() if r > tol}
    if not beyond and moved:
        key = max(moved, key=moved.get)
        beyond = {key: fit.lin[key]}
    return beyond


# --- the per-module analysis ----------------------------------------------------------


@dataclass(frozen=True)
class _Layout:
    """How the plant is discretised and where experiments restart.

    ``holds``: the discretisations to choose from on the training part (one: fixed by the twin
    file); ``restarts``: first samples of a separate held-out recording.
    """

    holds: tuple[str, ...]
    restarts: tuple[int, ...] = ()

    @property
    def families(self) -> list[tuple[str, ...]]:
        """The holds grouped by the plant's family: Euler alone, then the exact holds.

        The two families estimate the plant's state differently (:func:`_module_data`), so
        each is prepared on its own and the families compare their training gaps
        (:func:`_module_twin`).
        """
        exact = tuple(h for h in self.holds if h != EULER)
        return [(EULER,)] * (EULER in self.holds) + [exact] * bool(exact)


def _exact_plant_floor(data: ModuleData, simulated, lin: dict, n_train: int) -> NoiseFloor:
    """Return the exact plant's data floor: spectral noise times the window's noise gain.

    docs/gap.md §Noise floors: over windows the initial state estimated from the warm-up samples
    carries part of the measurement noise forward (:func:`~dtwin.gap.models.window_noise_gain`,
    with the noise's AR(1) pole).
    """
    residual = (data.output - simulated)[:n_train]
    # the scored samples only: the windows' unscored warm-ups (a fifth of every window) read
    # as zeros had taken a fifth off the noise's spectrum (a white floor 11 % low)
    floor = spectral_noise_floor(residual[np.isfinite(residual)], data.dt, plant_bandwidth_hz(lin))
    if data.horizon is None:
        return floor
    pole = float(floor.acf[1]) if len(floor.acf) > 1 else 0.0
    gain = window_noise_gain(lin, data.dt, data.discretisation, data.horizon, pole)
    return replace(floor, rms=floor.rms * math.sqrt(gain))


def _exact_plant_window(data, nominal, n_train, n_held) -> tuple[int, dict | None, int | None]:
    """Return the exact plant's window, its twin calibrated last and over which window.

    ``(horizon, fitted, fitted_horizon)``; ``fitted`` None for a nominal twin. When the search
    settles on the window it fitted over (``fitted_horizon == horizon``), that fit is the first
    hold's calibration (:func:`_prepare_exact_plant` does not repeat it).

    Calibration starts over the longest window (a quarter of the held-out part) and moves to
    the window of the fitted dynamics until it changes by at most ``WINDOW_SETTLED`` (at most
    ``WINDOW_ROUNDS`` fits; docs/gap.md §Gaps). A free-run start is meaningless for an
    integrating plant: it prefers a heavily damped twin that cannot drift, whose short window
    then hides the mass (a rig's mass fitted 0.15 instead of 54, window 20 instead of ~330).
    """
    if nominal is not None:
        return plant_horizon(nominal, data.dt, n_held), None, None
    horizon = max(n_held // 4, MIN_HORIZON)
    fitted = fitted_horizon = None
    for _ in range(WINDOW_ROUNDS):
        fitted, fitted_horizon = calibrate_linear(replace(data, horizon=horizon), n_train), horizon
        following = plant_horizon(fitted, data.dt, n_held)
        settled = abs(following - horizon) <= WINDOW_SETTLED * horizon
        horizon = following
        if settled:
            break
    return horizon, fitted, fitted_horizon


def _prepare_exact_plant(data, nominal, n_train, n_held, holds) -> tuple[ModuleData, dict]:
    """Choose the hold and the window of the exact plant; calibrate it when ``nominal`` is None.

    The window comes from the first hold (:func:`_exact_plant_window`); each hold is fitted over
    it (a nominal twin: evaluated), the later ones starting from the first hold's delay, and the
    one with the smaller training simulation error is kept (docs/gap.md §Modules). The first
    hold's fit of the window search is kept when it was over the same window (the same fit
    again cost a third of a 130,000-sample rig's calibration, docs/gap.md §Speed).
    """
    first = replace(data, discretisation=holds[0])
    horizon, start, fitted_horizon = _exact_plant_window(first, nominal, n_train, n_held)
    best = None
    for hold in holds:
        trial = replace(data, discretisation=hold, horizon=horizon)
        if nominal is not None:
            lin = dict(nominal)
        elif hold == holds[0] and fitted_horizon == horizon:
            lin = start
        else:
            near = None if start is None else int(start["delay_samples"])
            lin = calibrate_linear(trial, n_train, delay_near=near)
            start = lin
        fitted = fit_candidate(trial, None, lin, n_train=n_train, free=[])
        logger.debug("M1 %s: training RMS %.4g, window %s", hold, fitted.train_rms, horizon)
        if best is None or fitted.train_rms < best[0]:
            best = (fitted.train_rms, trial, fitted.lin)
    return best[1], best[2]


@dataclass(frozen=True)
class _Split:
    """The three parts of a recording (docs/gap.md §Interface).

    Training ``[0, n_train)``, choosing ``[n_train, n_choose)``, scoring ``[n_choose, n)``.
    """

    n_train: int
    n_choose: int
    n: int

    @property
    def choose(self) -> slice:
        """The choosing part: every decision (where, which, ``unexplained``)."""
        return slice(self.n_train, self.n_choose)

    @property
    def decide(self) -> slice:
        """Where the gap lies: the training and the choosing part (all before scoring)."""
        return slice(0, self.n_choose)

    @property
    def score(self) -> slice:
        """The scoring part: every reported gap after an effect and every shrink."""
        return slice(self.n_choose, self.n)


@dataclass
class _ModuleWork:
    name: str
    data: ModuleData
    calibrated: bool
    lin_nominal: dict[str, float] | None
    lin_base: dict[str, float]
    norm: float
    sim_before: np.ndarray
    gap_before: float
    gap_scored: float
    floor: NoiseFloor
    floor_twin: float | None
    floor_data: float
    gap_cal: float
    threshold: float
    n_eff: float
    candidates: list[_Fitted] = field(default_factory=list)
    reference_gap: float | None = None
    tried: dict[str, float] | None = None


@dataclass(frozen=True)
class _Fitted:
    """A fitted candidate: its prediction ``(n_samples,)`` and its choosing/scoring gaps."""

    effect: Effect
    fit: CandidateFit
    predicted: np.ndarray
    gap_choose: float
    gap_score: float


def _analyse_module(name, rec, twin, t, split: _Split, calibrate, settings, layout):
    """Return the module's :class:`_ModuleWork`: its twin, floors, gaps and threshold.

    The gap and threshold that decide where the gap lies are those of all data before the
    scoring part (training and choosing: a linear re-fit of a few parameters is barely biased
    in-sample, and a third of the data made faint effects read ``none``); candidates are
    compared on the choosing part; the gap the shrinks start from is the scoring part's
    (docs/gap.md §Where).
    """
    n_train = split.n_train
    nominal = _nominal_lin(name, twin)
    calibrated = calibrate or nominal is None
    start = None if calibrated else nominal
    data, lin_base, tried = _module_twin(name, rec, t, n_train, (nominal, start), settings, layout)
    norm = float(np.std(data.output)) or 1.0
    sim_before = simulate_module(data, lin_base)
    if data.discretisation != EULER:
        floor_data = _exact_plant_floor(data, sim_before, lin_base, n_train)
    else:
        floor_data = data_noise_floor(name, data.inputs, data.output, sim_before, lin_base, rec.dt)
    floor_twin = (
        twin_noise_floor(name, twin.noise, lin_base, rec.dt) if twin.noise is not None else None
    )
    floor = reconcile_noise_floor(floor_twin, floor_data, settings.noise_tolerance)
    data = replace(data, scales=_scales(data, n_train, floor.rms, lin_base, sim_before))
    gap_before = normalised_rms(data.output, sim_before, split.choose, norm)
    gap_cal = normalised_rms(data.output, sim_before, split.decide, norm)
    if not calibrated:
        in_band = _in_band_lin(data, lin_base, n_train, settings.calibration_tolerance)
        in_band_sim = simulate_module(data, in_band)
        gap_cal = min(gap_cal, normalised_rms(data.output, in_band_sim, split.decide, norm))
    n_eff = effective_samples(floor.acf, split.n_choose)
    threshold = gap_threshold(
        floor.rms / norm,
        n_eff,
        noise_tolerance=settings.noise_tolerance,
        significance=settings.significance,
        min_gap=settings.min_gap,
    )
    return _ModuleWork(
        name,
        data,
        calibrated,
        nominal,
        lin_base,
        norm,
        sim_before,
        gap_before,
        normalised_rms(data.output, sim_before, split.score, norm),
        floor,
        floor_twin.rms / norm if floor_twin is not None else None,
        floor_data.rms / norm,
        gap_cal,
        threshold,
        n_eff,
        tried=tried,
    )


def _in_band_lin(data: ModuleData, lin: dict, n_train: int, tolerance: float) -> dict:
    """Return the linear parameters re-fitted within ``tolerance`` of ``lin`` (§Where)."""
    typical = linear_typical(data.name, lin, data.scales)
    bounds = _in_band_bounds(lin, typical, tolerance)
    fitted = fit_candidate(data, None, lin, n_train=n_train, free=list(bounds), lin_bounds=bounds)
    return fitted.lin


def _module_twin(name, rec, t, n_train, twins, settings, layout) -> tuple:
    """Return ``(data, lin_base, tried)``: the module's data and linear twin before any effect.

    ``twins`` is ``(nominal, start)``: the twin file's linear parameters (None if absent; they
    set the provisional scales) and those to use (None: calibrated on the training part). The
    plant is prepared once per family of :attr:`_Layout.families` (exact holds: the best of them,
    :func:`_prepare_exact_plant`); with two families (a twin file that declares no
    discretisation) the one with the smaller training gap (:func:`_family_gaps`) is kept and
    ``tried`` maps each family's discretisation to that gap (docs/gap.md §Twin file);
    otherwise ``tried`` is None. A plant calibrated from data has no parameters whose meaning
    depends on the discretisation, so it is prepared with the exact holds alone: the Euler
    plant's data floor (process noise read from one-step errors) takes a calibrated twin's
    unmodelled force for noise (floors of 0.8–6 times the position's spread on rigs at
    80–1000 samples per period, which then read ``none`` with strong effects).
    """
    nominal, start = twins
    families = layout.families if name == "M1" else [(EULER,)]
    if start is None and len(families) > 1:
        families = families[1:]  # calibrated from data: the exact holds (docs/gap.md §Twin file)
    prepared = []
    for holds in families:
        data = _module_data(name, rec, t, layout, holds[0])
        data = replace(data, scales=_scales(data, n_train, 0.0, nominal or {}))
        if holds[0] != EULER:
            n_held = rec.n_samples - n_train
            prepared.append(_prepare_exact_plant(data, start, n_train, n_held, holds))
        elif start is None:
            prepared.append((data, calibrate_linear(data, n_train)))
        else:
            prepared.append((data, dict(start)))
    if len(prepared) == 1:
        return (*prepared[0], None)
    tolerance = None if start is None else settings.calibration_tolerance
    gaps = _family_gaps(prepared, n_train, tolerance)
    tried = {data.discretisation: gap for (data, _), gap in zip(prepared, gaps, strict=True)}
    data, lin = prepared[int(np.argmin(gaps))]
    return data, lin, tried


def _family_gaps(prepared, n_train: int, tolerance: float | None) -> list[float]:
    """Return each family's normalised RMS training error, over the same windows and samples.

    Every family is run over the windows of the windowed one (each restarted from the
    recording; the Euler twin from its own state estimate) and scored on the samples all
    of them score, so that neither a free run's drift nor a window's warm-up favours one. A
    nominal twin is first re-fitted within ``tolerance`` of its parameters
    (:func:`_in_band_lin`): the calibration slack the gap's location ignores too (§Where).
    """
    horizons = [data.horizon for data, _ in prepared if data.horizon is not None]
    windows = None
    if horizons:
        windows = plant_windows(n_train, horizons[0], prepared[0][0].restarts)
    sims = []
    for data, lin in prepared:
        if tolerance is not None:
            lin = _in_band_lin(data, lin, n_train, tolerance)
        segments = windows if data.discretisation == EULER else None
        sims.append(simulate_module(data, lin, stop=n_train, segments=segments))
    output = prepared[0][0].output[:n_train]
    scored = np.logical_and.reduce([np.isfinite(sim) for sim in sims])
    norm = float(np.std(prepared[0][0].output)) or 1.0
    if not scored.any():
        return [math.inf] * len(sims)
    return [float(np.sqrt(np.mean((output - sim)[scored] ** 2))) / norm for sim in sims]


def _finite(gap: float) -> float:
    return gap if math.isfinite(gap) else math.inf


def _fit_candidates(work: _ModuleWork, split: _Split) -> None:
    start = work.lin_base
    for effect in effects_for_module(work.name, include_mismatch=not work.calibrated):
        fitted = fit_candidate(work.data, effect, start, n_train=split.n_train)
        if effect.name == PARAMETER_MISMATCH:
            start = fitted.lin  # the effects start from the re-fitted linear twin
        predicted = simulate_module(work.data, fitted.lin, effect, fitted.theta)
        gaps = [
            _finite(normalised_rms(work.data.output, predicted, part, work.norm))
            for part in (split.choose, split.score)
        ]
        work.candidates.append(_Fitted(effect, fitted, predicted, *gaps))
        logger.debug("%s %s: choosing/scoring gap %.4g/%.4g", work.name, effect.name, *gaps)


def _quantizer_floor_and_deviance(work: _ModuleWork, fitted: CandidateFit, held: slice):
    """Return a quantizer candidate's noise floor and deviance over ``held`` (normalised units).

    ``held`` is the choosing part: both serve the choice only, never a reported shrink (which
    uses the module's one floor). A quantizer after noise makes part of the noise
    unpredictable: its variance is the floor of this candidate
    (:func:`~dtwin.gap.effects.quantization_variance`). Its deviance is ``−2·mean log p(y)``
    of the quantizer's own density
    (:func:`~dtwin.gap.effects.quantizer_log_density`) less ``log(2π) + 1``, on the scale of a
    Gaussian candidate's ``log(mse)``: values on a lattice are then evidence for it even when
    its mean prediction is no better (docs/gap.md §Which). The noise after the quantizer is
    what the module's noise leaves beyond the noise before it, at least ``q/100``.
    """
    step, offset, before = fitted.theta
    noise = work.floor.rms
    clean = simulate_module(work.data, fitted.lin)[held]
    extra = quantization_variance(clean - offset, step, before)
    floor = math.sqrt(max(noise**2 - before**2, 0.0) + extra) / work.norm
    if not step > 0:
        return floor, math.log(max(float(np.mean((work.data.output[held] - clean) ** 2)), 1e-300))
    after = max(math.sqrt(max(noise**2 - before**2, 0.0)), step / 100.0)
    log_p = quantizer_log_density(work.data.output[held], clean, step, offset, before, after)
    deviance = -2.0 * float(np.mean(log_p)) - 2.0 * math.log(work.norm)
    return floor, deviance - math.log(2 * math.pi) - 1.0


def _linear_refit_gap(work: _ModuleWork) -> float:
    """Return the scoring-part gap of the twin with only its linear parameters re-fitted.

    That is the ``parameter_mismatch`` fit (every linear parameter free, same training part);
    a module calibrated from data has no such candidate: its linear twin is already fitted
    freely on the training part (docs/gap.md §How far).
    """
    for fitted in work.candidates:
        if fitted.effect.name == PARAMETER_MISMATCH:
            return fitted.gap_score
    return work.gap_scored


def _three_shrinks(work: _ModuleWork, effect: str, gap_after: float, refit: float) -> tuple:
    """Return ``(raw, own, excess, clipped)``: the three shrinks (%) on the scoring part.

    ``own`` compares with the linear re-fit ``refit`` (the twin as given for
    ``parameter_mismatch``, which is that re-fit); ``excess`` uses the module's one noise floor
    for every candidate; ``clipped`` when the gap after is within it (docs/gap.md §How far).
    """
    floor = work.floor.rms / work.norm
    before = work.gap_scored
    reference = before if effect == PARAMETER_MISMATCH else refit
    excess_after = _excess(gap_after, floor)
    return (
        _shrink(before, gap_after),
        _shrink(_excess(reference, floor), excess_after),
        _shrink(_excess(before, floor), excess_after),
        bool(gap_after <= floor),
    )


def _score_candidates(work: _ModuleWork, split: _Split, settings: GapSettings):
    """Return the module's :class:`CandidateReport` list, best (lowest choosing score) first.

    ``score = n_eff·deviance + n_params·ln(n_eff)`` on the choosing part (docs/gap.md §Which);
    the shrinks on the scoring part (§How far).
    """
    n_eff = work.n_eff
    floor = work.floor.rms / work.norm
    excess_choose = _excess(work.gap_before, floor)
    refit = _linear_refit_gap(work)
    tolerance = settings.calibration_tolerance
    reports = []
    for fitted in work.candidates:
        effect, fit, gap = fitted.effect, fitted.fit, fitted.gap_choose
        floor_c = floor
        deviance = math.log(max(gap * gap, 1e-300))  # a Gaussian's, less log(2π) + 1
        if effect.name == "sensor_quantization":
            floor_c, deviance = _quantizer_floor_and_deviance(work, fit, split.choose)
        score = n_eff * deviance + fit.n_free * math.log(max(n_eff, 2.0))
        raw, own, excess, clipped = _three_shrinks(work, effect.name, fitted.gap_score, refit)
        reports.append(
            CandidateReport(
                module=work.name,
                effect=effect.name,
                params=_effect_params(effect, fit, work.lin_nominal, tolerance),
                lin=dict(fit.lin),
                n_params=fit.n_free,
                choosing_gap=gap,
                choosing_share_pct=_shrink(excess_choose, _excess(gap, floor_c)),
                scoring_gap_after=fitted.gap_score,
                raw_shrink_pct=raw,
                own_shrink_pct=own,
                excess_shrink_pct=excess,
                excess_clipped=clipped,
                score=score,
                weight=0.0,
            )
        )
    if not reports:  # a calibrated M3 or M4: no candidate once parameter_mismatch is out
        return []
    best = min(r.score for r in reports)
    weights = np.array([math.exp(-(r.score - best) / 2.0) for r in reports])
    weights /= weights.sum()
    reports = [
        replace(r, score=r.score - best, weight=float(w))
        for r, w in zip(reports, weights, strict=True)
    ]
    return sorted(reports, key=lambda r: r.score)


# --- the steps of the entry point ------------------------------------------------------


#: Fewest samples of the training part, and of the choosing and the scoring part.
MIN_TRAIN_SAMPLES, MIN_PART_SAMPLES = 100, 50


def _check_arguments(recording, twin, train_frac, heldout, choose_frac) -> tuple:
    """Validate the arguments of :func:`diagnose`; return ``(train_frac, n_train, n_choose)``.

    ``n_train`` samples from the start are the training part; the choosing part ends at
    ``n_choose`` (the ``choose_frac`` share of the rest; with a separate held-out recording,
    the whole rest of the recording: the held-out recording is the scoring part)
    (docs/gap.md §Interface).
    """
    if not isinstance(recording, Recording):
        raise DtwinTypeError(f"recording must be a Recording (got {type(recording).__name__})")
    if not isinstance(twin, TwinParams):
        raise DtwinTypeError(f"twin must be TwinParams (got {type(twin).__name__})")
    if heldout is not None and not isinstance(heldout, Recording):
        raise DtwinTypeError(f"heldout must be a Recording (got {type(heldout).__name__})")
    train_frac = require_in_range("train_frac", train_frac, 0.05, 0.95)
    for label, rec in (("recording", recording), ("held-out recording", heldout)):
        if rec is not None and abs(rec.dt - twin.dt) > DT_TOLERANCE * twin.dt:
            raise DtwinValueError(
                f"{label} dt ({rec.dt:.6g} s, from column 't') disagrees with twin.dt "
                f"({twin.dt:.6g} s) by more than {DT_TOLERANCE:.0%}"
            )
    n = recording.n_samples
    n_train = int(round(train_frac * n))
    if heldout is not None:
        n_choose, n_score = n - n_train, heldout.n_samples
    else:
        n_choose = int(round(choose_frac * (n - n_train)))
        n_score = n - n_train - n_choose
    if n_train < MIN_TRAIN_SAMPLES or min(n_choose, n_score) < MIN_PART_SAMPLES:
        raise DtwinValueError(
            f"train_frac must leave at least {MIN_TRAIN_SAMPLES} samples for training and "
            f"{MIN_PART_SAMPLES} each for choosing and for scoring (got {n_train}, {n_choose} "
            f"and {n_score}{'; the scoring part is the held-out recording' if heldout else ''})"
        )
    return train_frac, n_train, n_train + n_choose


def join_heldout(
    recording: Recording, n_train: int, heldout: Recording, names: list[str]
) -> Recording:
    """Return the first ``n_train`` samples of ``recording`` followed by the held-out recording.

    :func:`diagnose` keeps the whole first recording (its training and choosing parts); the
    held-out recording is the scoring part.

    Parameters
    ----------
    recording : Recording
        The first experiment; its first ``n_train`` samples are kept.
    n_train : int
        Number of samples kept.
    heldout : Recording
        The validation experiment; it must record every signal of the diagnosed ``names``.
    names : list of str
        The modules diagnosed on ``recording``.

    Returns
    -------
    Recording
        Shape ``(n_train + heldout.n_samples,)`` per signal; the held-out time continues the
        training time by one ``dt``. Every model restarts from the recorded state at sample
        ``n_train`` (a new experiment).
    """
    needed = sorted(
        {s for m in MODULES if m.name in names for s in (*m.inputs, m.output)}
        & set(recording.signals)
    )
    missing = [s for s in needed if s not in heldout.signals]
    if missing:
        raise DtwinValueError(
            f"held-out recording is missing column(s) {', '.join(missing)} "
            f"(the training recording has: {', '.join(needed)})"
        )
    t_held = recording.t[n_train - 1] + recording.dt + (heldout.t - heldout.t[0])
    signals = {
        s: np.concatenate([recording.signals[s][:n_train], heldout.signals[s]]) for s in needed
    }
    return Recording(
        t=np.concatenate([recording.t[:n_train], t_held]),
        dt=recording.dt,
        signals=signals,
        ignored=recording.ignored,
        time_resolution=recording.time_resolution,
    )


def _module_notes(works: Mapping[str, _ModuleWork], calibrate: bool) -> list[str]:
    """Return the report's notes on calibrated modules and on data vs twin noise floors."""
    notes = []
    for work in works.values():
        if work.tried is not None:
            others = ", ".join(
                f"{hold} {gap:.4g}"
                for hold, gap in work.tried.items()
                if hold != work.data.discretisation
            )
            notes.append(
                f"{work.name}: the twin file declares no discretisation; "
                f"{work.data.discretisation} fits the training part best (training gap "
                f"{work.tried[work.data.discretisation]:.4g}; {others})"
            )
        if work.calibrated:
            why = "--calibrate" if calibrate else "no nominal parameters in the twin file"
            notes.append(f"{work.name}: linear twin fitted on the training part ({why})")
        if work.reference_gap is not None:
            notes.append(
                f"{work.name}: scoring-part gap of the calibrated linear twin "
                f"{work.gap_scored:.4g} ({work.data.discretisation}, windows of "
                f"{work.data.horizon} samples); a plain output-error fit OE(nb=3, nf=2) on the "
                f"same split and windows: {work.reference_gap:.4g}"
            )
        if work.floor_twin is not None and work.floor_twin > 0:
            ratio = work.floor_data / work.floor_twin
            if not 0.67 <= ratio <= 1.5:
                notes.append(
                    f"{work.name}: noise floor estimated from the data is {ratio:.2f}× the "
                    "twin's (coloured noise, or a high-frequency effect)"
                )
    return notes


def _choose(flagged: list[_ModuleWork], ranked: Mapping[str, list], settings: GapSettings):
    """Return ``(source, chosen)``: the source module's work and its winning candidate.

    The source is the flagged module furthest above its threshold (``gap_cal/threshold``);
    ``chosen`` is its best-scored candidate if that removes at least its required share of the
    choosing part's excess gap (:func:`required_share`), else None (docs/gap.md §Which). Both
    are None when nothing is flagged. Every number used here is the choosing part's.
    """
    source = max(flagged, key=lambda w: w.gap_cal / w.threshold) if flagged else None
    chosen = None
    if source is not None:
        if not ranked[source.name]:
            return source, None
        best = _plain_over_nesting(ranked[source.name])
        chosen = best if _clears_bar(best, settings) else None
    return source, chosen


#: Share of the choosing excess (percentage points) a candidate must remove beyond a candidate
#: it nests (``Effect.nests``) to be chosen over it (docs/gap.md §Which).
NEST_MARGIN_PCT = 5.0


def _plain_over_nesting(ranked: Sequence[CandidateReport]) -> CandidateReport:
    """Return the best candidate, or the plain one it nests if that removes nearly as much.

    Stribeck friction with its breakaway force equal to its sliding one is Coulomb friction:
    with many effective samples the score prefers the wider form for any small mismatch of
    shape (a sharper sign), not for a bump. The plain form is kept unless the wider one removes
    :data:`NEST_MARGIN_PCT` more of the choosing excess; it then carries both weights.
    """
    best = ranked[0]
    for name in effect_by_name(best.effect).nests:
        plain = next((r for r in ranked if r.effect == name), None)
        if (
            plain is not None
            and best.choosing_share_pct - plain.choosing_share_pct < NEST_MARGIN_PCT
        ):
            return replace(plain, weight=plain.weight + best.weight)
    return best


def _clears_bar(candidate, settings: GapSettings) -> bool:
    """Return whether ``candidate`` removes its :func:`required_share` of the choosing gap."""
    return candidate.choosing_share_pct >= 100 * required_share(candidate.effect, settings)


def _other_gaps(
    flagged: Sequence[_ModuleWork],
    source: _ModuleWork | None,
    ranked: Mapping[str, list],
    settings: GapSettings,
) -> tuple[dict[str, Any], ...]:
    """Return the flagged modules other than the source: where a second effect is needed.

    Each is ``{module, effect, choosing_share_pct, gap_over_threshold}``, furthest above its
    threshold first: ``effect`` is the module's best-scored candidate if it clears
    :func:`required_share` on the choosing part (as the source's answer must), else
    ``unexplained``. The answer itself is unchanged: it names the larger effect and these
    say when two are needed (docs/gap.md, arm (g)).
    """
    others = sorted((w for w in flagged if w is not source), key=lambda w: -w.gap_cal / w.threshold)
    found = []
    for work in others:
        best = ranked[work.name][0] if ranked.get(work.name) else None
        explained = best is not None and _clears_bar(best, settings)
        found.append(
            {
                "module": work.name,
                "effect": best.effect if explained else UNEXPLAINED,
                "choosing_share_pct": None if best is None else float(best.choosing_share_pct),
                "gap_over_threshold": float(work.gap_cal / work.threshold),
            }
        )
    return tuple(found)


def required_share(effect: str, settings: GapSettings) -> float:
    """Return the share of the excess gap candidate ``effect`` must remove to be the answer.

    ``min_linear_share`` for a candidate of linear form (``Effect.linear_form``: inside the
    twin's own model class, exact when right), ``min_share`` for the others, whose forms may
    only approximate a measured effect (docs/gap.md §Which).
    """
    linear = effect_by_name(effect).linear_form
    return settings.min_linear_share if linear else settings.min_share


def _chain_before_after(rec, twin, works, t, source, chosen) -> tuple[dict, dict]:
    """Return the chain's signals before and after the chosen effect is added.

    *Before* runs every module with its nominal (or calibrated) linear twin; *after* adds the
    chosen candidate to the source module (the same signals as *before* when nothing is
    chosen). Each signal has shape ``(n_samples,)`` (docs/gap.md §How far).
    """
    scales = {name: w.data.scales for name, w in works.items()}
    layouts = {name: w.data for name, w in works.items()}
    models = {}
    for module in MODULES:
        if module.name in works:
            models[module.name] = ModuleModel(works[module.name].lin_base)
        else:
            nominal = _nominal_lin(module.name, twin)
            if nominal is not None:
                models[module.name] = ModuleModel(nominal)
    chain_before = run_chain(rec.signals, models, rec.dt, t, scales, layouts)
    chain_after = chain_before
    if chosen is not None:
        fitted = next(f for f in source.candidates if f.effect.name == chosen.effect)
        models_after = dict(models)
        models_after[source.name] = ModuleModel(fitted.fit.lin, fitted.effect, fitted.fit.theta)
        chain_after = run_chain(rec.signals, models_after, rec.dt, t, scales, layouts)
    return chain_before, chain_after


def _kpi_shrink(rec, chain_before, chain_after, source, chosen, scored, notes) -> tuple:
    """Return ``(kpi_signal, kpi_shrink_pct)`` on the scoring part; may append to ``notes``.

    The KPI signal is the most downstream recorded signal the chain simulates (``z`` first);
    its shrink is None when no effect was chosen or the source is not upstream of it.
    """
    kpi_signal = None
    for signal in ("z", "y_fused", "y_A", "y_B", "x", "u_act"):
        if signal in rec.signals and signal in chain_before:
            kpi_signal = signal
            break
    kpi_shrink = None
    if chosen is not None and kpi_signal is not None:
        if source.name in upstream_modules(kpi_signal):
            recorded = rec.signals[kpi_signal]
            norm = float(np.std(recorded)) or 1.0
            before = normalised_rms(recorded, chain_before[kpi_signal], scored, norm)
            after = normalised_rms(recorded, chain_after[kpi_signal], scored, norm)
            kpi_shrink = _shrink(before, after)
        else:
            notes.append(f"{source.name} is not upstream of the end-to-end signal {kpi_signal}")
    return kpi_signal, kpi_shrink


def _status(work: _ModuleWork, flagged, source, chain_gap: float | None) -> tuple[str, str]:
    """Return ``(status, reason)`` of an analysed module (docs/gap.md §Statuses)."""
    if work in flagged:
        status = "source" if work is source else "gap"
        return status, (
            f"gap {work.gap_cal:.3g} after in-tolerance calibration exceeds the noise "
            f"threshold {work.threshold:.3g}"
        )
    if chain_gap is not None and chain_gap > 2 * max(work.gap_before, work.threshold):
        return "inherited", (
            f"local gap {work.gap_before:.3g} is within noise; chain gap {chain_gap:.3g} "
            "comes from upstream"
        )
    return "clean", f"gap {work.gap_cal:.3g} within the noise threshold {work.threshold:.3g}"


def _skipped_report(module, rec: Recording) -> ModuleReport:
    """Return the report of a module whose input or output column is missing."""
    missing = [
        s
        for s in (*module.inputs, module.output)
        if s not in rec.signals and not (module.name == "M4" and s == "v")
    ]
    return ModuleReport(
        module.name, "skipped", f"column(s) not in the recording: {', '.join(missing)}"
    )


def _module_reports(rec, works, flagged, source, chosen, chains, split: _Split) -> dict:
    """Return one :class:`ModuleReport` per module of the wiring table, in its order.

    ``chains`` is ``(chain_before, chain_after)`` from :func:`_chain_before_after`; the status
    compares the choosing part's chain gap, the reported chain gaps are the scoring part's.
    """
    chain_before, chain_after = chains
    modules = {}
    for module in MODULES:
        name = module.name
        if name not in works:
            modules[name] = _skipped_report(module, rec)
            continue
        work = works[name]
        out = module.output
        chain_choose = chain_gap = chain_gap_after = None
        if out in chain_before:
            chain_choose = normalised_rms(
                work.data.output, chain_before[out], split.choose, work.norm
            )
            chain_gap = normalised_rms(work.data.output, chain_before[out], split.score, work.norm)
            chain_gap_after = normalised_rms(
                work.data.output, chain_after[out], split.score, work.norm
            )
        gap_after = refit = None
        if source is not None and name == source.name and chosen is not None:
            gap_after, refit = chosen.scoring_gap_after, _linear_refit_gap(work)
        status, reason = _status(work, flagged, source, chain_choose)
        modules[name] = ModuleReport(
            name,
            status,
            reason,
            work.calibrated,
            work.gap_before,
            work.gap_cal,
            work.gap_scored,
            refit,
            gap_after,
            chain_gap,
            chain_gap_after,
            work.floor.rms / work.norm,
            work.floor_twin,
            work.floor_data,
            work.threshold,
            work.n_eff,
            work.lin_nominal,
            work.lin_base,
            work.data.discretisation if name == "M1" else None,
            work.data.horizon,
            work.reference_gap,
            work.tried,
        )
    return modules


def _scoring_series(rec: Recording, source, ranked, scored: slice) -> dict[str, np.ndarray]:
    """Return the source module's scoring-part series for the figure, each ``(n_scored,)``.

    Keys ``t`` (s), ``recorded``, ``before`` (the twin) and ``after`` (the best candidate);
    empty when there is no source.
    """
    if source is None:
        return {}
    series = {
        "t": rec.t[scored],
        "recorded": source.data.output[scored],
        "before": source.sim_before[scored],
    }
    if not ranked[source.name]:
        return series
    best = ranked[source.name][0].effect
    series["after"] = next(f.predicted for f in source.candidates if f.effect.name == best)[scored]
    return series


def _free_run_rms(works: Mapping[str, _ModuleWork], source, chosen, split: _Split) -> dict:
    """Return ``free_run_rms_before`` and ``free_run_rms_after`` (recording units) as a dict.

    The source module's twin (M1's when there is no source; neither: both None) is run freely
    over the scoring part from the recorded state at its first sample (no windows), with its
    linear twin (calibrated, or the twin file's) and with the chosen effect (None when no
    effect is chosen); each value is the RMS of recorded − simulated over the scoring part's
    simulated samples, in the output's units, comparable to a published free-run simulation
    error. A plant that is not strictly stable (``k = 0``: integrating, or ``c ≤ 0``) has no
    free-run error worth reporting (its position drifts with any force error): both None
    (docs/gap.md §How far).
    """
    work = source if source is not None else works.get("M1")
    none = {"free_run_rms_before": None, "free_run_rms_after": None}
    if work is None or (work.name == "M1" and not _strictly_stable(work.lin_base)):
        return none
    restarts = tuple(sorted({*work.data.restarts, split.n_choose}))
    data = replace(work.data, horizon=None, restarts=restarts)
    runs = {"free_run_rms_before": simulate_module(data, work.lin_base)}
    if chosen is not None and work is source:
        fitted = next(f for f in work.candidates if f.effect.name == chosen.effect)
        runs["free_run_rms_after"] = simulate_module(
            data, fitted.fit.lin, fitted.effect, fitted.fit.theta
        )
    return none | {key: _rms(data.output, sim, split.score) for key, sim in runs.items()}


def _answer_intervals(source, chosen, split: _Split) -> dict[str, tuple[float, float]]:
    """Return the 95 % interval of each of the answer's parameters (docs/gap.md §Intervals).

    Those of ``params``, and for ``parameter_mismatch`` every re-fitted linear parameter
    (:func:`dtwin.gap.intervals.parameter_intervals`); empty without a chosen effect.
    """
    if chosen is None:
        return {}
    fitted = next(f for f in source.candidates if f.effect.name == chosen.effect)
    intervals = parameter_intervals(
        source.data,
        fitted.effect,
        fitted.fit.lin,
        fitted.fit.theta,
        split.n_train,
        other_part=(split.n_train, split.n_choose),
    )
    if chosen.effect == PARAMETER_MISMATCH:
        return intervals
    return {name: value for name, value in intervals.items() if name in chosen.params}


def _strictly_stable(lin: Mapping[str, float]) -> bool:
    """Return whether the plant ``m·ẍ + c·ẋ + k·x = u`` is strictly stable (m, c, k > 0)."""
    return all(float(lin.get(key, 0.0)) > 0 for key in ("m", "c", "k"))


def _rms(recorded: np.ndarray, simulated: np.ndarray, part: slice) -> float | None:
    """Return RMS(recorded − simulated) over ``part``'s finite samples (None if there are none)."""
    error = (recorded - simulated)[part]
    error = error[np.isfinite(error)]
    return float(np.sqrt(np.mean(error**2))) if len(error) else None


def _verdict(source, chosen) -> dict[str, Any]:
    """Return the answer's fields of :class:`Diagnosis` (module to ``excess_clipped``).

    ``none`` without a source, ``unexplained`` with a source but no chosen candidate
    (docs/gap.md §Statuses); the gaps and shrinks are the scoring part's.
    """
    verdict = dict.fromkeys(
        ("gap_before", "gap_refit", "gap_after", "raw_shrink_pct", "own_shrink_pct"), None
    )
    verdict.update(excess_shrink_pct=None, excess_clipped=None, params={}, confidence=None)
    verdict.update(bic_weight=None)
    if source is None:
        return {**verdict, "module": None, "effect": NONE}
    if chosen is None:
        return {**verdict, "module": source.name, "effect": UNEXPLAINED}
    return {
        "module": source.name,
        "effect": chosen.effect,
        "params": chosen.params,
        "confidence": calibrated_confidence(chosen.weight),
        "bic_weight": chosen.weight,
        "gap_before": source.gap_scored,
        "gap_refit": _linear_refit_gap(source),
        "gap_after": chosen.scoring_gap_after,
        "raw_shrink_pct": chosen.raw_shrink_pct,
        "own_shrink_pct": chosen.own_shrink_pct,
        "excess_shrink_pct": chosen.excess_shrink_pct,
        "excess_clipped": chosen.excess_clipped,
    }


# --- the entry point -----------------------------------------------------------------


def diagnose(
    recording: Recording,
    twin: TwinParams,
    *,
    calibrate: bool = False,
    train_frac: float = 0.5,
    settings: GapSettings | None = None,
    discretisation: str | None = None,
    heldout: Recording | None = None,
) -> Diagnosis:
    """Diagnose the sim-to-real gap of a recording against a twin.

    Parameters
    ----------
    recording : Recording
        The validated recording (:func:`dtwin.gap.recording.read_recording`).
    twin : TwinParams
        The twin (:func:`twin_from_mapping`); sections may be None (calibrated from data).
    calibrate : bool, default False
        Fit every diagnosed module's linear twin on the training part first.
    train_frac : float, default 0.5
        Fraction of samples, from the start, used for fitting (the training part); of the
        rest, the first ``settings.choose_frac`` is the choosing part (every decision), the
        remainder the scoring part (every reported gap after an effect and every shrink).
    settings : GapSettings, optional
        Decision constants.
    discretisation : {"euler", "zoh", "foh", "bandlimited"}, optional
        The plant's discretisation; default ``twin.discretisation`` (the twin file's). When
        both are None, the one of the four whose linear twin fits the training part best
        (``Diagnosis.twin_discretisation`` is then None, ``modules["M1"].discretisation``
        the one used).
    heldout : Recording, optional
        A separate validation experiment: the scoring part. The first ``round(train_frac·n)``
        samples of ``recording`` are the training part, the rest of it the choosing part.

    Returns
    -------
    Diagnosis

    Raises
    ------
    DtwinValueError
        If ``twin.dt`` disagrees with the recording's by more than 1 %, the split leaves fewer
        than 100 training samples or fewer than 50 for choosing or for scoring, or a module
        input is constant.

    Notes
    -----
    The three steps (where, which, how far) are specified in docs/gap.md §Where, §Which and
    §How far. BLAS runs single-threaded here: the diagnoser's matrices are 2×2 to 4×4, for
    which threads cost more than 100× the arithmetic on a loaded machine.
    """
    with threadpool_limits(limits=1):
        return _diagnose(recording, twin, calibrate, train_frac, settings, discretisation, heldout)


def _diagnose(recording, twin, calibrate, train_frac, settings, discretisation, heldout):
    """Run :func:`diagnose` (same arguments) with the thread limit set."""
    settings = settings or GapSettings()
    train_frac, n_train, n_choose = _check_arguments(
        recording, twin, train_frac, heldout, settings.choose_frac
    )
    discretisation = discretisation or twin.discretisation
    holds = (EULER, *EXACT_HOLDS) if discretisation is None else (discretisation,)
    layout = _Layout(holds)
    names = diagnosable_modules(recording.signals)
    _check_inputs_vary(recording, names, n_train)
    if heldout is not None:
        recording = join_heldout(recording, n_choose, heldout, names)
        layout = _Layout(holds, (n_choose,))
    n = recording.n_samples
    split = _Split(n_train, n_choose, n)
    t = recording.t - recording.t[0]
    notes: list[str] = []
    if recording.ignored:
        notes.append(f"ignored columns that are not module signals: {', '.join(recording.ignored)}")

    works = {}
    for name in names:
        progress.info("%s: linear twin and noise floor (%d samples)", name, n)
        works[name] = _analyse_module(name, recording, twin, t, split, calibrate, settings, layout)
    for work in works.values():
        if work.name == "M1" and work.calibrated and work.data.discretisation != EULER:
            reference = output_error_reference(
                work.data, int(work.lin_base.get("delay_samples", 0)), n_train
            )
            work.reference_gap = normalised_rms(work.data.output, reference, split.score, work.norm)
            # a gap a plain linear OE fit removes is calibration slack (docs/gap.md §Where)
            reached = normalised_rms(work.data.output, reference, split.decide, work.norm)
            work.gap_cal = min(work.gap_cal, reached) if np.isfinite(reached) else work.gap_cal
    notes.extend(_module_notes(works, calibrate))
    flagged = [w for w in works.values() if w.gap_cal > w.threshold]
    for work in flagged:
        progress.info("%s: fitting the candidate effects", work.name)
        _fit_candidates(work, split)
    ranked = {w.name: _score_candidates(w, split, settings) for w in flagged}
    source, chosen = _choose(flagged, ranked, settings)

    progress.info("scoring: chain, free run and intervals of the answer")
    chains = _chain_before_after(recording, twin, works, t, source, chosen)
    kpi_signal, kpi_shrink = _kpi_shrink(recording, *chains, source, chosen, split.score, notes)
    modules = _module_reports(recording, works, flagged, source, chosen, chains, split)
    candidates = [
        c
        for name in sorted(ranked, key=lambda k: k != getattr(source, "name", None))
        for c in ranked[name]
    ]
    return Diagnosis(
        **_verdict(source, chosen),
        kpi_shrink_pct=kpi_shrink,
        kpi_signal=kpi_signal,
        modules=modules,
        candidates=candidates,
        n_samples=n,
        n_train=n_train,
        n_choose=n_choose,
        dt=recording.dt,
        train_frac=train_frac,
        calibrated=tuple(w.name for w in works.values() if w.calibrated),
        notes=tuple(notes),
        settings=settings,
        also_needed=_other_gaps(flagged, source, ranked, settings),
        twin_discretisation=discretisation,
        **_free_run_rms(works, source, chosen, split),
        param_intervals=_answer_intervals(source, chosen, split),
        series=_scoring_series(recording, source, ranked, split.score),
    )
