"""Where the gap lies: each module's twin, noise floor, gap and threshold (docs/gap.md §Where).

Each module whose input and output are recorded is driven with its *recorded* input; its local
gap (:mod:`dtwin.gap.localise`) is compared with the largest gap its noise explains
(:mod:`dtwin.gap.noise`), both on the training and choosing parts. Twins are never calibrated
exactly, so the comparison uses the gap left after re-fitting the module's own linear parameters
inside ``calibration_tolerance`` of their nominal values on the training part: a gap such a
re-fit removes is calibration slack, not a sim-to-real gap. The plant's discretisation and, for
an exact hold, its window are chosen here too (§Modules, §Gaps).

:func:`analyse_module` returns a module's :class:`ModuleWork`, which the later steps
(:mod:`dtwin.gap.which`, :mod:`dtwin.gap.how_far`) fill in and read; :class:`Split` holds the
recording's three parts and :class:`Layout` the discretisations to choose from.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from dtwin._validation import DtwinValueError
from dtwin.gap.closed_loop import in_loop
from dtwin.gap.effects import Scales
from dtwin.gap.fit import calibrate_linear, fit_candidate, linear_typical
from dtwin.gap.localise import module_inputs, normalised_rms
from dtwin.gap.models import (
    LINEAR_PARAMS,
    MIN_HORIZON,
    ModuleData,
    held_noise_autocovariance,
    plant_bandwidth_hz,
    plant_horizon,
    plant_state_from_position,
    plant_windows,
    simulate_module,
    warmup_samples,
    window_error_covariance,
    window_noise_gain,
)
from dtwin.gap.noise import (
    NoiseFloor,
    data_noise_floor,
    effective_samples,
    gap_threshold,
    process_noise_floor,
    reconcile_noise_floor,
    residual_noise_floor,
    spectral_noise_floor,
    twin_noise_floor,
    window_gain_pole,
)
from dtwin.gap.oe_reference import output_error_reference
from dtwin.gap.recording import Recording
from dtwin.params import TwinParams
from dtwin.twin.paper_modules import EULER
from dtwin.twin.wiring import PLANT, module_by_name, role_of

if TYPE_CHECKING:
    from dtwin.gap.which import FittedCandidate

__all__ = [
    "Layout",
    "Split",
    "ModuleWork",
    "nominal_lin",
    "check_inputs_vary",
    "analyse_module",
    "add_reference_gaps",
    "module_notes",
]

logger = logging.getLogger(__name__)


#: Calibration fits of the exact plant's window search, at most (docs/gap.md §Gaps).
WINDOW_ROUNDS = 3


#: Relative change of the window under which its search stops.
WINDOW_SETTLED = 0.1


@dataclass(frozen=True)
class Layout:
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


@dataclass(frozen=True)
class Split:
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
class ModuleWork:
    """One diagnosed module's state through the three steps (normalised gaps, as in localise).

    :func:`analyse_module` fills everything up to ``n_eff`` (§Where): the module's data and
    linear twin (``lin_base``; ``lin_nominal`` the twin file's), the output's standard deviation
    ``norm`` that normalises every gap, the twin's simulation ``sim_before``, the gaps on the
    choosing part (``gap_before``), the scoring part (``gap_scored``) and both parts before
    scoring after in-band calibration (``gap_cal``), the noise floors and the threshold;
    :func:`~dtwin.gap.which.fit_candidates` appends ``candidates``;
    :func:`add_reference_gaps` sets ``reference_gap``; ``tried`` maps each discretisation
    family tried to its training gap (None when the twin file declares one); ``nested`` is the
    reason a module within its noise threshold has a gap after all, by the nested test
    (:func:`~dtwin.gap.which.nested_test`), else None.
    """

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
    candidates: list[FittedCandidate] = field(default_factory=list)
    reference_gap: float | None = None
    tried: dict[str, float] | None = None
    nested: str | None = None


def nominal_lin(name: str, twin: TwinParams) -> dict[str, float] | None:
    """Return the twin file's linear parameters of module ``name``, or None without a section."""
    section = getattr(twin, module_by_name(name).section)
    if section is None:
        return None
    return {key: float(getattr(section, key)) for key in LINEAR_PARAMS[name]}


def _module_data(
    name: str, rec: Recording, t: np.ndarray, layout: Layout, scheme: str = EULER
) -> ModuleData:
    """Return the module's recorded signals; the plant's state estimate follows ``scheme``."""
    inputs = module_inputs(name, rec.signals, rec.dt)
    module = module_by_name(name)
    output = rec.signals[module.output]
    velocity, position, lead = inputs.get("v"), None, 0
    if module.role == PLANT:
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
    velocity_std = float(np.std(data.velocity)) if data.role == PLANT else 0.0
    if simulated is not None and data.role == PLANT and data.discretisation != EULER:
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


def check_inputs_vary(rec: Recording, names: list[str], n_train: int) -> None:
    """Raise :class:`DtwinValueError` if a module input is constant over the recording or part."""
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


def _exact_plant_floor(
    data: ModuleData, simulated, lin: dict, n_train: int, significance: float, refit=None
) -> NoiseFloor:
    """Return the exact plant's data floor: the spectral one, or a whole-band one if larger.

    docs/gap.md §Noise floors: the spectral noise above the plant times the window's noise
    gain (over windows the initial state estimated from the warm-up samples carries part of the
    measurement noise forward: :func:`~dtwin.gap.models.window_noise_gain`, with the noise's
    AR(1) pole unless it sits at the top of its grid, :func:`window_gain_pole`); and the linear
    twin's training error taken as AR(1) noise over the whole band when that model explains it
    (:func:`residual_noise_floor`, its innovations white at size ``significance``), which a
    coloured noise with its power below the plant's resonance needs. ``refit``: ``(lin,
    simulated)`` of the twin file's plant re-fitted freely on the training part (a twin file
    with the plant's parameters but no noise levels); its training error is also taken as
    process noise through that plant beside the measurement noise read above it, when that
    model explains it (:func:`_process_floor`): a re-fit, so that a parameter mismatch does
    not pass for process noise.
    """
    residual = (data.output - simulated)[:n_train]
    # the scored samples only: the windows' unscored warm-ups (a fifth of every window) read
    # as zeros had taken a fifth off the noise's spectrum (a white floor 11 % low)
    above = spectral_noise_floor(residual[np.isfinite(residual)], data.dt, plant_bandwidth_hz(lin))
    if data.horizon is None:
        return above
    pole = window_gain_pole(above)
    gain = window_noise_gain(lin, data.dt, data.discretisation, data.horizon, pole)
    floor = replace(above, rms=above.rms * math.sqrt(gain))
    # the realised error of the windows carries their warm-ups' noise already: no gain
    whole = residual_noise_floor(residual, significance)
    if refit is not None:
        process = _process_floor(data, *refit, n_train, pole, significance)
        if process is not None and (whole is None or process.rms > whole.rms):
            whole = process
    if whole is not None and whole.rms > floor.rms:
        return whole
    # the noise read above the plant is measurement noise on the position, which a twin file
    # never states: it adds to the twin's floor (reconcile_noise_floor) as the Euler plant's
    # data measurement does, unless its pole sits at the top of the grid (no estimate: the
    # steep spectrum of a force's sign changes, window_gain_pole)
    estimated = len(above.acf) < 2 or pole > 0.0
    return replace(floor, measurement=floor.rms) if estimated else floor


def _process_floor(data, lin, simulated, n_train: int, pole: float, significance: float):
    """Return the windows' process and measurement noise floor, or None (docs/gap.md §Noise floors).

    The windows inside the training part, grouped by length, with the covariances of their
    scored errors per unit of each noise (:func:`~dtwin.gap.models.window_error_covariance`:
    acceleration noise held over each sample through ``lin``'s plant, AR(1) noise of ``pole``),
    go to :func:`~dtwin.gap.noise.process_noise_floor`; None for a plant without a stationary
    variance.
    """
    windows = [
        (a, b)
        for a, b in plant_windows(len(data.output), data.horizon, data.restarts)
        if b <= n_train
    ]
    if not windows:
        return None
    longest = max(b - a for a, b in windows)
    autocovariance = held_noise_autocovariance(lin, data.dt, longest)
    if autocovariance is None or autocovariance[0] <= 0.0:
        return None
    warmup = warmup_samples(data.horizon)
    error = data.output - simulated
    rows: dict[int, list[np.ndarray]] = {}
    for a, b in windows:
        rows.setdefault(b - a, []).append(error[a + warmup : b])
    noise = pole ** np.arange(longest)
    groups = [
        (
            np.array(errors),
            window_error_covariance(
                lin, data.dt, data.discretisation, data.horizon, n, autocovariance
            ),
            window_error_covariance(lin, data.dt, data.discretisation, data.horizon, n, noise),
        )
        for n, errors in rows.items()
    ]
    if not all(np.all(np.isfinite(errors)) for errors, _, _ in groups):
        return None
    return process_noise_floor(groups, autocovariance / autocovariance[0], pole, significance)


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
    if in_loop(data.inputs["u_act"][:n_train], data.output[:n_train]):
        # docs/gap.md §Closed loop: the longest window (the controller holds the position)
        return horizon, calibrate_linear(replace(data, horizon=horizon), n_train), horizon
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


def analyse_module(name, rec, twin, t, split: Split, calibrate, settings, layout):
    """Return the module's :class:`ModuleWork`: its twin, floors, gaps and threshold.

    The gap and threshold that decide where the gap lies are those of all data before the
    scoring part (training and choosing: a linear re-fit of a few parameters is barely biased
    in-sample, and a third of the data made faint effects read ``none``); candidates are
    compared on the choosing part; the gap the shrinks start from is the scoring part's
    (docs/gap.md §Where).
    """
    n_train = split.n_train
    nominal = nominal_lin(name, twin)
    calibrated = calibrate or nominal is None
    start = None if calibrated else nominal
    data, lin_base, tried = _module_twin(name, rec, t, n_train, (nominal, start), settings, layout)
    norm = float(np.std(data.output)) or 1.0
    sim_before = simulate_module(data, lin_base)
    if data.discretisation != EULER:
        refit = None
        if not calibrated and twin.noise is None:
            # the scales of the final data (a linear fit reads no noise level)
            scaled = replace(data, scales=_scales(data, n_train, 0.0, lin_base, sim_before))
            lin = fit_candidate(scaled, None, lin_base, n_train=n_train).lin
            refit = (lin, simulate_module(data, lin))
        floor_data = _exact_plant_floor(
            data, sim_before, lin_base, n_train, settings.significance, refit
        )
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
    return ModuleWork(
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
    plant is prepared once per family of :attr:`Layout.families` (exact holds: the best of them,
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
    families = layout.families if role_of(name) == PLANT else [(EULER,)]
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


def module_notes(works: Mapping[str, ModuleWork], calibrate: bool) -> list[str]:
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


def add_reference_gaps(works: Mapping[str, ModuleWork], split: Split) -> None:
    """Compare a calibrated exact plant with a plain output-error fit; update ``works``.

    For M1 calibrated from data with an exact hold, ``reference_gap`` becomes the scoring-part
    gap of :func:`~dtwin.gap.oe_reference.output_error_reference` on the same split and windows
    (a note of the report), and ``gap_cal`` at most the gap that fit reaches before the scoring
    part: a gap a plain linear OE fit removes is calibration slack (docs/gap.md §Where).
    """
    for work in works.values():
        if work.data.role == PLANT and work.calibrated and work.data.discretisation != EULER:
            reference = output_error_reference(
                work.data, int(work.lin_base.get("delay_samples", 0)), split.n_train
            )
            work.reference_gap = normalised_rms(work.data.output, reference, split.score, work.norm)
            reached = normalised_rms(work.data.output, reference, split.decide, work.norm)
            work.gap_cal = min(work.gap_cal, reached) if np.isfinite(reached) else work.gap_cal
