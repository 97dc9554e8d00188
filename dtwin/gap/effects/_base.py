"""What every catalogue effect is made of: :class:`Effect`, :class:`Scales`, :class:`ForceOps`.

:class:`Scales` holds the data scales an effect's bounds are drawn from, :class:`ForceOps` the
elementary functions its force laws are built on.

Specification: docs/gap.md §Candidate effects (the catalogue table).

Each :class:`Effect` is the one place of its effect in the diagnoser: the modules it can belong
to, its parameters with units, bounds and starting points (scaled from the data, so the
catalogue works in any units), and the form the twin takes with it (its ``input_map``,
``force_law`` or ``output_map``). No code branches on an effect's name
(tests/gap/test_gap_effects.py walks the catalogue). How it enters the module's twin, its ``stage``:

``input``
    a static map on the module input before its linear dynamics (Hammerstein form):
    ``actuator_saturation``, ``actuator_deadzone``.
``delay``
    an extra input delay in seconds, fractional (linear interpolation): ``actuator_delay``,
    ``sensor_delay``.
``force``
    an extra force ``F(x, v)`` subtracted in the plant's acceleration (paper §3.1 M1), its law
    the effect's ``force_law``: ``coulomb_friction``, ``stribeck_friction``,
    ``cubic_stiffness``, ``quadratic_damping``.
``output``
    a map on the sensor output (``lag`` is the sensor's noise-free first-order lag of x, ``bias``
    its offset): ``sensor_quantization``, ``sensor_scale_error``, ``sensor_bias_drift``.
``linear``
    ``parameter_mismatch``: no new term, the module's own linear parameters are re-fitted.

The forms are the textbook ones on purpose; the real ones differ (a generalised Stribeck
exponent, a smooth saturation, a drift that is not linear) and a candidate must still win when
it is only close.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Scales",
    "Bounds",
    "Effect",
    "ForceOps",
    "CompiledLaw",
    "ARRAY_OPS",
    "SCALAR_OPS",
    "FRICTION_SMOOTHING",
    "smoothing_velocity",
    "NONE",
    "UNEXPLAINED",
    "PARAMETER_MISMATCH",
]


NONE = "none"
UNEXPLAINED = "unexplained"
PARAMETER_MISMATCH = "parameter_mismatch"


@dataclass(frozen=True)
class Scales:
    """Data scales an effect's bounds and starting points are drawn from (recording units).

    Attributes
    ----------
    input_max : float
        ``max |input|`` over the training part.
    input_std, output_std : float
        Standard deviations of the module's input and output.
    velocity_std : float
        Standard deviation of the plant velocity (M1; else 0).
    duration : float
        Length of the recording, s.
    dt : float
        Sample period, s.
    noise_std : float
        The module's output noise standard deviation (used by quantization), output units.
    stiffness, mass : float
        The plant's ``k`` and ``m`` in the twin (M1; else 0).
    output_mean : float
        Mean of the module's output over the training part (where a rig's spring is likely
        centred when its position is recorded with an offset), output units.
    """

    input_max: float
    input_std: float
    output_std: float
    velocity_std: float
    duration: float
    dt: float
    noise_std: float
    stiffness: float = 0.0
    mass: float = 0.0
    output_mean: float = 0.0


Bounds = list[tuple[float, float]]


#: A force law for the compiled loop: the kernel's name and its parameters.
CompiledLaw = tuple[str, tuple[float, ...]]


@dataclass(frozen=True)
class Effect:
    """One candidate effect.

    Attributes
    ----------
    name : str
        Effect name of the report (``"coulomb_friction"``).
    modules : tuple of str
        Modules it can belong to.
    params : tuple of str
        Parameter names, in the order of ``theta``.
    units : tuple of str
        Unit of each parameter, in words ("input units", "s").
    stage : str
        How it enters the twin (see the module docstring).
    formula : str
        The form, for the report.
    bounds : callable
        ``bounds(scales) -> [(low, high), ...]``.
    starts : callable
        ``starts(scales) -> [theta0, ...]``: starting points of the multi-start fit.
    typical : callable
        ``typical(scales) -> [scale, ...]``: a typical magnitude of each parameter.
    linear_form : bool
        True when the candidate stays inside the twin's linear model class (a re-fit of the
        linear parameters, a sensor gain): if it is the right answer the re-fitted twin is exact,
        so it must remove more of the excess gap than other candidates
        (``GapSettings.min_linear_share``).
    nests : tuple of str
        Catalogue effects this one contains as a special case (Stribeck friction with
        ``Fs = Fc`` is Coulomb friction): the plain one is the answer unless this one removes
        clearly more (``dtwin.gap.which.NEST_MARGIN_PCT``).
    nested_starts : callable or None
        Starting points from the fitted parameters of the effect it nests (``nests[0]``):
        ``nested_starts(theta_plain, scales) -> [theta0, ...]``, the first of them the plain
        fit itself in this form (Stribeck friction with ``Fs = Fc``), so that the wider form,
        fitted from there, never fits the training part worse than the form it contains.
    departure : callable or None
        How far fitted parameters lie from the form it nests, relative to the effect's size:
        ``departure(theta) -> float`` (Stribeck friction: ``(Fs − Fc)/Fc``, the breakaway
        force's excess over the sliding one). From ``dtwin.gap.which.NEST_DEPARTURE`` on,
        the data show what the plain form lacks.
    plain_part : callable or None
        The plain form's parameters nearest to fitted ones of this form:
        ``plain_part(theta) -> theta_plain`` (Stribeck friction: ``[Fc]``), the same model
        exactly where ``departure(theta)`` is 0. The plain form is fitted again from there when
        this form's fit trains better (``dtwin.gap.which.fit_candidates``).
    force_law : callable or None
        A ``force`` effect's law: ``force_law(theta, velocity_std, ops) -> F(x, v)``, built on
        ``ops`` (:data:`ARRAY_OPS` for numpy arrays, :data:`SCALAR_OPS` for Python floats).
    compiled_law : callable or None
        The same law for the exact plant's compiled loop (:mod:`dtwin.twin._force_kernels`):
        ``compiled_law(values, smoothing) -> (kernel name, parameters)``, ``values`` the floats
        of ``theta``, ``smoothing`` the friction's smoothing velocity.
    input_map : callable or None
        An ``input`` or ``delay`` effect's map on the module input before its linear dynamics:
        ``input_map(u, theta, dt) -> u'``, shape ``(n_samples,)``.
    output_map : callable or None
        An ``output`` effect's sensor reading: ``output_map(lag, bias, t, theta) -> y``, from
        the sensor's noise-free lag of x, its bias and the time axis (s), shape
        ``(n_samples,)``.
    lattice : bool
        The effect puts the output on a lattice (a quantizer): it is fitted on the lattice the
        values sit on and chosen by its own likelihood, not a Gaussian's (docs/gap.md §Which).
    input_limit : (str, str) or None
        ``(parameter, input signal)``: a parameter that is the limit of the effect's input map
        as the input grows (a saturation level). A recording determines the map only over the
        inputs it holds, so the data bound that parameter from below only by the largest
        ``|map output|`` over the training inputs; its interval's lower end reaches down to
        that (:func:`dtwin.gap.intervals.parameter_intervals`).
    smoothed : Effect or None
        A wider form fitted for the interval alone where no catalogue candidate nests this one:
        this form with a sharpness, this form as its limit (a dead zone with rounded edges is
        read by the hard one with ``D`` 2–5 % low; :func:`dtwin.gap.intervals.smoothed_fit`).
    """

    name: str
    modules: tuple[str, ...]
    params: tuple[str, ...]
    units: tuple[str, ...]
    stage: str
    formula: str
    bounds: Callable[[Scales], Bounds]
    starts: Callable[[Scales], list[list[float]]]
    typical: Callable[[Scales], list[float]]
    linear_form: bool = False
    nests: tuple[str, ...] = ()
    nested_starts: Callable[[Sequence[float], Scales], list[list[float]]] | None = None
    departure: Callable[[Sequence[float]], float] | None = None
    plain_part: Callable[[Sequence[float]], list[float]] | None = None
    force_law: Callable[..., Callable[[float, float], float]] | None = None
    compiled_law: Callable[[list[float], float], CompiledLaw] | None = None
    input_map: Callable[[np.ndarray, Sequence[float], float], np.ndarray] | None = None
    output_map: Callable[..., np.ndarray] | None = None
    lattice: bool = False
    input_limit: tuple[str, str] | None = None
    smoothed: Effect | None = None

    @property
    def n_params(self) -> int:
        """Number of effect parameters."""
        return len(self.params)

    @property
    def refits_linear(self) -> bool:
        """Whether this is ``parameter_mismatch``: no new term, the linear twin re-fitted."""
        return self.stage == "linear"


@dataclass(frozen=True)
class ForceOps:
    """The elementary functions a plant force law is built on (numpy ufuncs or ``math``)."""

    tanh: Callable
    abs: Callable
    exp: Callable


#: Force laws over numpy arrays, and over Python floats (the exact plant's scalar windows).
ARRAY_OPS = ForceOps(np.tanh, np.abs, np.exp)
SCALAR_OPS = ForceOps(math.tanh, abs, math.exp)

#: Friction smoothing velocity as a fraction of std(v) (the tanh of the friction effects).
FRICTION_SMOOTHING = 0.01


def smoothing_velocity(velocity_std: float) -> float:
    """Return the friction effects' smoothing velocity: :data:`FRICTION_SMOOTHING`·std(v)."""
    return max(FRICTION_SMOOTHING * velocity_std, 1e-300)
