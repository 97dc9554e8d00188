"""Benchmark families of other physics for the table diagnoser: tanks, motor, thermal, battery.

Specification: docs/gap.md §Benchmark. The paper family (:mod:`dtwin.gapbench.generator`) and
the rig families (:mod:`dtwin.gapbench.rigs`) record one chain of modules; these families record
assets whose twin is a ``modules:`` table (docs/gap.md §Your own twin), so the diagnoser is
scored on physics it was not written around. :func:`generate_family_case` draws one recording
with one withheld effect (or none, or one the catalogue does not hold), the nominal twin file
and a key holding the truth:

- the asset (:mod:`dtwin.gapbench.family_assets`) is integrated by classical Runge-Kutta with
  :data:`SUBSTEPS` sub-steps per sample, its input held over each sample, never by dtwin's own
  twin simulator (which is what is being tested);
- the input is random steps (the motor's sometimes with a multisine), reaching the effect in
  the training half (the first);
- measurement noise on every recorded output, 0.5–2 % of its spread, white or AR(1) (pole
  0.3–0.8); the recorded input is a command, noise-free;
- the twin's params are off from the truth by up to 2 % each; its noise levels are right to
  ±10 %, and absent in a fifth of the cases;
- the effect's strength runs from barely above the noise (``magnitude`` 0) to strong (1),
  log-uniformly, in real forms that differ from the catalogue's
  (:mod:`dtwin.gapbench.family_effects`);
- with ``internal`` the internal signals are recorded too (tanks: ``q, h1``; motor: ``i``;
  thermal: ``P, T1``; battery: ``I``); without, modules joined by unrecorded signals form one
  unit, whose modules the key's ``group`` lists.

Case types ``<family>_<effect>`` (``tanks_state_limit``), with ``internal`` drawn (half of
the cases), or ``<family>_internal_<effect>`` / ``<family>_bare_<effect>`` to fix it;
:func:`dtwin.gapbench.rigs.generate_any_case` dispatches them here. Every random draw comes
from a generator seeded by the case seed (one stream per purpose: the asset, the noise, the
effect, the twin file, the case's own choices), so a seed gives byte-identical files and the
cases of one seed share their asset across effects. :func:`score_family_case` scores a
diagnosis against a key; :func:`summarise_family_scores` gives each family's accuracies with
their Wilson intervals.

Arrays are time-first, shape ``(n_samples,)``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from dtwin._validation import DtwinValueError
from dtwin.gap.effects import NONE, UNEXPLAINED
from dtwin.gapbench.family_assets import (
    BATTERY,
    MOTOR,
    TANKS,
    THERMAL,
    Asset,
    Derivative,
    Family,
)
from dtwin.gapbench.family_effects import Context, OutputView, Placed
from dtwin.gapbench.generator import GeneratedCase
from dtwin.proportions import wilson_interval

__all__ = [
    "FAMILIES",
    "FAMILY_EFFECTS",
    "FAMILY_PREFIXES",
    "FAMILY_CASE_TYPES",
    "RECORDING_ARMS",
    "SUBSTEPS",
    "FamilyRun",
    "parse_family_case_type",
    "run_family_case",
    "generate_family_case",
    "write_family_case",
    "score_family_case",
    "summarise_family_scores",
]

#: The families, by case-type prefix (without its underscore).
FAMILIES: dict[str, Family] = {family.name: family for family in (TANKS, MOTOR, THERMAL, BATTERY)}
#: Each family's effects, ``none`` first.
FAMILY_EFFECTS: dict[str, tuple[str, ...]] = {
    name: (NONE, *family.effects) for name, family in FAMILIES.items()
}
#: Case-type prefixes of the families (``tanks_``, ``motor_``, ``thermal_``).
FAMILY_PREFIXES: tuple[str, ...] = tuple(f"{name}_" for name in FAMILIES)
#: Every case type ``<family>_<effect>`` (internal signals drawn per case).
FAMILY_CASE_TYPES: tuple[str, ...] = tuple(
    f"{name}_{effect}" for name, effects in FAMILY_EFFECTS.items() for effect in effects
)
#: The key's ``arm``: with the internal signals recorded, or without them.
RECORDING_ARMS: tuple[str, ...] = ("internal", "bare")
#: Runge-Kutta sub-steps per sample.
SUBSTEPS = 10
#: Share of the cases whose twin file declares no noise levels.
_NO_NOISE_SHARE = 0.2
#: Random streams of a case, by purpose (the second entry of the seed sequence).
_STREAMS = {"case": 0, "asset": 1, "noise": 2, "effect": 3, "twin": 4}
_NO_EFFECT = Placed(NONE, {})


@dataclass(frozen=True)
class FamilyRun:
    """A generated case with its noise-free signals.

    Attributes
    ----------
    case : GeneratedCase
        ``recording`` (``t`` s, the input, the recorded outputs), ``twin`` (``dt``,
        ``modules``, ``noise`` when declared) and ``key`` (the truth).
    clean : pandas.DataFrame
        The recording's columns without measurement noise and without a sensor effect
        (the asset's run with its effect, as its states were), same shape as ``recording``.
    """

    case: GeneratedCase
    clean: pd.DataFrame


def parse_family_case_type(case_type: str) -> tuple[Family, str, bool | None]:
    """Return ``(family, effect, internal)`` of a case type (``internal`` None: drawn).

    Raises
    ------
    DtwinValueError
        If the prefix is no family's or the effect is not the family's.
    """
    name, _, rest = case_type.partition("_")
    if name not in FAMILIES:
        raise DtwinValueError(
            f"family case type must start with one of {', '.join(FAMILY_PREFIXES)} "
            f"(got {case_type!r})"
        )
    internal = None
    for arm, flag in (("internal_", True), ("bare_", False)):
        if rest.startswith(arm):
            rest, internal = rest[len(arm) :], flag
    if rest not in FAMILY_EFFECTS[name]:
        raise DtwinValueError(
            f"{name} effect must be one of {', '.join(FAMILY_EFFECTS[name])} (got {rest!r})"
        )
    return FAMILIES[name], rest, internal


# --- integration ---------------------------------------------------------------------------


def _rk4(rhs: Derivative, x0: Sequence[float], u_sub: np.ndarray, dt: float, project=None):
    """Integrate by classical Runge-Kutta; return the states at every sub-step.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, x, u) -> dx`` on plain floats.
    x0 : sequence of float
        States at ``t = 0``.
    u_sub : numpy.ndarray, shape (n_samples, substeps)
        The input over each sub-step (held).
    dt : float
        Sampling step (s).
    project : callable, optional
        ``project(x) -> x`` after each sub-step (a hard limit).

    Returns
    -------
    numpy.ndarray, shape ((n_samples − 1)·substeps + 1, n_states)
        Row ``k·substeps`` is sample ``k``.
    """
    h = dt / u_sub.shape[1]
    half, sixth = 0.5 * h, h / 6.0
    x = [float(v) for v in x0]
    rows = [x]
    step = 0
    for inputs in u_sub[:-1].tolist():
        for u in inputs:
            t = step * h
            k1 = rhs(t, x, u)
            k2 = rhs(t + half, [a + half * b for a, b in zip(x, k1, strict=True)], u)
            k3 = rhs(t + half, [a + half * b for a, b in zip(x, k2, strict=True)], u)
            k4 = rhs(t + h, [a + h * b for a, b in zip(x, k3, strict=True)], u)
            x = [
                a + sixth * (b + 2.0 * (c + d) + e)
                for a, b, c, d, e in zip(x, k1, k2, k3, k4, strict=True)
            ]
            if project is not None:
                x = project(x)
            rows.append(x)
            step += 1
    return np.array(rows)


def _substep_inputs(u: np.ndarray, delay: float, dt: float) -> np.ndarray:
    """Return the input over each sub-step, ``(n_samples, SUBSTEPS)``, delayed by ``delay`` s.

    The delay is a whole number of sub-steps; before ``t = 0`` the input is 0 (at rest).
    """
    shift = int(round(delay / (dt / SUBSTEPS)))
    index = (np.arange(len(u) * SUBSTEPS) - shift) // SUBSTEPS
    return np.where(index >= 0, u[np.maximum(index, 0)], 0.0).reshape(len(u), SUBSTEPS)


def _scheduled(family: Family, params: dict[str, float], placed: Placed) -> Derivative:
    """Return the asset's derivative, with a param changing in time if the effect says so."""
    if placed.schedule is None:
        return family.derivative(params, placed)
    name, factor = placed.schedule

    def f(t: float, x: Sequence[float], u: float) -> list[float]:
        moved = {**params, name: params[name] * factor(t)}
        return family.derivative(moved, placed)(t, x, u)

    return f


def _with_term(f: Derivative, index: int, term) -> Derivative:
    def g(t: float, x: Sequence[float], u: float) -> list[float]:
        dx = f(t, x, u)
        dx[index] += term(t, x)
        return dx

    return g


def _with_limit(f: Derivative, index: int, upper: float, steepness: float) -> Derivative:
    """Return ``f`` with state ``index`` held below ``upper`` (hard: steepness 0) or drained."""

    def hard(t: float, x: Sequence[float], u: float) -> list[float]:
        dx = f(t, x, u)
        if x[index] >= upper and dx[index] > 0.0:
            dx[index] = 0.0
        return dx

    def steep(t: float, x: Sequence[float], u: float) -> list[float]:
        dx = f(t, x, u)
        if x[index] > upper:
            dx[index] -= steepness * (x[index] - upper)
        return dx

    return hard if steepness == 0.0 else steep


def _with_rate(f: Derivative, rate: float, gain: float) -> Derivative:
    """Return ``f`` driven by a follower of the input slewing at most ``rate`` (its last state)."""

    def g(t: float, x: Sequence[float], u: float) -> list[float]:
        follower = x[-1]
        slew = min(max(gain * (u - follower), -rate), rate)
        return [*f(t, x, follower), slew]

    return g


def _hooked(family: Family, params: dict[str, float], placed: Placed, dt: float):
    """Return the derivative with the effect's hooks and the projection of a hard limit."""
    states = family.states(placed)
    f = _scheduled(family, params, placed)
    if placed.term is not None:
        f = _with_term(f, states.index(placed.term[0]), placed.term[1])
    project = None
    if placed.limit is not None:
        name, upper, steepness = placed.limit
        index = states.index(name)
        f = _with_limit(f, index, upper, steepness)
        if steepness == 0.0:

            def project(x: list[float]) -> list[float]:
                x[index] = min(x[index], upper)
                return x

    if placed.rate is not None:
        f = _with_rate(f, placed.rate, SUBSTEPS / (3.0 * dt))
    return f, project


@dataclass(frozen=True)
class _Trajectory:
    """The asset's signals and states at every sub-step (``fine``) and its instants (s)."""

    fine: dict[str, np.ndarray]
    t_fine: np.ndarray

    def samples(self, name: str) -> np.ndarray:
        return self.fine[name][::SUBSTEPS]


def _simulate(family: Family, asset: Asset, params: dict[str, float], placed: Placed):
    """Run the asset with ``placed``'s hooks; return its :class:`_Trajectory`."""
    u_seen = asset.u if placed.input_map is None else placed.input_map(asset.u)
    u_sub = _substep_inputs(u_seen, placed.input_delay, asset.dt)
    rhs, project = _hooked(family, params, placed, asset.dt)
    x0 = family.rest(params, placed)
    states = family.states(placed)
    if placed.rate is not None:
        x0.append(0.0)
    X = _rk4(rhs, x0, u_sub, asset.dt, project)[:, : len(states)]
    fine = {name: X[:, i] for i, name in enumerate(states)}
    fine.update(family.observe(params, placed, X))
    return _Trajectory(fine, np.arange(len(X)) * (asset.dt / SUBSTEPS))


# --- a case --------------------------------------------------------------------------------


def _streams(seed: int) -> dict[str, np.random.Generator]:
    return {name: np.random.default_rng([int(seed), k]) for name, k in _STREAMS.items()}


def _noises(family: Family, base: _Trajectory, rng: np.random.Generator, n: int):
    """Draw each noisy output's noise: ``(noise (n,), std, AR(1) pole)`` by signal.

    The std is 0.5–2 % of the signal's spread in the run without the effect; the noise is
    white or (half the cases) AR(1) with pole 0.3–0.8, unit-variance stationary shape.
    """
    drawn = {}
    for name in family.noisy:
        level, coloured, pole = rng.uniform(0.005, 0.02), rng.uniform() < 0.5, rng.uniform(0.3, 0.8)
        pole = pole if coloured else 0.0
        white = rng.standard_normal(n)
        gain = math.sqrt(1.0 - pole**2)
        shape = lfilter([gain], [1.0, -pole], white, zi=[(1.0 - gain) * white[0]])[0]
        std = level * (float(np.std(base.samples(name))) or 1.0)
        drawn[name] = (std * shape, std, pole)
    return drawn


def _declared(params: Mapping[str, float], rng: np.random.Generator) -> dict[str, float]:
    """Return the twin's params: each true one off by a uniform factor within ±2 %."""
    return {name: float(value * (1.0 + rng.uniform(-0.02, 0.02))) for name, value in params.items()}


def _recorded(family: Family, internal: bool) -> tuple[str, ...]:
    return (*family.internal, *family.outputs) if internal else family.outputs


def _interpolator(t_fine: np.ndarray, fine: np.ndarray):
    """Return ``at(times)``: ``fine`` interpolated linearly, its first value before ``t = 0``."""

    def at(times: np.ndarray) -> np.ndarray:
        return np.interp(times, t_fine, fine)

    return at


def _record(run: _Trajectory, noises: Mapping, placed: Placed, names: Sequence[str]):
    """Return the recorded outputs ``{signal: (n,)}`` of a run: clean + noise, or the sensor's."""
    t = run.t_fine[::SUBSTEPS]
    recorded = {}
    for name in names:
        noise = noises[name][0]
        clean = run.samples(name)
        if placed.output is not None and placed.output[0] == name:
            view = OutputView(clean, noise, t, _interpolator(run.t_fine, run.fine[name]))
            recorded[name] = np.asarray(placed.output[1](view), dtype=float)
        else:
            recorded[name] = clean + noise
    return recorded


def _units(modules: Mapping[str, Mapping], recorded: Iterable[str]) -> dict[str, list[str]]:
    """Return each module's unit: the modules joined to it by unrecorded signals, table order."""
    root = {name: name for name in modules}

    def find(name: str) -> str:
        while root[name] != name:
            name = root[name]
        return name

    producer = {signal: name for name, m in modules.items() for signal in m["outputs"]}
    seen = set(recorded)
    for name, module in modules.items():
        for signal in module["inputs"]:
            if signal in producer and signal not in seen:
                root[find(name)] = find(producer[signal])
    return {name: [m for m in modules if find(m) == find(name)] for name in modules}


def _twin_file(family, asset, declared, noises, names, rng, with_noise) -> dict[str, Any]:
    """Return the nominal twin file: ``dt``, ``modules`` and (when declared) ``noise``.

    The declared noise std of each recorded output is its true one times ``1 ± 10 %``.
    """
    twin: dict[str, Any] = {"dt": float(asset.dt), "modules": family.twin(declared)}
    errors = {name: rng.uniform(-0.1, 0.1) for name in names}
    if with_noise:
        twin["noise"] = {name: float(noises[name][1] * (1.0 + errors[name])) for name in names}
    return twin


def _snr(recorded, baseline, noises, names) -> dict[str, float]:
    """Return RMS(effect's contribution) over the noise std, per recorded output."""
    return {
        name: float(np.sqrt(np.mean((recorded[name] - baseline[name]) ** 2)) / noises[name][1])
        for name in names
    }


@dataclass(frozen=True)
class _Choices:
    """The case's own draws: strength, internal signals recorded, noise levels declared."""

    magnitude: float
    internal: bool
    noise_declared: bool


def _choices(rng: np.random.Generator, magnitude, internal) -> _Choices:
    """Draw the case's choices (always all three draws, so a given value keeps the stream)."""
    drawn = (rng.uniform(), rng.uniform() < 0.5, rng.uniform() >= _NO_NOISE_SHARE)
    return _Choices(
        float(drawn[0] if magnitude is None else magnitude),
        bool(drawn[1] if internal is None else internal),
        bool(drawn[2]),
    )


def _placed_effect(family, effect, asset, base, noises, declared, rng, level) -> Placed:
    """Draw the effect (none: no hooks) against the run without it."""
    if effect == NONE:
        return _NO_EFFECT
    ctx = Context(
        dt=asset.dt,
        u=asset.u,
        clean={name: base.samples(name) for name in base.fine},
        noise={name: value[1] for name, value in noises.items()},
        params=dict(asset.params),
        declared=dict(declared),
        tau_slow=asset.tau_slow,
        substeps=SUBSTEPS,
    )
    return family.effects[effect].draw(rng, level, ctx)


def _key(family, effect, placed, choices, asset, twin, names) -> dict[str, Any]:
    """Return the truth of a case (the parts that do not depend on the run)."""
    none = effect == NONE
    spec = None if none else family.effects[effect]
    expected = NONE if none else spec.expected
    also = () if none or (spec.equivalent_bare_only and choices.internal) else spec.equivalent
    module = None if none else placed.module or spec.module
    units = _units(twin["modules"], (family.input, *names))
    true_params = {**asset.params, **placed.true_params}
    return {
        "family": family.name,
        "arm": RECORDING_ARMS[0] if choices.internal else RECORDING_ARMS[1],
        "effect": effect,
        "expected_effect": expected,
        "accepted_effects": [expected, *also],
        "module": module,
        "group": units[module] if module else [],
        "at": None if none else placed.at or spec.at,
        "in_list": expected not in (NONE, UNEXPLAINED),
        "magnitude": choices.magnitude,
        "form": placed.form,
        "params": dict(placed.params),
        "true_params": {m: dict(e["params"]) for m, e in family.twin(true_params).items()},
        "internal": choices.internal,
        "noise_declared": choices.noise_declared,
        "dt": float(asset.dt),
        "excitation": asset.excitation,
        "columns": ["t", family.input, *names],
    }


def run_family_case(
    case_type: str,
    seed: int,
    *,
    magnitude: float | None = None,
    internal: bool | None = None,
    n_samples: int | None = None,
) -> FamilyRun:
    """Generate one family case and return it with its noise-free signals.

    Parameters
    ----------
    case_type : str
        ``<family>_[internal_|bare_]<effect>`` (:data:`FAMILY_CASE_TYPES`).
    seed : int
        Seed of every draw.
    magnitude : float, optional
        The effect's strength, 0 (barely above the noise) to 1 (strong); drawn uniformly when
        None.
    internal : bool, optional
        Record the internal signals; overrides the case type's; drawn (half) when neither
        says.
    n_samples : int, optional
        Samples of the recording (drawn: tanks 2000–6000, motor 3000–8000, thermal
        3000–10,000).

    Returns
    -------
    FamilyRun
        The case and its noise-free signals.
    """
    family, effect, fixed = parse_family_case_type(case_type)
    rng = _streams(seed)
    choices = _choices(rng["case"], magnitude, fixed if internal is None else internal)
    asset = family.draw(rng["asset"], n_samples)
    declared = _declared(asset.params, rng["twin"])
    base = _simulate(family, asset, asset.params, _NO_EFFECT)
    noises = _noises(family, base, rng["noise"], asset.n)
    placed = _placed_effect(
        family, effect, asset, base, noises, declared, rng["effect"], choices.magnitude
    )
    run = base
    if effect != NONE and placed.dynamic:
        run = _simulate(family, asset, {**asset.params, **placed.true_params}, placed)
    names = _recorded(family, choices.internal)
    recorded = _record(run, noises, placed, names)
    snr = _snr(recorded, _record(base, noises, _NO_EFFECT, names), noises, names)
    twin = _twin_file(family, asset, declared, noises, names, rng["twin"], choices.noise_declared)
    key = _key(family, effect, placed, choices, asset, twin, names)
    key.update(
        snr=max(snr.values()) if effect != NONE else 0.0,
        snr_by_signal=snr,
        noise={name: noises[name][1] for name in names},
        noise_pole={name: noises[name][2] for name in names},
        seed=int(seed),
        n_samples=asset.n,
    )
    t = np.arange(asset.n) * asset.dt
    frame = pd.DataFrame({"t": t, family.input: asset.u, **recorded})
    clean = pd.DataFrame({"t": t, family.input: asset.u, **{n: run.samples(n) for n in names}})
    return FamilyRun(GeneratedCase(recording=frame, twin=twin, key=key), clean)


def generate_family_case(
    case_type: str,
    seed: int,
    *,
    magnitude: float | None = None,
    internal: bool | None = None,
    n_samples: int | None = None,
) -> GeneratedCase:
    """Generate one family case: recording, nominal twin file (a ``modules:`` table) and key.

    Parameters as in :func:`run_family_case`.

    Returns
    -------
    GeneratedCase
        ``recording``: ``t`` (s), the input (``u`` V for tanks, ``V`` V for the motor, ``u``
        % for thermal) and the recorded outputs (tanks ``[q, h1,] level``; motor ``[i,] w``;
        thermal ``[P, T1,] y``). ``twin``: ``dt``, ``modules`` and, in four cases of five,
        ``noise``. ``key``: ``family``, ``arm`` (``internal`` or ``bare``), ``effect``,
        ``expected_effect``, ``accepted_effects``, ``module``, ``group``, ``at``, ``in_list``,
        ``magnitude``, ``snr``, ``snr_by_signal``, ``form``, ``params``, ``true_params`` (by
        module, the twin's names), ``noise``, ``noise_pole``, ``noise_declared``,
        ``internal``, ``seed``, ``n_samples``, ``dt``, ``excitation``, ``columns``.

    Examples
    --------
    >>> case = generate_family_case("tanks_bare_state_limit", 3, n_samples=300)
    >>> list(case.recording.columns), case.key["module"], case.key["group"]
    (['t', 'u', 'level'], 'tanks', ['pump', 'tanks', 'sensor'])
    """
    run = run_family_case(
        case_type, seed, magnitude=magnitude, internal=internal, n_samples=n_samples
    )
    return run.case


def write_family_case(
    case_type: str,
    index: int,
    seed: int,
    folder: str | os.PathLike,
    *,
    n_samples: int | None = None,
) -> GeneratedCase:
    """Generate a family case and write ``recording.csv``, ``twin.yaml`` and ``key.json``.

    Parameters
    ----------
    case_type : str
        A :data:`FAMILY_CASE_TYPES` entry (or with ``internal_``/``bare_``).
    index : int
        The case's number: its name is ``<case_type>_<index:02d>`` (the key's ``case``).
    seed : int
        Seed of every draw.
    folder : path
        Created if missing; each file is written atomically, as
        :func:`dtwin.gapbench.batch.write_case_folder` writes a case.
    n_samples : int, optional
        Samples of the recording (drawn when None, as the benchmark draws them).

    Returns
    -------
    GeneratedCase
        The case written.
    """
    import yaml

    from dtwin.artifacts import atomic_write, write_csv, write_json

    case = generate_family_case(case_type, seed, n_samples=n_samples)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_csv(case.recording, folder / "recording.csv")
    text = yaml.safe_dump(case.twin, sort_keys=False)
    atomic_write(folder / "twin.yaml", lambda tmp: Path(tmp).write_text(text))
    write_json({"case": f"{case_type}_{int(index):02d}", **case.key}, folder / "key.json")
    return case


# --- scores --------------------------------------------------------------------------------


def _bare_name(at: Any) -> str | None:
    """Return ``at`` without a ``module.`` prefix (``tanks.h1`` → ``h1``), None if absent."""
    return None if at is None else str(at).rsplit(".", 1)[-1]


def score_family_case(key: Mapping[str, Any], diagnosis: Mapping[str, Any]) -> dict[str, Any]:
    """Score one diagnosis (``diagnosis.json``) against a family case's key.

    Parameters
    ----------
    key : mapping
        The case's key (:func:`generate_family_case`; ``case`` when written to a folder).
    diagnosis : mapping
        ``module``, ``modules`` (the unit's), ``effect`` and ``at`` of the answer.

    Returns
    -------
    dict
        The case's ``case, family, arm, effect, expected_effect, module, at, in_list,
        magnitude, snr`` and the answer's ``diagnosed_module, diagnosed_modules,
        diagnosed_effect, diagnosed_at``, with ``located`` (the key's module is the answer's
        module or in its ``modules``; None for a ``none`` case), ``at_ok`` (the answer's
        ``at`` without its ``module.`` prefix is the key's) and ``named``: ``none`` answered
        for a ``none`` case; ``unexplained`` and located for an out-of-list one; else located,
        the effect one of the key's ``accepted_effects`` (the generated one's catalogue name,
        or one that explains the recording exactly as well) and, for a ``state_*`` effect,
        ``at`` right.
    """
    expected = key["expected_effect"]
    effect, module = diagnosis.get("effect"), diagnosis.get("module")
    modules = list(diagnosis.get("modules") or ([module] if module else []))
    at_ok = _bare_name(diagnosis.get("at")) == key.get("at")
    located = None
    if expected == NONE:
        named = effect == NONE
    else:
        located = key["module"] == module or key["module"] in modules
        named = located and effect in key.get("accepted_effects", [expected])
        if expected.startswith("state_"):
            named = named and at_ok
    return {
        **{
            name: key.get(name)
            for name in ("case", "family", "arm", "effect", "expected_effect", "module", "at")
        },
        "in_list": bool(key["in_list"]),
        "magnitude": key.get("magnitude"),
        "snr": key.get("snr"),
        "diagnosed_module": module,
        "diagnosed_modules": modules,
        "diagnosed_effect": effect,
        "diagnosed_at": diagnosis.get("at"),
        "located": located,
        "at_ok": at_ok,
        "named": bool(named),
    }


def _rate(flags: Sequence[bool]) -> dict[str, Any]:
    """Return ``{k, n, rate, low, high}``: a proportion with its Wilson 95 % interval."""
    k, n = int(sum(bool(f) for f in flags)), len(flags)
    low, high = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None, "low": low, "high": high}


def _summary(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Return one group of scored cases' accuracies (each a :func:`_rate`)."""
    effects = sorted({row["effect"] for row in rows})
    return {
        "n_cases": len(rows),
        "module": _rate([r["located"] for r in rows if r["expected_effect"] != NONE]),
        "effect": _rate([r["named"] for r in rows if r["in_list"]]),
        "none": _rate([r["named"] for r in rows if r["expected_effect"] == NONE]),
        "unexplained": _rate([r["named"] for r in rows if r["expected_effect"] == UNEXPLAINED]),
        "all": _rate([r["named"] for r in rows]),
        "by_effect": {e: _rate([r["named"] for r in rows if r["effect"] == e]) for e in effects},
    }


def summarise_family_scores(rows: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Return each family's accuracies, and the same per arm, with Wilson 95 % intervals.

    Parameters
    ----------
    rows : iterable of mapping
        :func:`score_family_case` results.

    Returns
    -------
    dict
        By family: ``n_cases``; ``module`` (located, over cases with an effect), ``effect``
        (named, over in-list cases), ``none``, ``unexplained``, ``all`` (named over every
        case) and ``by_effect``, each ``{k, n, rate, low, high}`` (``rate`` None and the
        interval NaN with no case); ``arms``: the same per arm (``internal``, ``bare``).
    """
    rows = list(rows)
    summary = {}
    for family in sorted({row["family"] for row in rows}):
        mine = [row for row in rows if row["family"] == family]
        arms = sorted({row["arm"] for row in mine})
        summary[family] = {
            **_summary(mine),
            "arms": {arm: _summary([r for r in mine if r["arm"] == arm]) for arm in arms},
        }
    return summary
