"""Unit tests of the effect catalogue (dtwin/gap/effects/, one module per effect), its helpers."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from dtwin.gap.effects import (
    ARRAY_OPS,
    EFFECT_MODULES,
    EFFECTS,
    FRICTION_SMOOTHING,
    SCALAR_OPS,
    Scales,
    effect_by_name,
    quantization_variance,
)
from tests.conftest import paper_twin


def test_quantization_variance_is_continuous_across_the_closed_form_threshold():
    """Exact level sum just below σ = 2q, Sheppard's σ² + q²/12 from there: they agree."""
    s = np.random.default_rng(0).normal(scale=3.0, size=20_000)
    sigma_below = 0.1 * (2.0 - 1e-9)
    below = quantization_variance(s, 0.1, sigma_below)
    at = quantization_variance(s, 0.1, 0.2)
    assert at == pytest.approx(0.2**2 + 0.1**2 / 12, rel=1e-15)
    assert below == pytest.approx(sigma_below**2 + 0.1**2 / 12, rel=1e-12)


def test_quantization_variance_matches_a_monte_carlo_quantizer():
    """Mean of Var(q·round((s + ε)/q) | s) against 4000 noise draws per sample."""
    rng = np.random.default_rng(1)
    s = rng.uniform(-1.0, 1.0, size=50)
    step, sigma = 0.2, 0.07
    draws = step * np.round((s[:, None] + sigma * rng.standard_normal((50, 4000))) / step)
    assert quantization_variance(s, step, sigma) == pytest.approx(
        draws.var(axis=1).mean(), rel=0.05
    )


@pytest.mark.parametrize("noise_std", [1e-3, 1e3, 1e11, 1e150])
def test_quantization_variance_memory_does_not_grow_with_the_noise_to_step_ratio(noise_std):
    """A spike that inflates σ once asked for an array of shape (T, 2·5σ/q): now O(T)."""
    s = np.random.default_rng(2).normal(size=100_000)
    tracemalloc.start()
    value = quantization_variance(s, 1e-3, noise_std)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert np.isfinite(value) and value > 0
    assert peak < 50 * 2**20, f"peak {peak / 2**20:.1f} MB"


def test_bias_drift_is_a_line_at_zero_curvature_and_settles_or_accelerates_otherwise():
    from dtwin.gap.effects import bias_drift

    t = np.linspace(0.0, 20.0, 401)
    assert np.array_equal(bias_drift(t, 0.3, 0.0), 0.3 * t)
    settling = bias_drift(t, 0.3, 0.5)
    assert settling[-1] == pytest.approx(0.3 / 0.5 * (1 - np.exp(-10.0)))
    assert np.all(np.diff(settling) > 0) and np.all(np.diff(settling, 2) < 0)
    accelerating = bias_drift(t, 0.3, -0.05)
    assert np.all(np.diff(accelerating, 2) > 0)
    # the initial rate is `rate` whatever the curvature
    for curvature in (0.5, 1e-12, -0.05):
        assert (bias_drift(t[:2], 0.3, curvature)[1] / t[1]) == pytest.approx(0.3, rel=0.03)


# --- the catalogue: each effect in one place ---------------------------------------------

#: A module's data scales as the diagnoser measures them (recording units).
SCALES = Scales(
    input_max=2.0,
    input_std=0.7,
    output_std=0.3,
    velocity_std=1.1,
    duration=20.0,
    dt=0.01,
    noise_std=0.01,
    stiffness=4.0,
    mass=1.0,
    output_mean=0.05,
)

#: Which form each stage carries (and only it).
FORM_OF_STAGE = {
    "input": "input_map",
    "delay": "input_map",
    "force": "force_law",
    "output": "output_map",
    "linear": None,
}


@pytest.mark.parametrize("effect", EFFECTS, ids=lambda e: e.name)
def test_every_effect_holds_its_parameters_and_exactly_the_form_of_its_stage(effect):
    forms = {"input_map", "force_law", "output_map"}
    own = FORM_OF_STAGE[effect.stage]
    assert [f for f in sorted(forms) if getattr(effect, f) is not None] == ([own] if own else [])
    assert (effect.compiled_law is not None) == (effect.stage == "force")
    assert effect.refits_linear == (effect.stage == "linear") == (effect.n_params == 0)
    assert len(effect.units) == effect.n_params
    bounds, typical = effect.bounds(SCALES), effect.typical(SCALES)
    assert len(bounds) == len(typical) == effect.n_params
    assert all(low < high for low, high in bounds)
    for start in effect.starts(SCALES):
        if start:  # an empty start: the effect finds its own (the quantizer's lattice)
            assert len(start) == effect.n_params
            assert all(low <= v <= high for v, (low, high) in zip(start, bounds, strict=True))


def _inside(effect) -> list[float]:
    """Each parameter at its typical magnitude, inside its bounds (a quantizer: no noise before).

    Noise before a quantizer as large as its step averages the staircase away.
    """
    values = [
        float(np.clip(abs(typical), low, high))
        for typical, (low, high) in zip(effect.typical(SCALES), effect.bounds(SCALES), strict=True)
    ]
    return [*values[:-1], 0.0] if effect.lattice else values


@pytest.mark.parametrize("effect", EFFECTS, ids=lambda e: e.name)
def test_every_effects_form_changes_the_twin_and_keeps_its_shape(effect):
    t = np.arange(500) * SCALES.dt
    signal = np.sin(2 * np.pi * 0.5 * t) * SCALES.input_max
    theta = _inside(effect)
    if effect.input_map is not None:
        changed = effect.input_map(signal, theta, SCALES.dt)
    elif effect.output_map is not None:
        changed = effect.output_map(signal, 0.1, t, theta)
        signal = signal + 0.1
    elif effect.force_law is not None:
        force = effect.force_law(theta, SCALES.velocity_std, ARRAY_OPS)
        changed, signal = force(signal, np.cos(t)), np.zeros_like(signal)
    else:
        return
    assert changed.shape == signal.shape and np.all(np.isfinite(changed))
    assert not np.allclose(changed, signal)


@pytest.mark.parametrize("effect", [e for e in EFFECTS if e.stage == "force"], ids=lambda e: e.name)
def test_a_force_effects_compiled_law_is_its_array_law(effect):
    """The compiled loop steps the same force as the numpy and scalar forms (to rounding)."""
    from dtwin.twin._force_kernels import LAWS, _law_value

    theta = _inside(effect)
    smooth = max(FRICTION_SMOOTHING * SCALES.velocity_std, 1e-300)
    name, params = effect.compiled_law([float(v) for v in theta], smooth)
    x, v = np.linspace(-0.8, 0.9, 7), np.linspace(-2.0, 1.5, 7)
    arrays = effect.force_law(theta, SCALES.velocity_std, ARRAY_OPS)(x, v)
    scalars = effect.force_law(theta, SCALES.velocity_std, SCALAR_OPS)
    compiled = [
        _law_value(LAWS.index(name), a, b, np.array(params)) for a, b in zip(x, v, strict=True)
    ]
    np.testing.assert_allclose(compiled, arrays, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(
        [scalars(a, b) for a, b in zip(x, v, strict=True)], arrays, rtol=1e-12
    )


def test_the_catalogue_is_every_effect_module_of_the_package():
    """An effect's module that is not listed in EFFECT_MODULES would never be a candidate."""
    from pathlib import Path

    import dtwin.gap.effects as package

    files = sorted(p.stem for p in Path(package.__file__).parent.glob("[!_]*.py"))
    assert sorted(module.EFFECT.name for module in EFFECT_MODULES) == files
    assert [module.EFFECT for module in EFFECT_MODULES] == list(EFFECTS)


@pytest.mark.parametrize("module", EFFECT_MODULES, ids=lambda m: m.EFFECT.name)
def test_each_effect_is_one_module_holding_its_fitted_form_and_its_case(module):
    """Adding an effect is one module of dtwin/gap/effects/ plus its test: it holds both sides.

    The module is named after its effect and holds its ``EFFECT`` (what the diagnoser fits) and
    its ``CASE`` (what the benchmark draws and the real form it acts in, named alike); an effect
    that only widens another has none. A case's truth round-trips: a generated case of the
    effect sits in one of its modules and reads back as a parameter the diagnoser fits for it.
    """
    from dtwin.gapbench.generator import CASE_EFFECTS, generate_case
    from dtwin.gapbench.scores import true_parameter
    from dtwin.twin.paper_modules import LINEAR_PARAMS

    effect, case = module.EFFECT, module.CASE
    assert module.__name__.rsplit(".", 1)[1] == effect.name
    assert (case is None) == bool(effect.nests)
    if case is None:
        return
    assert case.name == effect.name and CASE_EFFECTS[effect.name] is case
    if case.truth is None:
        return
    for seed in range(20):
        key = generate_case(effect.name, seed, n_samples=1000, nominal=paper_twin()).key
        truth = true_parameter(key, 0.02)
        if truth is not None:
            break
    assert truth is not None
    assert key["module"] in effect.modules
    assert truth[0] in set(effect.params) | set(LINEAR_PARAMS[key["module"]])


def test_the_benchmark_draws_every_catalogue_effect_in_its_modules():
    """Each catalogue effect has generated cases, in modules it can belong to.

    An effect that only widens another (``nests``: Stribeck friction around Coulomb friction)
    is drawn as the one it widens (the benchmark's friction has a Stribeck bump).
    """
    from dtwin.gapbench.generator import IN_LIST_EFFECTS

    assert sorted(e.name for e in EFFECTS if not e.nests) == sorted(IN_LIST_EFFECTS)
    modules = {e.name: set(e.modules) for e in EFFECTS}
    assert [
        name for name, where in IN_LIST_EFFECTS.items() if not set(where) <= modules[name]
    ] == []


def test_every_case_effect_acts_somewhere_in_the_asset():
    """A benchmark effect with no hook would generate a clean recording under its name."""
    from dataclasses import fields

    from dtwin.gapbench.case_effects import CaseEffect
    from dtwin.gapbench.generator import ARM_EFFECTS, CASE_EFFECTS

    hooks = [f.name for f in fields(CaseEffect) if f.name not in ("name", "draw", "truth")]
    idle = sorted(n for n, e in CASE_EFFECTS.items() if not any(getattr(e, h) for h in hooks))
    assert idle == []
    drawn = {e for effects in ARM_EFFECTS.values() for pair in effects for e in pair.split("+")}
    assert sorted(drawn - {"none"} - set(CASE_EFFECTS)) == []
    assert all(name == effect.name for name, effect in CASE_EFFECTS.items())


def test_every_case_effects_truth_is_a_parameter_of_its_answer():
    """A case effect's scored truth is a parameter the diagnoser fits for the expected answer.

    Each case effect with a ``truth`` is generated in an arm that draws it until a seed gives a
    form of the catalogue's family (a symmetric saturation, a power-2 stiffness).
    """
    from dtwin.gapbench.generator import ARM_EFFECTS, CASE_EFFECTS, generate_case
    from dtwin.gapbench.scores import true_parameter
    from dtwin.twin.paper_modules import LINEAR_PARAMS

    scored = [name for name, effect in CASE_EFFECTS.items() if effect.truth is not None]
    assert len(scored) >= 10
    for name in scored:
        arm = next(arm for arm, effects in ARM_EFFECTS.items() if name in effects)
        for seed in range(20):
            key = generate_case(name, seed, n_samples=1000, arm=arm, nominal=paper_twin()).key
            truth = true_parameter(key, 0.02)
            if truth is not None:
                break
        assert truth is not None, name
        expected = effect_by_name(key["expected_effect"])
        fitted = set(expected.params) | set(LINEAR_PARAMS[key["module"]])
        assert truth[0] in fitted, (name, truth)
