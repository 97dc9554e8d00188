"""The candidate effects of a unit of a twin table: where a user would look for them.

Specification: docs/gap.md §Twin file (Which, on any module). Effects attach

- at a unit's **input** signal: ``input_saturation`` (symmetric limit ``U`` about 0, its knee
  as sharp as ``p`` says: ``u/(1 + |u/U|^p)^(1/p)``, a hard clip as ``p`` grows),
  ``input_deadzone`` (``sign(u)·max(|u| − D, 0)``), ``input_delay`` (``delay`` s, fractional);
- at a recorded **output**: ``output_saturation`` (clipped to ``[low, high]``),
  ``output_bias_drift`` (``b0 + b1·τ + b2·τ²``, ``τ`` the time over the recording's length),
  ``output_scale_error`` (``gain·y``), ``output_delay`` (``delay`` s), ``output_quantization``
  (a lattice of step ``q`` found in the recorded values);
- at a **state**: ``state_limit`` (an upper or a lower bound, ``limit``: an overflow, an end
  stop) and a missing term ``θ·f(z)`` in a state's derivative, ``z = (s_i − c)/σ`` a state the
  derivative reads, scaled by its spread ``σ`` (and centred on its mean ``c`` for the cubic):
  ``state_cubic`` (``z³``), ``state_abs_square`` (``|z|·z``), ``state_sign`` (``tanh(z/0.01)``,
  a smoothed sign);
- ``parameter_mismatch``: every declared param re-fitted (not with ``--calibrate``, whose twin
  already is that re-fit).

A ``mass_spring_damper`` block keeps its named effects: the sign, cubic and ``|v|·v`` terms of
its own states in its velocity's derivative are ``coulomb_friction`` (``Fc``),
``cubic_stiffness`` (``k3``) and ``quadratic_damping`` (``c2``), reported in force units; the
cubic stiffness is centred on the spring's rest ``x = 0`` (the block's ``k·x``), not on the mean.
``Variant.at`` names the signal, the state whose derivative gains the term (or the limited
state), or nothing for a re-fit (the report names the param furthest off).
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from dtwin.gap.effects import find_lattice
from dtwin.gap.table_fit import UnitData, Variant
from dtwin.twin.simulate import Assignment

__all__ = [
    "STATE_TERMS",
    "candidate_variants",
    "lattice_of",
    "twin_variant",
    "quantizer_mean",
    "slew_probes",
    "with_quantizer_starts",
    "skew_freed",
]

#: The missing terms of a state's derivative: name → the function of ``z`` (text).
STATE_TERMS: dict[str, str] = {
    "state_cubic": "{z}**3",
    "state_abs_square": "abs({z})*({z})",
    "state_sign": "tanh(({z})/0.01)",
}
#: The mass-spring-damper's names for the terms of its own states in ``dv/dt``:
#: (term, state) → (effect, reported param, force per unit of θ as a function of m and σ).
MSD_NAMES = {
    ("state_sign", "v"): ("coulomb_friction", "Fc", lambda m, s: -m),
    ("state_cubic", "x"): ("cubic_stiffness", "k3", lambda m, s: -m / s**3),
    ("state_abs_square", "v"): ("quadratic_damping", "c2", lambda m, s: -m / s**2),
}
#: Largest slope of each term's ``f(z)`` over ``|z| ≤ 4``, per unit of ``θ/σ``.
TERM_SLOPES: dict[str, float] = {"state_cubic": 48.0, "state_abs_square": 8.0, "state_sign": 100.0}
#: Built-in blocks whose states get no state effect (a lag's state is its filter's).
NO_STATE_EFFECTS = frozenset({"lag"})
#: (block, state) whose derivative is a definition (a mass-spring-damper's ``x' = v``): no
#: missing term is added there (on the EMPS axis a cubic term of ``v`` in ``x'`` was named
#: over the friction in ``v'``); its limits (an end stop) are kept.
KINEMATIC_STATES = frozenset({("mass_spring_damper", "x")})
#: Delays tried before fitting a delay, in samples.
DELAY_GRID = (0.5, 1, 2, 4, 6, 9, 13, 18, 25)


def twin_variant(data: UnitData) -> Variant:
    """Return the unit's twin as a :class:`Variant` (no effect)."""
    return Variant("linear", None, data.model)


def _number(value: float) -> str:
    return repr(float(value))


def _shift(values: np.ndarray, delay: float, dt: float) -> np.ndarray:
    """``values`` delayed by ``delay`` s (linear interpolation; each run's first value held before).

    A run is a stretch of finite rows: a simulation over windows that are not adjacent (a
    capped fit) is NaN between them, and each window's start is held as the recording's first
    value is. Shifted across the gap, a window's first samples read NaN, which the fit counts
    as a diverged run: every capped fit of an output delay lost to that penalty.
    """
    n = len(values)
    finite = np.isfinite(values) if values.ndim == 1 else np.isfinite(values).all(axis=1)
    first = np.maximum.accumulate(np.where(finite, -1, np.arange(n))) + 1  # each run's start
    samples = np.clip(np.arange(n) - delay / dt, np.minimum(first, n - 1), n - 1)
    low = np.floor(samples).astype(int)
    high = np.minimum(low + 1, n - 1)
    frac = (samples - low)[:, None] if values.ndim == 2 else samples - low
    step = np.where(frac > 0, frac * (values[high] - values[low]), 0.0)
    gap = ~finite[:, None] if values.ndim == 2 else ~finite
    return np.where(gap, np.nan, values[low] + step)


#: Fewest samples a delay candidate may reach, and the share of a window it may reach beyond.
DELAY_SAMPLES, DELAY_WINDOW_SHARE = 30, 0.25


def _max_delay(data: UnitData) -> float:
    """Return the longest delay a candidate is fitted to (s): a quarter of a window, at least 30.

    A window is 10 of the unit's slowest time constants; a thermal sensor's 42-sample delay (a
    tenth of its time constant) stopped at 30 samples and read as a slower sensor.
    """
    return max(DELAY_SAMPLES, DELAY_WINDOW_SHARE * data.window) * data.dt


def _input_variants(data: UnitData) -> list[Variant]:
    out = []
    for i, signal in enumerate(data.spec.inputs):
        u = data.inputs[:, i]
        reach = float(np.max(np.abs(u)))
        spread = float(np.std(u)) or 1.0
        u_name, d_name, delay_name = f"_e_U_{i}", f"_e_D_{i}", f"_e_delay_{i}"
        p_name, s_name = f"_e_p_{i}", f"_e_skew_{i}"
        # on an input that takes both signs the widths may differ by direction: the skew is held
        # at 0 (a symmetric dead zone) until the full fit frees it (table_diagnose._full_fit)
        skewed = bipolar(u)

        def saturate(values, theta, _data, i=i, name=u_name, sharpness=p_name):
            out = values.copy()
            out[:, i] = soft_saturation(values[:, i], theta[name], theta[sharpness])
            return out

        def deadzone(values, theta, _data, i=i, name=d_name, skew=s_name):
            out = values.copy()
            direction = np.sign(values[:, i])
            width = theta[name] * (1.0 + theta.get(skew, 0.0) * direction)
            out[:, i] = direction * np.maximum(np.abs(values[:, i]) - width, 0)
            return out

        def delay(values, theta, data, i=i, name=delay_name):
            out = values.copy()
            out[:, i] = _shift(values[:, i], theta[name], data.dt)
            return out

        model = data.model
        out += [
            Variant("input_saturation", signal, model, (u_name, p_name),
                    {u_name: 0.8 * reach, p_name: SHARPNESS_START},
                    {u_name: (1e-3 * spread, 2 * reach), p_name: SHARPNESS_BOUNDS},
                    {u_name: spread, p_name: SHARPNESS_START / 2}, input_map=saturate),
            _deadzone_variant(signal, model, d_name, s_name if skewed else None, spread, reach,
                              deadzone),
            Variant("input_delay", signal, model, (delay_name,), {delay_name: data.dt},
                    {delay_name: (0.0, _max_delay(data))}, {delay_name: data.dt}, input_map=delay),
        ]  # fmt: skip
    return out


def _deadzone_variant(signal, model, d_name, s_name, spread, reach, deadzone) -> Variant:
    """Return the ``input_deadzone`` variant: width ``d_name``; ``s_name``, its skew, held at 0.

    The skew is not a param of the variant (its start, bounds and scale are kept for
    :func:`skew_freed`): the dead zone is screened and first fitted symmetric.
    """
    starts, bounds, scales = {d_name: 0.1 * spread}, {d_name: (0.0, reach)}, {d_name: spread}
    if s_name is not None:
        starts[s_name], bounds[s_name], scales[s_name] = 0.0, (-SKEW_LIMIT, SKEW_LIMIT), 0.1
    return Variant("input_deadzone", signal, model, (d_name,), starts, bounds, scales,
                   input_map=deadzone)  # fmt: skip


def skew_freed(variant: Variant) -> Variant | None:
    """Return a dead zone ``variant`` with its widths by direction free, or None (no skew)."""
    extra = tuple(name for name in variant.bounds if name not in variant.effect_params)
    if variant.name != "input_deadzone" or not extra:
        return None
    return replace(variant, effect_params=(*variant.effect_params, *extra))


#: Largest relative difference of a dead zone's widths by direction: ``D·(1 ± skew)``.
SKEW_LIMIT = 0.6
#: Share of an input's largest magnitude it must reach on each side of zero to be bipolar.
BIPOLAR_SHARE = 0.1


def bipolar(u: np.ndarray) -> bool:
    """Return whether ``u`` (``(n,)``) reaches :data:`BIPOLAR_SHARE` of its reach both ways."""
    finite = u[np.isfinite(u)]
    if finite.size == 0:
        return False
    reach = float(np.max(np.abs(finite)))
    share = BIPOLAR_SHARE * reach
    return bool(reach > 0 and finite.min() < -share and finite.max() > share)


#: The saturation's knee sharpness ``p``: its start (a clip rounded by 3.4 % of ``U`` at
#: ``|u| = U``, by under 1 % beyond ±10 % of it) and bounds (a knee as round as ``tanh``'s to
#: a clip rounded by 0.35 %).
SHARPNESS_START, SHARPNESS_BOUNDS = 20.0, (1.5, 200.0)


def soft_saturation(u: np.ndarray, limit: float, sharpness: float) -> np.ndarray:
    """Return ``u/(1 + |u/U|^p)^(1/p)``: a saturation at ``±U`` whose knee is as sharp as ``p``.

    Linear for ``|u| ≪ U`` and ``±U`` for ``|u| ≫ U`` whatever ``p``; a hard clip as ``p``
    grows, a knee as round as ``tanh``'s at ``p ≈ 2``. A real actuator's limit is seldom the
    clip the textbook draws (a drive's current limit, a pump's flow at full speed), and a
    clip fitted to a rounded knee leaves an error that grows with the recording's length.
    ``u`` shape ``(n,)`` (input units); written with ``logaddexp`` so that ``|u/U|^p`` never
    overflows.
    """
    with np.errstate(divide="ignore"):
        log_ratio = np.log(np.abs(u) / limit)
    return u * np.exp(-np.logaddexp(0.0, sharpness * log_ratio) / sharpness)


def _with_drift(values, theta, data, *, column: int, names, sign: float) -> np.ndarray:
    """Return ``values`` with a drift added (``sign`` 1) or removed (−1) in one column.

    The drift is ``b0 + b1·τ + b2·τ²`` (``names`` its three params, signal units), ``τ`` the
    time over the run's duration; ``values`` shape ``(n_samples, n_columns)``.
    """
    tau = np.arange(len(values)) * data.dt / (data.n_samples * data.dt)
    out = values.copy()
    out[:, column] += sign * (theta[names[0]] + theta[names[1]] * tau + theta[names[2]] * tau**2)
    return out


def _with_gain(values, theta, _data, *, column: int, name: str, inverse: bool) -> np.ndarray:
    """Return ``values`` with one column times the gain ``theta[name]`` (or divided by it)."""
    out = values.copy()
    if inverse:
        out[:, column] /= theta[name] or 1.0
    else:
        out[:, column] *= theta[name]
    return out


def _sensor_variants(data: UnitData, produced: frozenset[str]) -> list[Variant]:
    """Return the candidates of a recorded input another module produces being read wrong.

    The unit is driven by ``recorded − drift`` (``output_bias_drift``) or ``recorded / gain``
    (``output_scale_error``) instead of the recorded values; the answer names the signal, so
    its module is the producer's (docs/gap.md §Your own twin: a sensor error on a signal that
    feeds another module is blamed on the module that produces it).
    """
    out = []
    for i, signal in enumerate(data.spec.inputs):
        if signal not in produced:
            continue
        spread = float(np.std(data.inputs[slice(*data.parts["train"]), i])) or 1.0
        drifts = tuple(f"_e_{p}_in{i}" for p in ("b0", "b1", "b2"))
        gain = f"_e_gain_in{i}"
        drift = partial(_with_drift, column=i, names=drifts, sign=-1.0)
        scale = partial(_with_gain, column=i, name=gain, inverse=True)

        out += [
            Variant("output_bias_drift", signal, data.model, drifts, dict.fromkeys(drifts, 0.0),
                    dict.fromkeys(drifts, (-np.inf, np.inf)), dict.fromkeys(drifts, spread),
                    input_map=drift),
            Variant("output_scale_error", signal, data.model, (gain,), {gain: 1.0},
                    {gain: (0.1, 10.0)}, {gain: 0.1}, input_map=scale, linear_form=True),
        ]  # fmt: skip
    return out


def _output_variants(data: UnitData) -> list[Variant]:
    out = []
    train = slice(*data.parts["train"])
    for o, signal in enumerate(data.spec.outputs):
        y = data.outputs[train, o]
        spread = float(np.std(y)) or 1.0
        mid = float(np.median(y))
        names = [f"_e_{p}_{o}" for p in ("low", "high", "b0", "b1", "b2", "gain", "delay")]
        low, high, b0, b1, b2, gain, delay = names

        def clip(values, theta, _data, o=o, low=low, high=high):
            out = values.copy()
            out[:, o] = np.clip(values[:, o], theta[low], theta[high])
            return out

        def lag(values, theta, data, o=o, delay=delay, sign=1.0):
            out = values.copy()
            out[:, o] = _shift(values[:, o], sign * theta[delay], data.dt)
            return out

        drift, undrift = (
            partial(_with_drift, column=o, names=(b0, b1, b2), sign=sign) for sign in (1.0, -1.0)
        )
        scale, unscale = (
            partial(_with_gain, column=o, name=gain, inverse=inverse) for inverse in (False, True)
        )

        wide = (float(np.min(y)) - spread, float(np.max(y)) + spread)
        drifts = (b0, b1, b2)
        model = data.model
        out += [
            Variant("output_saturation", signal, model, (low, high),
                    {low: float(np.min(y)), high: float(np.max(y))},
                    {low: (wide[0], mid), high: (mid, wide[1])}, {low: spread, high: spread},
                    output_map=clip),
            Variant("output_bias_drift", signal, model, drifts, dict.fromkeys(drifts, 0.0),
                    dict.fromkeys(drifts, (-np.inf, np.inf)), dict.fromkeys(drifts, spread),
                    output_map=drift, output_inverse=undrift),
            Variant("output_scale_error", signal, model, (gain,), {gain: 1.0}, {gain: (0.0, 10.0)},
                    {gain: 0.1}, output_map=scale, linear_form=True, output_inverse=unscale),
            Variant("output_delay", signal, model, (delay,), {delay: data.dt},
                    {delay: (0.0, _max_delay(data))}, {delay: data.dt}, output_map=lag,
                    output_inverse=partial(lag, sign=-1.0)),
        ]  # fmt: skip
        out += _quantization_variant(data, o, signal, y, spread)
    return out


def lattice_of(y: np.ndarray) -> tuple[float, float, float]:
    """Return ``(q, offset, concentration)`` of the lattice the values ``y`` sit on.

    Values a quantizer wrote after the noise sit exactly on their lattice, so the smallest
    gap between distinct values is its step ``q`` (or a multiple of it): that step is taken
    when its concentration ``|mean(exp(2πi·y/q))|`` is at least 0.9, which holds however many
    levels the values span. Otherwise the log-grid search of
    :func:`~dtwin.gap.effects.find_lattice` (steps 10⁻⁴ to 0.5 of the spread; its 2 % grid
    resolves a lattice of up to about 25 levels), whose concentration counts only when the
    values visited are concentrated too (:data:`VISITED_MIN`, :func:`_visited_concentration`).
    ``y`` shape ``(n,)``, output units.
    """
    y = np.asarray(y, dtype=float)
    spread = float(np.ptp(y))
    if not spread > 0:
        return 0.0, 0.0, 0.0
    levels = np.unique(y)
    gaps = np.diff(levels)
    gaps = gaps[gaps > 1e-9 * spread]
    if len(gaps) and len(levels) <= len(y) // 2:
        step = float(gaps.min())
        phasor = np.mean(np.exp(2j * np.pi * y / step))
        if abs(phasor) >= 0.9:
            return step, float(np.angle(phasor) * step / (2 * np.pi)), float(abs(phasor))
    q, offset, concentration = find_lattice(y, 1e-4 * spread, 0.5 * spread)
    visited = _visited_concentration(y, q)
    return q, offset, concentration if visited >= VISITED_MIN else visited


#: Cells per lattice step in which :func:`_visited_concentration` reads the values visited.
VISIT_CELLS = 16
#: Least concentration of the visited values for a lattice the log-grid search found: a
#: quantizer blurred by noise of 5 % (8 %) of its step visits values of concentration 0.85
#: (0.70; 3,000 samples of a random walk); a heater's power on three plateaus, 0.14.
VISITED_MIN = 0.5


def _visited_concentration(y: np.ndarray, q: float) -> float:
    """Return the lattice concentration of the values ``y`` visits, not of the time spent there.

    Each visited cell (width ``q/``:data:`VISIT_CELLS`) counts once. A quantizer blurred by
    noise visits only cells near its lattice; a lag driven by steps spends most of its time on
    a few plateaus, which any step dividing their spacing fits, but visits every cell between
    them on its way (a heater's power at three plateaus read as a lattice of step 12.4 with
    concentration above 0.9 and was named ``output_quantization`` on a clean recording).
    """
    if not q > 0:
        return 0.0
    cells = np.unique(np.round(np.asarray(y, dtype=float) * VISIT_CELLS / q))
    return float(abs(np.mean(np.exp(2j * np.pi * cells / VISIT_CELLS))))


def _quantization_variant(data, o, signal, y, spread) -> list[Variant]:
    """``output_quantization`` when the recorded values sit on a lattice (else nothing).

    The recorded values are a quantizer's of the output with its noise: the prediction is
    their expectation (:func:`quantizer_mean`), with the lattice (step ``q``, phase ``c``)
    read from the recorded values and held, and the quantizer's input shift ``b`` (0 for a
    rounding quantizer, ``−q/2`` for one that truncates) and the noise before it ``σ``
    fitted (their starts: :func:`with_quantizer_starts`).
    """
    step, offset, concentration = lattice_of(y)
    if concentration < 0.5:
        return []
    names = tuple(f"_e_{p}_{o}" for p in ("q", "offset", "shift", "sigma"))
    q_name, c_name, b_name, s_name = names

    def quantize(values, theta, _data, o=o):
        out = values.copy()
        out[:, o] = quantizer_mean(
            values[:, o], theta[q_name], theta[c_name], theta[b_name], theta[s_name]
        )
        return out

    fixed = {q_name: step, c_name: offset}
    starts = {**fixed, b_name: 0.0, s_name: 0.3 * step}
    bounds = {b_name: (-step, step), s_name: (QUANTIZER_MIN_SIGMA * step, 2.0 * step)}
    scales = {b_name: 0.25 * step, s_name: 0.25 * step}
    return [
        Variant("output_quantization", signal, data.model, names, starts, bounds, scales,
                output_map=quantize, fixed=fixed)
    ]  # fmt: skip


#: Fourier terms of a quantizer's expected output (:func:`quantizer_mean`); with the noise
#: at least :data:`QUANTIZER_MIN_SIGMA` of the step the last one is damped by ``e⁻⁵⁰``.
QUANTIZER_TERMS = 32
#: Smallest noise before a quantizer, as a fraction of its step (a noise-free quantizer's
#: staircase, its edges rounded by 5 % of a step).
QUANTIZER_MIN_SIGMA = 0.05


def quantizer_mean(y: np.ndarray, q: float, c: float, b: float, sigma: float) -> np.ndarray:
    """Return ``E[c + q·round((y + b + n − c)/q)]`` for Gaussian noise ``n`` of sd ``sigma``.

    The quantizer's error is a sawtooth of ``y + b`` with Fourier series
    ``q·Σₖ (−1)^(k+1) sin(2πk(y + b − c)/q)/(πk)``; the noise damps its ``k``-th term by
    ``exp(−2π²k²σ²/q²)`` (the Gaussian's characteristic function). So the expectation is
    ``y + b`` minus the damped sawtooth: a staircase for ``σ ≪ q``, a line with a bias for
    ``σ ≳ q/2`` (the noise dithers the quantizer). Smooth in ``b`` and ``σ``, so a fit moves
    them. ``y`` shape ``(n,)``, output units; :data:`QUANTIZER_TERMS` terms.
    """
    x = np.asarray(y, dtype=float) + b
    k = np.arange(1, QUANTIZER_TERMS + 1)
    weights = (-1.0) ** (k + 1) / (np.pi * k) * np.exp(-2.0 * (np.pi * k * sigma / q) ** 2)
    keep = np.abs(weights) > 1e-6 / k
    phase = 2.0 * np.pi * np.multiply.outer((x - c) / q, k[keep])
    return x - q * (np.sin(phase) @ weights[keep])


#: Input shifts a quantizer's fit starts from, as fractions of its step (one step's grid).
QUANTIZER_SHIFTS = np.arange(-8, 8) / 16


def with_quantizer_starts(
    variant: Variant, simulated: np.ndarray, recorded: np.ndarray, noise: float
) -> Variant:
    """Return the quantizer ``variant`` starting from its noise and input shift read from data.

    The noise before the quantizer starts at what the output's noise floor ``noise`` leaves
    beyond the quantizer's own ``q²/12``; the shift at the one of :data:`QUANTIZER_SHIFTS`
    (times ``q``) whose expected output is nearest the recorded values (least squares): the
    cost is periodic in the shift, so a fit from 0 can stop in the wrong period's minimum.
    ``simulated``, ``recorded``: the output's twin simulation and its recorded values, shape
    ``(n,)`` (NaN where not simulated; output units).
    """
    q_name, c_name, b_name, s_name = variant.effect_params
    q, c = variant.fixed[q_name], variant.fixed[c_name]
    low, high = variant.bounds[s_name]
    sigma = float(np.clip(np.sqrt(max(noise**2 - q**2 / 12.0, 0.0)), low, high))
    rows = np.isfinite(simulated) & np.isfinite(recorded)
    y, r = simulated[rows], recorded[rows]
    costs = [np.sum(np.square(quantizer_mean(y, q, c, f * q, sigma) - r)) for f in QUANTIZER_SHIFTS]
    shift = float(QUANTIZER_SHIFTS[int(np.argmin(costs))] * q) if len(y) else 0.0
    return replace(variant, starts={**variant.starts, b_name: shift, s_name: sigma})


def _local_name(assignment: Assignment, slot: str) -> str | None:
    return next((local for local, target in assignment.symbols.items() if target == slot), None)


def _state_variants(data: UnitData, guess: np.ndarray, blocks: dict[str, str | None]):
    """Return the missing-term and limit candidates of every state of the unit.

    A block whose state is a modelling device rather than a physical quantity
    (:data:`NO_STATE_EFFECTS`: a lag's filter state) has none: a limit on it is its input's
    saturation seen through the lag, which the input candidates already name.
    """
    spec, model = data.spec, data.model
    train = slice(*data.parts["train"])
    out = []
    derivatives = {a.target[2:]: a for a in model.assignments if a.target.startswith("d/")}
    for j, state in enumerate(spec.states):
        if blocks.get(spec.module_of(state)) in NO_STATE_EFFECTS:
            continue
        assignment = derivatives[state]
        path = guess[train, j]
        rate = float(np.nanstd(np.diff(path))) / data.dt or 1.0
        read = [s for s in spec.states if _local_name(assignment, s) is not None]
        if (blocks.get(spec.module_of(state)), state.split(".", 1)[1]) in KINEMATIC_STATES:
            read = []  # its derivative is a definition; a missing force is in the velocity's
        for source in read:
            i = spec.states.index(source)
            values = guess[train, i]
            for term, form in STATE_TERMS.items():
                out.append(
                    _term_variant(data, assignment, state, source, values, term, form, rate, blocks)
                )
        out += _limit_variants(data, state, j, path)
    return out


def _term_variant(data, assignment, state, source, values, term, form, rate, blocks) -> Variant:
    """One missing term ``θ·f(z)`` of state ``source`` in the derivative of ``state``.

    ``z = (s − c)/σ``: the cubic centred on the state's mean (a mass-spring-damper's named
    ``cubic_stiffness`` on the spring's rest ``x = 0``, its ``k·x``'s); the sign and ``|z|·z`` about
    0 (a velocity's friction and drag), except an ``|z|·z`` that is not a mass-spring-damper's named
    ``quadratic_damping``, whose centre ``c`` is fitted (``_e_centre``, state units), started from 0
    or, when the state never reaches 0, from the end of its range nearest 0 (a body heated from the
    ambient: its coolest): a loss growing as the square of a temperature's rise grows about the
    ambient, not about 0 °C, and ``|T|·T`` about 0 °C is a different function that the twin's linear
    loss cannot take up.
    """
    module, own = state.split(".", 1)[0], state.split(".", 1)[1]
    named = None
    if blocks.get(module) == "mass_spring_damper" and own == "v":
        named = MSD_NAMES.get((term, source.split(".", 1)[1]))
    centre = float(np.nanmean(values)) if term == "state_cubic" and named is None else 0.0
    sigma = float(np.nanstd(values - centre)) or 1.0
    if term != "state_cubic":
        sigma = float(np.sqrt(np.nanmean(values**2))) or 1.0
    local = _local_name(assignment, source)
    name, report = term, None
    if named is not None:
        name, report = named[0], (named[1], named[2], f"{module}.m", sigma)
    theta, shift = "_e_theta", "_e_centre"
    params, starts = (theta,), {theta: 0.0}
    bounds, scales = {theta: (-np.inf, np.inf)}, {theta: rate}
    z = f"(({local} - {_number(centre)})/{_number(sigma)})"
    if term == "state_abs_square" and report is None:
        low, high = float(np.nanmin(values)), float(np.nanmax(values))
        z = f"(({local} - {shift})/{_number(sigma)})"
        params, starts = (theta, shift), {theta: 0.0, shift: min(max(0.0, low), high)}
        bounds[shift] = (min(low - (high - low), 0.0), max(high, 0.0))
        scales[shift] = sigma
    text = f"({assignment.text}) + {theta}*{form.format(z=z)}"
    model = data.model.variant({assignment.target: text}, extra=params)
    slope = TERM_SLOPES[term] / sigma
    return Variant(
        name, state, model, params, starts, bounds, scales, report=report,
        stiffness=lambda values: abs(values[theta]) * slope,
    )  # fmt: skip


#: Quantiles of the twin's path an upper limit's screening also starts from (a lower limit's:
#: one minus them): from the 97 % quantile a limit above every screening window's path has no
#: gradient (a thermal node held at 60.2 °C for 15 % of the run, the twin's path above it,
#: screened at the twin's own cost from 65.4 and at 0.065 of it from 50 to 62).
LIMIT_SCREEN_QUANTILES = (0.8, 0.5)


def _limit_variants(data, state, j, path) -> list[Variant]:
    """Return an upper and a lower bound on ``state`` (``path``: the twin's state, recording).

    Each starts at the 97 % (3 %) quantile of the twin's path and may reach its 10 % (90 %)
    quantile: a tank that overflows half of the time has a limit below the median of the path
    the twin, which has no limit, draws for it (one at ``h1 = 3.0`` where the twin's ``h1``
    had its median above 3 could not be reached from the median the bound was).
    """
    n_states = len(data.spec.states)
    low_q, reach_low, reach_high, high_q = np.nanquantile(path, [0.03, 0.1, 0.9, 0.97])
    above = np.nanquantile(path, LIMIT_SCREEN_QUANTILES)
    below = np.nanquantile(path, [1.0 - q for q in LIMIT_SCREEN_QUANTILES])
    spread = float(np.nanstd(path)) or 1.0
    out = []
    for side, start, bounds, alternatives in (
        ("upper", high_q, (reach_low, float(np.nanmax(path)) + spread), above),
        ("lower", low_q, (float(np.nanmin(path)) - spread, reach_high), below),
    ):
        name = f"_e_limit_{side}"

        def limits(theta, name=name, side=side):
            lo, hi = np.full(n_states, -np.inf), np.full(n_states, np.inf)
            (hi if side == "upper" else lo)[j] = theta[name]
            return lo, hi

        variant = Variant("state_limit", state, data.model, (name,), {name: float(start)},
                          {name: bounds}, {name: spread}, limits=limits,
                          screen_starts=tuple({name: float(v)} for v in alternatives))  # fmt: skip
        out.append(variant)
    return out


def slew_probes(data: UnitData) -> list[Variant]:
    """Return a slew-rate limit at each of the unit's inputs: a cause outside the catalogue.

    Not a candidate the diagnosis names: a probe (docs/gap.md §Your own twin) that tells an
    ``unexplained`` gap from the catalogue effects a slew limit looks like (a delay of steps, a
    slower lag, a lag's input saturation). The input moves at most ``span·dt/ramp`` a sample
    (:func:`~dtwin.twin._kernels.slew_limited`), ``ramp`` (s) the time a full-span step takes,
    from half a sample to half the recording (the follower runs over the whole recording, so a
    ramp may span many windows). The follower's value before the first sample (``start``, in
    the input's units) is the slew limiter's state, fitted as the windows' states are: an
    actuator need not sit at its command when the recording starts (a heater's follower at 0 %
    under a first command of 92 %, with a 547 s ramp, slews through the first 200 samples; a
    follower started at the command left the true ramp and lag a training error of 7.7 W,
    33 times the noise's 0.23 W).
    """
    from dtwin.twin._kernels import slew_limited

    out = []
    for i, signal in enumerate(data.spec.inputs):
        u = data.inputs[:, i]
        low, high = float(np.nanmin(u)), float(np.nanmax(u))
        span = high - low or 1.0
        name, first = f"_e_ramp_{i}", f"_e_slew_start_{i}"
        u0 = float(u[np.isfinite(u)][0]) if np.isfinite(u).any() else 0.0

        def slew(values, theta, data, i=i, name=name, first=first, span=span):
            out = values.copy()
            column = np.concatenate([[theta[first]], values[:, i]]).astype(float)
            out[:, i] = slew_limited(column, span * data.dt / theta[name])[1:]
            return out

        ramp = (0.5 * data.dt, 0.5 * data.n_samples * data.dt)
        # the start within a span beyond the recorded range: the actuator may sit outside the
        # commands recorded (the heater's at 0 % below commands of 8-92 %)
        starts = (low - span, high + span)
        out.append(
            Variant("input_slew_limit", signal, data.model, (name, first),
                    {name: 5.0 * data.dt, first: u0}, {name: ramp, first: starts},
                    {name: 5.0 * data.dt, first: span}, input_map=slew)
        )  # fmt: skip
    return out


def candidate_variants(
    data: UnitData,
    guess: np.ndarray,
    blocks: dict[str, str | None],
    *,
    calibrate: bool,
    produced: frozenset[str] = frozenset(),
) -> list[Variant]:
    """Every candidate effect of a unit (input, output and state effects; a re-fit).

    Parameters
    ----------
    data : UnitData
    guess : numpy.ndarray, shape (n_samples, n_states)
        The twin's states along the recording (:func:`dtwin.gap.table_fit.state_guess`),
        for the centres, spreads and start values of the state effects.
    blocks : dict of str to str or None
        Each module's built-in block (None for an equations module).
    calibrate : bool
        The twin is calibrated (no ``parameter_mismatch`` candidate).
    produced : frozenset of str
        Signals a module of the table produces: a unit's recorded input among them may be read
        wrong (:func:`_sensor_variants`).
    """
    out = (
        []
        if calibrate
        else [Variant("parameter_mismatch", None, data.model, refits_linear=True, linear_form=True)]
    )
    out += _input_variants(data)
    out += _sensor_variants(data, produced)
    out += _output_variants(data)
    if not getattr(data.model, "closed", False):  # an FMU's internals are closed
        out += _state_variants(data, guess, blocks)
    return out
