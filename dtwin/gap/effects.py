"""The catalogue of candidate unmodelled effects of the gap diagnoser.

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
    "Effect",
    "ForceOps",
    "ARRAY_OPS",
    "SCALAR_OPS",
    "FRICTION_SMOOTHING",
    "EFFECTS",
    "EFFECT_NAMES",
    "NONE",
    "UNEXPLAINED",
    "PARAMETER_MISMATCH",
    "effects_for_module",
    "effect_by_name",
    "soft_saturation",
    "deadzone",
    "fractional_delay",
    "bias_drift",
    "DRIFT_CURVATURE_MAX",
    "smooth_quantize",
    "quantization_variance",
    "quantizer_log_density",
    "find_lattice",
    "refine_lattice",
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
    force_law : callable or None
        A ``force`` effect's law: ``force_law(theta, velocity_std, ops) -> F(x, v)``, built on
        ``ops`` (:data:`ARRAY_OPS` for numpy arrays, :data:`SCALAR_OPS` for Python floats).
    compiled_law : callable or None
        The same law for the exact plant's compiled loop (:mod:`dtwin._force_kernels`):
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
    force_law: Callable[..., Callable[[float, float], float]] | None = None
    compiled_law: Callable[[list[float], float], CompiledLaw] | None = None
    input_map: Callable[[np.ndarray, Sequence[float], float], np.ndarray] | None = None
    output_map: Callable[..., np.ndarray] | None = None
    lattice: bool = False

    @property
    def n_params(self) -> int:
        """Number of effect parameters."""
        return len(self.params)

    @property
    def refits_linear(self) -> bool:
        """Whether this is ``parameter_mismatch``: no new term, the linear twin re-fitted."""
        return self.stage == "linear"


# --- the forms --------------------------------------------------------------------------


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


def _smoothing(velocity_std: float) -> float:
    return max(FRICTION_SMOOTHING * velocity_std, 1e-300)


def _coulomb_law(theta, velocity_std: float, ops: ForceOps):
    """``F = Fc·tanh(v/v_s)``."""
    fc, smooth = float(theta[0]), _smoothing(velocity_std)
    return lambda x, v: fc * ops.tanh(v / smooth)


def _stribeck_law(theta, velocity_std: float, ops: ForceOps):
    """``F = (Fc + max(Fs − Fc, 0)·exp(−(v/vs)²))·tanh(v/v_s)``: the breakaway force at rest.

    A breakaway force below the sliding one is no Stribeck bump (it would mimic a viscous
    term: a Coulomb and viscous friction read as Stribeck friction with ``Fs < Fc``).
    """
    fc, fs, vs = (float(value) for value in theta)
    bump, vs, smooth = max(fs - fc, 0.0), max(abs(vs), 1e-300), _smoothing(velocity_std)

    def stribeck(x, v):
        ratio = v / vs
        return (fc + bump * ops.exp(-ratio * ratio)) * ops.tanh(v / smooth)

    return stribeck


def _stribeck_from_coulomb(theta: Sequence[float], s: Scales) -> list[list[float]]:
    """Stribeck starts from a fitted Coulomb level ``Fc``: the Coulomb fit itself, then a bump.

    A Coulomb friction fitted to a friction with a breakaway force reads a level between the
    sliding and the breakaway force, so the bumped starts put the sliding force below it and
    the breakaway force above it, at a low and a middling Stribeck velocity.
    """
    fc = float(theta[0])
    low, mid = 0.1 * s.velocity_std, 0.3 * s.velocity_std
    return [[fc, fc, low], [0.8 * fc, 2.0 * fc, low], [0.8 * fc, 2.0 * fc, mid]]


def _breakaway_excess(theta: Sequence[float]) -> float:
    """``(Fs − Fc)/Fc`` (0 without a bump, inf for a bump on no sliding force)."""
    fc, fs = float(theta[0]), float(theta[1])
    bump = max(fs - fc, 0.0)
    return bump / fc if fc > 0 else (math.inf if bump > 0 else 0.0)


def _cubic_law(theta, velocity_std: float, ops: ForceOps):
    """``F = k3·(x − x0)³``."""
    k3, centre = float(theta[0]), float(theta[1])

    def cubic(x, v):
        offset = x - centre
        return k3 * offset * offset * offset

    return cubic


def _quadratic_damping_law(theta, velocity_std: float, ops: ForceOps):
    """``F = c2·v·|v|``."""
    c2 = float(theta[0])
    return lambda x, v: c2 * v * ops.abs(v)


#: A force law for the compiled loop: the kernel's name and its parameters.
CompiledLaw = tuple[str, tuple[float, ...]]


def _coulomb_compiled(values: list[float], smooth: float) -> CompiledLaw:
    return "tanh_friction", (values[0], smooth)


def _stribeck_compiled(values: list[float], smooth: float) -> CompiledLaw:
    fc, fs, vs = values
    return "stribeck_friction", (fc, max(fs - fc, 0.0), max(abs(vs), 1e-300), smooth)


def _cubic_compiled(values: list[float], smooth: float) -> CompiledLaw:
    return "cubic_spring", (values[0], values[1])


def _quadratic_damping_compiled(
    values: list[float], smooth: float
) -> tuple[str, tuple[float, ...]]:
    return "quadratic_damping", (values[0],)


def soft_saturation(u: np.ndarray, limit: float, sharpness: float) -> np.ndarray:
    """Return ``u / (1 + |u/U|^p)^(1/p)``: a saturation at ±U, hard as ``p → ∞``."""
    ratio = np.abs(u / limit)
    with np.errstate(over="ignore"):
        return u / np.power(1.0 + np.power(ratio, sharpness), 1.0 / sharpness)


def deadzone(u: np.ndarray, width: float) -> np.ndarray:
    """Return ``sign(u)·max(|u| − D, 0)``: no output inside ``|u| < D``."""
    return np.sign(u) * np.maximum(np.abs(u) - width, 0.0)


#: Largest |curvature·duration| of ``sensor_bias_drift``: the drift's rate changes at most
#: e^10-fold over the recording.
DRIFT_CURVATURE_MAX = 10.0


def bias_drift(t: np.ndarray, rate: float, curvature: float) -> np.ndarray:
    """Return a sensor's drift ``rate·(1 − exp(−ρ·t))/ρ`` at times ``t`` (s), shape of ``t``.

    A drift whose rate changes exponentially, ``rate·exp(−ρ·t)``: ``ρ > 0`` settles (a sensor
    warming up, the first-order thermal drift), ``ρ < 0`` accelerates, ``ρ = 0`` is the
    straight line ``rate·t``. A straight line fitted on the training part overshot a settling
    drift on the choosing part: strong drifts (signal-to-noise 4–8) read ``unexplained``.
    """
    t = np.asarray(t, dtype=float)
    if abs(curvature) * float(np.max(np.abs(t), initial=0.0)) < 1e-9:
        return rate * t
    return rate * -np.expm1(-curvature * t) / curvature


def fractional_delay(u: np.ndarray, delay_samples: float) -> np.ndarray:
    """Return ``u`` delayed by a non-negative, possibly fractional number of samples.

    ``u_d[k] = (1 − f)·u[k − n] + f·u[k − n − 1]`` with ``n + f = delay_samples``; samples
    before the start repeat ``u[0]``.
    """
    delay_samples = max(float(delay_samples), 0.0)
    whole = int(math.floor(delay_samples))
    frac = delay_samples - whole
    n = len(u)
    if whole >= n:
        return np.full(n, u[0])
    padded = np.concatenate([np.full(whole + 1, u[0]), u])
    shifted = padded[1 : n + 1]  # u[k - whole]
    shifted_more = padded[:n]  # u[k - whole - 1]
    return (1.0 - frac) * shifted + frac * shifted_more


def smooth_quantize(s: np.ndarray, step: float, noise_std: float) -> np.ndarray:
    """Return ``E[q·round((s + ε)/q)]`` for ``ε ~ N(0, σ²)``, the MSE-best quantized prediction.

    Notes
    -----
    ``q·round(s/q) − s`` is a sawtooth with Fourier series
    ``Σ_m (q/(π m))·(−1)^m·sin(2π m s/q)``; averaging over Gaussian noise before the quantizer
    damps term m by ``exp(−2π² m² σ²/q²)``. With ``σ → 0`` this is the hard staircase; with
    ``σ ≳ q/2`` it is ``s``: a quantizer finer than the noise is invisible in the mean.
    """
    step = abs(step)
    if step <= 0:
        return s
    sigma = max(noise_std, step / 60.0)
    out = s.copy()
    phase = 2.0 * np.pi * s / step
    for m in range(1, 61):
        damp = math.exp(-2.0 * math.pi**2 * m * m * sigma * sigma / (step * step))
        if damp < 1e-5:
            break
        out += (step / (math.pi * m)) * (-1.0) ** m * damp * np.sin(m * phase)
    return out


#: Above this noise-to-step ratio the quantizer's conditional variance is ``σ² + q²/12``
#: up to terms of order ``exp(−2π²·ratio²)`` (< 1e-34 at 2): Sheppard's correction.
_SHEPPARD_RATIO = 2.0

#: Rows per block in :func:`quantization_variance`: bounds its temporaries at a few MB.
_QUANTIZATION_BLOCK = 1 << 15


def quantization_variance(s: np.ndarray, step: float, noise_std: float) -> float:
    """Return the mean over ``s`` of ``Var(q·round((s + ε)/q) | s)``, ``ε ~ N(0, σ²)``.

    The part of a quantizer's output that no prediction can remove: with noise before the
    quantizer the quantization error is itself random.

    Parameters
    ----------
    s : ndarray, shape (T,)
        Noise-free signal before the quantizer (signal units).
    step : float
        Quantizer step ``q`` (signal units).
    noise_std : float
        Standard deviation ``σ`` of the Gaussian noise before the quantizer (signal units).

    Returns
    -------
    float
        The mean conditional variance (signal units squared); 0 when ``σ`` or ``q`` is not
        positive.

    Notes
    -----
    For ``σ ≥ 2q`` the closed form ``σ² + q²/12`` holds to within ``exp(−2π²σ²/q²)`` of the
    variance; below that the exact sum runs over the ``≤ 35`` levels within ``8σ`` of each
    sample, in blocks of rows. Memory is O(1) beyond ``s`` whatever the values' magnitudes.

    Examples
    --------
    >>> s = np.linspace(0.0, 1.0, 1001)
    >>> round(quantization_variance(s, 0.1, 1.0) / (1.0 + 0.1**2 / 12), 12)
    1.0
    >>> quantization_variance(s, 0.1, 0.0)
    0.0
    """
    if not (noise_std > 0 and step > 0) or len(s) == 0:
        return 0.0
    if noise_std >= _SHEPPARD_RATIO * step:
        return float(noise_std**2 + step**2 / 12.0)
    total = 0.0
    for start in range(0, len(s), _QUANTIZATION_BLOCK):
        total += _quantization_variance_sum(s[start : start + _QUANTIZATION_BLOCK], step, noise_std)
    return total / len(s)


def _quantization_variance_sum(s: np.ndarray, step: float, noise_std: float) -> float:
    """Return the sum over ``s`` of the exact conditional variance (``σ < 2q``, ≤ 35 levels).

    Levels within ``8σ`` of each sample, measured from the sample (variance is shift-free, so
    the truncated mass, < 1.3e-15, does not scale with ``s²``), probabilities renormalised.
    """
    from scipy.special import ndtr

    reach = int(math.ceil(8 * noise_std / step)) + 1
    levels = np.round(s / step)[:, None] + np.arange(-reach, reach + 1)[None, :]
    offsets = levels * step - s[:, None]
    prob = ndtr((offsets + 0.5 * step) / noise_std) - ndtr((offsets - 0.5 * step) / noise_std)
    prob /= np.sum(prob, axis=1, keepdims=True)
    mean = np.sum(prob * offsets, axis=1)
    return float(np.sum(np.sum(prob * offsets**2, axis=1) - mean**2))


def quantizer_log_density(
    y: np.ndarray,
    s: np.ndarray,
    step: float,
    offset: float,
    noise_before: float,
    noise_after: float,
) -> np.ndarray:
    """Return ``log p(y[k] | s[k])`` of a quantizer between two noises, shape ``(T,)``.

    ``y = offset + q·round((s − offset + ε_b)/q) + ε_a`` with ``ε_b ~ N(0, σ_b²)``,
    ``ε_a ~ N(0, σ_a²)``: a Gaussian mixture over the levels within ``8σ_b`` of each sample,
    level ``l`` weighted by ``P(l | s) = Φ((l·q + q/2 − s')/σ_b) − Φ((l·q − q/2 − s')/σ_b)``.
    Values that sit on a lattice (small ``σ_a``) are far likelier under it than under any
    Gaussian as wide as the quantization error: this is how a quantizer is told apart when the
    noise before it makes its staircase unpredictable. Rows are processed in blocks (memory
    O(block·levels)).

    Parameters
    ----------
    y, s : ndarray, shape (T,)
        Recorded output and the noise-free prediction before the quantizer (signal units).
    step, offset : float
        Quantizer step ``q > 0`` and lattice offset (signal units).
    noise_before, noise_after : float
        ``σ_b ≥ 0`` and ``σ_a > 0`` (signal units).

    Examples
    --------
    >>> y = np.array([0.0, 0.1, 0.2])
    >>> bool(np.all(quantizer_log_density(y, y, 0.1, 0.0, 0.0, 0.001) > 5.0))
    True
    """
    from scipy.special import logsumexp, ndtr

    sigma_b = max(float(noise_before), 1e-6 * step)
    reach = int(math.ceil(8 * sigma_b / step)) + 1
    out = np.empty(len(y))
    for start in range(0, len(y), _QUANTIZATION_BLOCK):
        rows = slice(start, start + _QUANTIZATION_BLOCK)
        shifted = s[rows] - offset
        levels = np.round(shifted / step)[:, None] + np.arange(-reach, reach + 1)[None, :]
        centre = levels * step - shifted[:, None]
        prob = ndtr((centre + 0.5 * step) / sigma_b) - ndtr((centre - 0.5 * step) / sigma_b)
        residual = (y[rows] - offset)[:, None] - levels * step
        log_normal = -0.5 * (residual / noise_after) ** 2 - math.log(
            noise_after * math.sqrt(2 * math.pi)
        )
        out[rows] = logsumexp(log_normal, b=np.maximum(prob, 1e-300), axis=1)
    return out


def refine_lattice(y: np.ndarray, step: float, offset: float, rounds: int = 3):
    """Return ``(q, offset, blur)``: a lattice refined by least squares on its level numbers.

    Each value is given its level ``l = round((y − offset)/q)``; regressing ``y`` on ``l``
    gives the step and offset exactly when the values sit on a lattice (a grid search leaves
    an error of a per cent or so, which the far levels multiply); ``blur`` is the residual's
    standard deviation (noise after the quantizer). Stops when the levels no longer change.

    Examples
    --------
    >>> y = 0.37 * np.arange(-6, 7) + 0.05
    >>> [round(v, 9) for v in refine_lattice(y, 0.35, 0.0)]
    [0.37, 0.05, 0.0]
    """
    levels = None
    for _ in range(rounds):
        new_levels = np.round((y - offset) / step)
        if levels is not None and np.array_equal(new_levels, levels):
            break
        levels = new_levels
        if np.ptp(levels) == 0:
            break
        slope, intercept = np.polyfit(levels, y, 1)
        if not slope > 0:
            break
        step, offset = float(slope), float(intercept)
    blur = float(np.std(y - offset - step * np.round((y - offset) / step)))
    return step, offset, blur


def find_lattice(y: np.ndarray, low: float, high: float, n_grid: int = 400):
    """Return ``(q, offset, concentration)`` of the coarsest lattice the values ``y`` sit on.

    For each step ``q`` on a log grid in ``[low, high]`` the concentration
    ``R(q) = |mean(exp(2πi·y/q))|`` is 1 when every value is a multiple of ``q`` (plus an
    offset), ``exp(−2π²σ²/q²)`` when noise of std σ is added after the quantizer, and about
    ``1/√n`` for values on no lattice. The coarsest step whose concentration is at least half
    the best is returned (a lattice of step q also lies on q/2, q/3, …), refined locally.
    """
    grid = np.geomspace(low, high, n_grid)
    sample = y[:: max(1, len(y) // 5000)]
    conc = np.array([abs(np.mean(np.exp(2j * np.pi * sample / q))) for q in grid])
    best = conc.max()
    index = int(np.flatnonzero(conc >= 0.5 * best)[-1])
    index = max(range(max(0, index - 3), min(n_grid, index + 4)), key=lambda i: conc[i])
    while index > 0 and conc[index - 1] > conc[index]:  # up to the peak: a coarse lattice's
        index -= 1  # shoulder (few levels) can stay above half the best far from its peak
    fine = np.linspace(grid[max(0, index - 1)], grid[min(n_grid - 1, index + 1)], 41)
    fine_conc = [abs(np.mean(np.exp(2j * np.pi * sample / q))) for q in fine]
    q = float(fine[int(np.argmax(fine_conc))])
    phase = np.angle(np.mean(np.exp(2j * np.pi * y / q)))
    return q, float(phase * q / (2 * np.pi)), float(max(fine_conc))


def _saturation_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return soft_saturation(u, theta[0], theta[1])


def _deadzone_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return deadzone(u, theta[0])


def _delay_input(u: np.ndarray, theta: Sequence[float], dt: float) -> np.ndarray:
    return fractional_delay(u, theta[0] / dt)


def _scale_output(lag, bias, t, theta) -> np.ndarray:
    return theta[0] * lag + bias


def _drift_output(lag, bias, t, theta) -> np.ndarray:
    return lag + bias + bias_drift(t, theta[0], theta[1])


def _quantizer_output(lag, bias, t, theta) -> np.ndarray:
    step, offset, before = theta
    return offset + smooth_quantize(lag + bias - offset, step, before)


# --- the catalogue ----------------------------------------------------------------------


#: Longest extra delay a delay candidate may take, in samples.
MAX_DELAY_SAMPLES = 25


def _centre_bounds(s: Scales) -> tuple[float, float]:
    """Return the bounds of a spring's centre: 3 standard deviations about the mean, and 0."""
    reach = 3.0 * s.output_std
    return (min(s.output_mean - reach, -reach), max(s.output_mean + reach, reach))


def _delay_bounds(s: Scales) -> Bounds:
    return [(0.0, MAX_DELAY_SAMPLES * s.dt)]


def _delay_starts(s: Scales) -> list[list[float]]:
    return [[(d + 0.5) * s.dt] for d in range(MAX_DELAY_SAMPLES)]


EFFECTS: tuple[Effect, ...] = (
    Effect(
        "actuator_saturation",
        ("M0",),
        ("U", "p"),
        ("input units", "1"),
        "input",
        "u -> u / (1 + |u/U|^p)^(1/p)  (saturation at ±U, sharpness p)",
        lambda s: [(0.02 * s.input_max, 3.0 * s.input_max), (1.0, 40.0)],
        lambda s: [[f * s.input_max, p] for f in (0.4, 0.7, 1.0) for p in (3.0, 12.0)],
        lambda s: [s.input_max, 5.0],
        input_map=_saturation_input,
    ),
    Effect(
        "actuator_deadzone",
        ("M0",),
        ("D",),
        ("input units",),
        "input",
        "u -> sign(u)·max(|u| − D, 0)",
        lambda s: [(0.0, 0.9 * s.input_max)],
        lambda s: [[f * s.input_max] for f in (0.05, 0.2, 0.45)],
        lambda s: [0.1 * s.input_max],
        input_map=_deadzone_input,
    ),
    Effect(
        "actuator_delay",
        ("M0",),
        ("delay",),
        ("s",),
        "delay",
        "u_cmd[k] -> u_cmd[k − delay/dt]  (fractional, linear interpolation)",
        _delay_bounds,
        _delay_starts,
        lambda s: [s.dt],
        input_map=_delay_input,
    ),
    Effect(
        "coulomb_friction",
        ("M1",),
        ("Fc",),
        ("input units (force)",),
        "force",
        "F = Fc·tanh(v / v_s),  v_s = 0.01·std(v)",
        lambda s: [(0.0, 3.0 * s.input_max)],
        lambda s: [[0.05 * s.input_std]],
        lambda s: [0.1 * s.input_std],
        force_law=_coulomb_law,
        compiled_law=_coulomb_compiled,
    ),
    Effect(
        "stribeck_friction",
        ("M1",),
        ("Fc", "Fs", "vs"),
        ("input units (force)", "input units (force)", "output units / s"),
        "force",
        "F = (Fc + max(Fs − Fc, 0)·exp(−(v/vs)²))·tanh(v / v_s),  v_s = 0.01·std(v)",
        lambda s: [
            (0.0, 3.0 * s.input_max),
            (0.0, 3.0 * s.input_max),
            (0.05 * s.velocity_std, 0.5 * s.velocity_std),
        ],
        lambda s: [[0.05 * s.input_std, 0.1 * s.input_std, f * s.velocity_std] for f in (0.1, 0.3)],
        lambda s: [0.1 * s.input_std, 0.1 * s.input_std, 0.1 * s.velocity_std],
        nests=("coulomb_friction",),
        nested_starts=_stribeck_from_coulomb,
        departure=_breakaway_excess,
        force_law=_stribeck_law,
        compiled_law=_stribeck_compiled,
    ),
    Effect(
        "cubic_stiffness",
        ("M1",),
        ("k3", "x0"),
        ("input units / output units^3", "output units"),
        "force",
        "F = k3·(x − x0)^3  (x0: the spring's centre in recording units)",
        lambda s: [
            (-50.0 * s.stiffness / s.output_std**2, 50.0 * s.stiffness / s.output_std**2),
            _centre_bounds(s),
        ],
        lambda s: [[0.0, 0.0], [0.0, s.output_mean]],
        lambda s: [0.1 * s.stiffness / s.output_std**2, s.output_std],
        force_law=_cubic_law,
        compiled_law=_cubic_compiled,
    ),
    Effect(
        "quadratic_damping",
        ("M1",),
        ("c2",),
        ("input units·s²/output units²",),
        "force",
        "F = c2·v·|v|",
        lambda s: [(0.0, 50.0 * s.input_std / s.velocity_std**2)],
        lambda s: [[0.05 * s.input_std / s.velocity_std**2]],
        lambda s: [0.1 * s.input_std / s.velocity_std**2],
        force_law=_quadratic_damping_law,
        compiled_law=_quadratic_damping_compiled,
    ),
    Effect(
        "sensor_quantization",
        ("M2a", "M2b"),
        ("q", "offset", "noise_before"),
        ("output units", "output units", "output units"),
        "output",
        "y = offset + q·round((lag + bias − offset + e)/q) + e',  e ~ N(0, noise_before²)",
        lambda s: [(1e-12, 4.0 * s.output_std), (-np.inf, np.inf), (0.0, np.inf)],
        lambda s: [[]],
        lambda s: [max(s.noise_std, 0.01 * s.output_std), s.output_std, s.noise_std or 1.0],
        output_map=_quantizer_output,
        lattice=True,
    ),
    Effect(
        "sensor_scale_error",
        ("M2a", "M2b"),
        ("gain",),
        ("1",),
        "output",
        "y = gain·lag + bias",
        lambda s: [(0.1, 10.0)],
        lambda s: [[1.0]],
        lambda s: [0.1],
        linear_form=True,
        output_map=_scale_output,
    ),
    Effect(
        "sensor_bias_drift",
        ("M2a", "M2b"),
        ("rate", "curvature"),
        ("output units / s", "1 / s"),
        "output",
        "y = lag + bias + rate·(1 − exp(−ρ·t))/ρ,  ρ = curvature (ρ = 0: rate·t)",
        lambda s: [
            (-100.0 * s.output_std / s.duration, 100.0 * s.output_std / s.duration),
            (-DRIFT_CURVATURE_MAX / s.duration, DRIFT_CURVATURE_MAX / s.duration),
        ],
        lambda s: [[0.0, 0.0], [0.0, 3.0 / s.duration], [0.0, -1.0 / s.duration]],
        lambda s: [0.1 * s.output_std / s.duration, 1.0 / s.duration],
        output_map=_drift_output,
    ),
    Effect(
        "sensor_delay",
        ("M2a", "M2b"),
        ("delay",),
        ("s",),
        "delay",
        "x[k] -> x[k − delay/dt]  (fractional, linear interpolation)",
        _delay_bounds,
        _delay_starts,
        lambda s: [s.dt],
        input_map=_delay_input,
    ),
    Effect(
        PARAMETER_MISMATCH,
        ("M0", "M1", "M2a", "M2b", "M3", "M4"),
        (),
        (),
        "linear",
        "the module's own linear parameters re-fitted (no new term)",
        lambda s: [],
        lambda s: [[]],
        lambda s: [],
        linear_form=True,
    ),
)

#: Every name a diagnosis can report as ``effect``.
EFFECT_NAMES: tuple[str, ...] = (*(effect.name for effect in EFFECTS), NONE, UNEXPLAINED)


def effects_for_module(module: str, *, include_mismatch: bool = True) -> list[Effect]:
    """Return the candidate effects of ``module`` (``parameter_mismatch`` first if included)."""
    found = [e for e in EFFECTS if module in e.modules and not e.refits_linear]
    if include_mismatch:
        found.insert(0, effect_by_name(PARAMETER_MISMATCH))
    return found


def effect_by_name(name: str) -> Effect:
    """Return the :class:`Effect` called ``name``."""
    for effect in EFFECTS:
        if effect.name == name:
            return effect
    raise KeyError(f"unknown effect {name!r}; known: {', '.join(e.name for e in EFFECTS)}")
