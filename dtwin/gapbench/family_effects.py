"""Withheld effects of the other-physics families: their real forms and their random draws.

Specification: docs/gap.md §Benchmark. The families (:mod:`dtwin.gapbench.families`: a two-tank
process, a DC motor, a thermal network) are twin *tables*, so an effect is placed where the
table diagnoser looks for it: at a module's input signal, at a recorded output signal, at a
state, or at a param. Each draw here returns a :class:`Placed` effect: the real form (which
differs from the catalogue's textbook form on purpose: a smooth or hard saturation, a dead zone
with a soft edge, a fractional transport delay, a drift shaped as a power, an exponential or a
line with a wander, a quantizer after the noise, a hard or steep state limit) and the hooks
where it enters the asset, which the family's integration calls without branching on the
effect's name.

Strength: ``level`` (the case's magnitude) in [0, 1] maps log-uniformly from barely above the
noise (0) to strong (1) (:func:`~dtwin.gapbench.case_effects.log_between`). Every random draw
comes from the ``rng`` the engine passes in (seeded by the case seed). Arrays are time-first,
shape ``(n_samples,)``; every quantity is in recording units (s, the signals' own units).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dtwin.gapbench.case_effects import log_between

__all__ = [
    "Context",
    "OutputView",
    "Placed",
    "FamilyEffect",
    "input_saturation",
    "input_deadzone",
    "input_delay",
    "rate_limiter",
    "output_saturation",
    "output_bias_drift",
    "output_scale_error",
    "output_delay",
    "output_quantization",
    "state_limit",
    "parameter_mismatch",
    "parameter_drift",
    "parameter_step",
]


@dataclass(frozen=True)
class Context:
    """What an effect's draw may read: the asset and its noise-free run without the effect.

    Attributes
    ----------
    dt : float
        Sampling step (s).
    u : numpy.ndarray, shape (n_samples,)
        The asset's input, held over each sample (recording units).
    clean : dict of str to numpy.ndarray
        The run without the effect, noise-free, at the sample instants: every signal and
        every state by name, each ``(n_samples,)``.
    noise : dict of str to float
        True noise standard deviation per noisy output signal (its units).
    params : dict of str to float
        The asset's true params (the twin's names).
    declared : dict of str to float
        The params the twin file declares (within 2 % of ``params``).
    tau_slow : float
        The asset's slowest time constant (s), the scale of a rate limit.
    substeps : int
        Integration sub-steps per sample (a delay is rounded to whole sub-steps).
    """

    dt: float
    u: np.ndarray
    clean: dict[str, np.ndarray]
    noise: dict[str, float]
    params: dict[str, float]
    declared: dict[str, float]
    tau_slow: float
    substeps: int

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(len(self.u))


@dataclass(frozen=True)
class OutputView:
    """One output signal of the run with the effect, as a sensor effect sees it.

    Attributes
    ----------
    clean : numpy.ndarray, shape (n_samples,)
        Noise-free signal at the sample instants.
    noise : numpy.ndarray, shape (n_samples,)
        The measurement noise drawn for it.
    t : numpy.ndarray, shape (n_samples,)
        Sample instants (s).
    at : callable
        ``at(times)``: the noise-free signal at any instants (s), interpolated linearly on the
        integration's sub-steps, held at its first value before ``t = 0``.
    """

    clean: np.ndarray
    noise: np.ndarray
    t: np.ndarray
    at: Callable[[np.ndarray], np.ndarray]


#: ``term(t, x) -> float``: a term added to one state's derivative (state units per s); ``x``
#: the asset's state vector (a sequence of floats in the family's state order).
Term = Callable[[float, Sequence[float]], float]


@dataclass
class Placed:
    """A drawn effect: its real form, its parameters and the hooks where it enters the asset.

    Attributes
    ----------
    form : str
        The real form's name (``clip``, ``tanh``, ``hard``, ``power`` ...).
    params : dict
        The effect's true parameters in recording units (the key's ``params``).
    input_map : callable or None
        ``f(u) -> u_seen`` on the input array ``(n_samples,)``: what the module receives.
    input_delay : float
        Transport delay of the input (s), a whole number of sub-steps.
    rate : float or None
        Slew-rate limit of the input (input units per s).
    term : (str, callable) or None
        ``(state, term)``: a :data:`Term` added to that state's derivative.
    limit : (str, float, float) or None
        ``(state, upper level, steepness)``: the state cannot rise above the level; steepness
        0 is a hard stop (the derivative held at 0, the state clamped), else an outflow
        ``steepness·(x − level)`` above it (1/s).
    true_params : dict
        Params of the asset that differ from the drawn ones (a mismatch).
    schedule : (str, callable) or None
        ``(param, factor(t))``: a param that changes during the run (``t`` in s).
    output : (str, callable) or None
        ``(signal, f(view) -> recorded)``: what the sensor records, ``(n_samples,)``
        (:class:`OutputView`); without it a signal records ``clean + noise``.
    plant : dict
        A family's own change of structure (the motor's backlash).
    at, module : str or None
        The drawn ``at`` and module where they depend on the draw (a mismatch's param).
    """

    form: str
    params: dict[str, Any]
    input_map: Callable[[np.ndarray], np.ndarray] | None = None
    input_delay: float = 0.0
    rate: float | None = None
    term: tuple[str, Term] | None = None
    limit: tuple[str, float, float] | None = None
    true_params: dict[str, float] = field(default_factory=dict)
    schedule: tuple[str, Callable[[float], float]] | None = None
    output: tuple[str, Callable[[OutputView], np.ndarray]] | None = None
    plant: dict[str, Any] = field(default_factory=dict)
    at: str | None = None
    module: str | None = None

    @property
    def dynamic(self) -> bool:
        """Whether the effect changes the asset's run (not only what a sensor records)."""
        return self.output is None


#: ``draw(rng, level, ctx) -> Placed``.
Draw = Callable[[np.random.Generator, float, Context], Placed]


@dataclass(frozen=True)
class FamilyEffect:
    """One withheld effect of a family: the right answer and the draw of its real form.

    Attributes
    ----------
    expected : str
        The catalogue effect the diagnoser should name, or ``unexplained``.
    module : str
        The module it sits in (an input's reader, an output's producer, a state's or param's
        owner); a draw may override it (:attr:`Placed.module`).
    at : str or None
        The signal, state or param (as written in the twin file), or None.
    draw : callable
        :data:`Draw`.
    equivalent : tuple of str
        Catalogue effects that explain the recording exactly as well (the key's
        ``accepted_effects``): a delay at a unit's input and at its only output commute
        through a time-invariant unit started from rest; a sensor's gain error equals a
        re-fit of params when the twin is covariant with the output's scale.
    equivalent_bare_only : bool
        The equivalence holds only without the internal signals (a recorded internal
        signal that the effect leaves alone breaks it).
    """

    expected: str
    module: str
    at: str | None
    draw: Draw
    equivalent: tuple[str, ...] = ()
    equivalent_bare_only: bool = False


#: ``x`` with ``tanh(x) = x/2``: a tanh reaching half its linear extension (1.9150...).
_TANH_HALF = 1.9150080004407


def _softplus(z: np.ndarray) -> np.ndarray:
    return np.logaddexp(0.0, z)


def _sign(rng: np.random.Generator) -> float:
    return 1.0 if rng.uniform() < 0.5 else -1.0


def input_saturation() -> Draw:
    """Return the draw of a saturating input that lowers the largest input by 0.3–40 %.

    The largest input ``M`` is the smaller of the two halves' ``max|u|``, so the training
    half holds the effect. Forms: ``clip`` (hard at ``U = (1 − depth)·M``), ``tanh`` (linear
    up to ``(1 − 2·depth)·M``, then a tanh towards ``U``, the asymptote, reaching
    ``(1 − depth)·M`` at ``M``), ``knee`` (a soft minimum of ``|u|`` and ``U = (1 −
    depth)·M``, width 0.5–1.5 ``depth·M``); symmetric about 0 (a unipolar input is limited
    above).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        form = str(rng.choice(["clip", "tanh", "knee"]))
        softness = rng.uniform(0.5, 1.5)
        depth = log_between(0.003, 0.4, level)
        half = ctx.n // 2
        top = min(float(np.max(np.abs(ctx.u[:half]))), float(np.max(np.abs(ctx.u[half:]))))
        start, bend = (1.0 - 2.0 * depth) * top, 2.0 * depth * top / _TANH_HALF
        limit = start + bend if form == "tanh" else (1.0 - depth) * top

        def saturate(u: np.ndarray) -> np.ndarray:
            a = np.abs(u)
            if form == "clip":
                return np.clip(u, -limit, limit)
            if form == "tanh":
                return np.sign(u) * np.where(
                    a > start, start + bend * np.tanh((a - start) / bend), a
                )
            w = softness * depth * top
            return np.sign(u) * (limit - w * _softplus((limit - a) / w))

        return Placed(form, {"U": limit, "depth": depth}, input_map=saturate)

    return draw


def input_deadzone() -> Draw:
    """Return the draw of a dead zone on the input: width ``D`` 0.2–30 % of ``max|u|``.

    Forms: ``hard`` (``sign(u)·max(|u| − D, 0)``), ``smooth`` (a soft edge of width
    0.1–0.3 ``D``) and, on a bipolar input, ``asymmetric`` (``D`` ± 10–30 % by direction).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        bipolar = float(np.min(ctx.u)) < 0.0
        form = str(rng.choice(["hard", "smooth", "asymmetric"] if bipolar else ["hard", "smooth"]))
        soft, skew = rng.uniform(0.1, 0.3), rng.uniform(0.1, 0.3) * _sign(rng)
        width = log_between(0.002, 0.3, level) * float(np.max(np.abs(ctx.u)))

        def dead(u: np.ndarray) -> np.ndarray:
            a = np.abs(u)
            if form == "smooth":
                w = soft * width
                return np.sign(u) * w * _softplus((a - width) / w)
            d = width * (1.0 + skew * np.sign(u)) if form == "asymmetric" else width
            return np.sign(u) * np.maximum(a - d, 0.0)

        return Placed(form, {"D": width}, input_map=dead)

    return draw


def _whole_substeps(delay: float, ctx: Context) -> float:
    step = ctx.dt / ctx.substeps
    return max(round(delay / step), 1) * step


def _delay(level: float, ctx: Context) -> float:
    """Return a delay of 0.2–10 % of the asset's slowest time constant, at least 0.3 sample (s)."""
    return max(log_between(0.002, 0.1, level) * ctx.tau_slow, 0.3 * ctx.dt)


def input_delay() -> Draw:
    """Return the draw of a transport delay of the input: 0.2–10 % of the slowest time constant.

    At least 0.3 sample; rounded to whole integration sub-steps (so fractional in samples).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        delay = _whole_substeps(_delay(level, ctx), ctx)
        return Placed("transport", {"delay": delay}, input_delay=delay)

    return draw


def rate_limiter() -> Draw:
    """Return the draw of a slew-rate limit on the input (out of the catalogue).

    A full-span step takes 0.003–1 of the asset's slowest time constant.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        span = float(np.ptp(ctx.u)) or 1.0
        ramp = log_between(0.003, 1.0, level) * ctx.tau_slow
        return Placed("slew", {"rate": span / ramp, "ramp_s": ramp}, rate=span / ramp)

    return draw


def output_saturation(signal: str) -> Draw:
    """Return the draw of a sensor that clips ``signal`` above ``high``.

    ``high`` leaves 0.5–30 % of the training half's clean samples (the first half) above it.
    Forms: ``clip`` (after the noise, as an ADC clips) and ``knee`` (a soft minimum, width
    0.5–2 % of the signal's spread).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        form = str(rng.choice(["clip", "knee"]))
        y = ctx.clean[signal]
        width = rng.uniform(0.005, 0.02) * float(np.ptp(y))
        share = log_between(0.005, 0.3, level)
        high = float(np.quantile(y[: ctx.n // 2], 1.0 - share))

        def sense(view: OutputView) -> np.ndarray:
            raw = view.clean + view.noise
            if form == "clip":
                return np.minimum(raw, high)
            return high - width * _softplus((high - raw) / width)

        return Placed(form, {"high": high, "share_train": share}, output=(signal, sense))

    return draw


def _drift_shape(form: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """Return a drift's shape over the run, ``(n,)``, 0 at the start and 1 at the end."""
    tau = np.linspace(0.0, 1.0, n)
    power, scale = rng.uniform(0.6, 2.0), rng.uniform(0.2, 1.0)
    steps = rng.standard_normal(n)
    if form == "power":
        return tau**power
    if form == "exponential":
        return (1.0 - np.exp(-tau / scale)) / (1.0 - np.exp(-1.0 / scale))
    wander = np.cumsum(steps)
    wander = (wander - np.linspace(wander[0], wander[-1], n)) / (np.ptp(wander) or 1.0)
    return tau + 0.1 * wander


def output_bias_drift(signal: str) -> Draw:
    """Return the draw of a sensor offset growing over the run: 2–40 noise std at the end.

    Shapes: ``power`` (``τ^p``, ``p`` 0.6–2), ``exponential`` (saturating), ``wander`` (a line
    with a random-walk wander of 10 % of its end value); ``τ`` = t over the run's length.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        form = str(rng.choice(["power", "exponential", "wander"]))
        end = log_between(2.0, 40.0, level) * ctx.noise[signal] * _sign(rng)
        drift = end * _drift_shape(form, rng, ctx.n)

        def sense(view: OutputView) -> np.ndarray:
            return view.clean + view.noise + drift

        return Placed(form, {"drift_end": end}, output=(signal, sense))

    return draw


#: Smallest sensor gain error drawn, the smallest param mismatch drawn: every family's twin has
#: params its recorded output scales with (a sensor's gain, a motor's torque and back-EMF
#: constants, a heater's gain; without the internal signals, a tank's outflow coefficient too,
#: the level going as its inverse square), declared up to 2 % off and re-fitted within the 5 %
#: calibration tolerance, so a gain error of a few per cent is nominal by the twin file's own
#: tolerance.
SCALE_ERROR_MIN = 0.15


def output_scale_error(signal: str) -> Draw:
    """Return the draw of a sensor gain error on the clean signal: ``gain = 1 ± e``.

    ``e·rms(signal)`` is 1.5–40 noise std, ``e`` at least :data:`SCALE_ERROR_MIN` and at most 0.5.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        rms = float(np.sqrt(np.mean(ctx.clean[signal] ** 2))) or 1.0
        visible = log_between(1.5, 40.0, level) * ctx.noise[signal] / rms
        error = min(max(visible, SCALE_ERROR_MIN), 0.5)
        gain = 1.0 + _sign(rng) * error

        def sense(view: OutputView) -> np.ndarray:
            return gain * view.clean + view.noise

        return Placed("gain", {"gain": gain}, output=(signal, sense))

    return draw


def output_delay(signal: str) -> Draw:
    """Return the draw of a delayed reading: 0.2–10 % of the asset's slowest time constant.

    At least 0.3 sample, fractional (interpolated on the integration's sub-steps); the noise
    is not delayed.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        delay = _delay(level, ctx)

        def sense(view: OutputView) -> np.ndarray:
            return view.at(view.t - delay) + view.noise

        return Placed("fractional", {"delay": delay}, output=(signal, sense))

    return draw


def output_quantization(signal: str) -> Draw:
    """Return the draw of a quantizer after the noise: step ``q`` 1–12 noise std.

    Forms: ``round`` and ``floor`` (a truncating converter, biased by ``q/2``), on a lattice
    with a random offset.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        form = str(rng.choice(["round", "floor"]))
        step = log_between(1.0, 12.0, level) * ctx.noise[signal]
        offset = rng.uniform(0.0, step)
        snap = np.round if form == "round" else np.floor

        def sense(view: OutputView) -> np.ndarray:
            return step * snap((view.clean + view.noise - offset) / step) + offset

        return Placed(form, {"q": step, "offset": offset}, output=(signal, sense))

    return draw


def state_limit(state: str) -> Draw:
    """Return the draw of an upper limit of ``state`` reached in the training half.

    The level leaves 0.5–30 % of the training half's samples (the first half of the run
    without the effect) above it. Forms: ``hard`` (the state stops there) and ``steep`` (an
    outflow of 1–3 per sample time constant above it: a weir, a boiling point).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        form = str(rng.choice(["hard", "steep"]))
        steep = rng.uniform(1.0, 3.0) / ctx.dt
        share = log_between(0.005, 0.3, level)
        upper = float(np.quantile(ctx.clean[state][: ctx.n // 2], 1.0 - share))
        steepness = 0.0 if form == "hard" else steep
        params = {"limit_upper": upper, "share_train": share, "steepness": steepness}
        return Placed(form, params, limit=(state, upper, steepness))

    return draw


def parameter_mismatch(owners: Mapping[str, str]) -> Draw:
    """Return the draw of one param off by 15–40 % (either way) from its declared value.

    ``owners`` maps the params that may be drawn to their modules.
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        name = str(rng.choice(sorted(owners)))
        factor = 1.0 + _sign(rng) * log_between(0.15, 0.4, level)
        true = ctx.declared[name] * factor
        params = {"param": name, "declared": ctx.declared[name], "true": true, "factor": factor}
        return Placed("factor", params, true_params={name: true}, at=name, module=owners[name])

    return draw


def parameter_drift(name: str) -> Draw:
    """Return the draw of a param drifting linearly over the run (out of the catalogue).

    ``name`` falls by 1–30 % of its value from the start to the end (a clogging orifice).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        fall = log_between(0.01, 0.3, level)
        span = ctx.n * ctx.dt

        def factor(t: float) -> float:
            return 1.0 - fall * t / span

        return Placed("linear", {"param": name, "fall": fall}, schedule=(name, factor))

    return draw


def parameter_step(name: str) -> Draw:
    """Return the draw of a param that steps mid-run (out of the catalogue).

    ``name`` is divided by ``1 + jump``, ``jump`` 0.02–1, from 35–65 % of the run on (a fan
    that switches on).
    """

    def draw(rng: np.random.Generator, level: float, ctx: Context) -> Placed:
        jump = log_between(0.02, 1.0, level)
        when = rng.uniform(0.35, 0.65) * ctx.n * ctx.dt

        def factor(t: float) -> float:
            return 1.0 / (1.0 + jump) if t >= when else 1.0

        return Placed("step", {"param": name, "jump": jump, "at_s": when}, schedule=(name, factor))

    return draw
