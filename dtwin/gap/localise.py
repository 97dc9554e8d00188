"""Where the gap lies: local gaps, the chain, and which gaps are only inherited.

Specification: docs/gap.md §Gaps and §Statuses.

The **gap** of a signal is a normalised RMS error over the held-out samples::

    gap = RMS_{k in held-out}(recorded[k] − twin[k]) / std(recorded over the whole recording)

A module's **local** gap drives its twin with the module's *recorded* input, so nothing
upstream can leak into it. Its **chain** gap runs the whole twin from the most upstream
recorded signal (``u_cmd`` when present), every module fed by its simulated predecessor, as the
deployed twin runs (the contract's chain runner, :func:`dtwin.twin.paper_modules.run_modules`); a
chain gap well above the local gap is inherited from upstream.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dtwin.gap.effects import Effect, Scales
from dtwin.gap.models import ModuleData, simulate_module, velocity_from_position
from dtwin.twin.paper_modules import CONTRACTS, Step, run_modules
from dtwin.twin.wiring import MODULES, Module, module_by_name

__all__ = [
    "normalised_rms",
    "ModuleModel",
    "module_inputs",
    "run_chain",
    "upstream_modules",
]


def normalised_rms(recorded: np.ndarray, predicted: np.ndarray, rows: slice, norm: float) -> float:
    """Return ``RMS(recorded − predicted)`` over ``rows`` divided by ``norm``.

    Samples predicted as NaN are not scored (a window's warm-up, docs/gap.md §Gaps); ``inf``
    (a diverged simulation) gives ``inf``.
    """
    error = np.asarray(recorded[rows], dtype=float) - np.asarray(predicted[rows], dtype=float)
    error = error[~np.isnan(error)]
    if not len(error):
        return math.nan
    if not np.all(np.isfinite(error)):
        return math.inf
    with np.errstate(over="ignore"):
        return float(np.sqrt(np.mean(error**2)) / norm)


@dataclass(frozen=True)
class ModuleModel:
    """A module's twin as the chain runs it: linear parameters and an optional effect."""

    lin: Mapping[str, float]
    effect: Effect | None = None
    theta: tuple[float, ...] = ()


def module_inputs(
    name: str, signals: Mapping[str, np.ndarray], dt: float
) -> dict[str, np.ndarray] | None:
    """Return the inputs of module ``name`` from ``signals`` (None if one is missing).

    M4's velocity falls back on the position's (:func:`velocity_from_position`).
    """
    module = module_by_name(name)
    inputs = {}
    for signal in module.inputs:
        if signal in signals:
            inputs[signal] = signals[signal]
        elif signal == "v" and "x" in signals:
            inputs["v"] = velocity_from_position(signals["x"], dt)
        else:
            return None
    return inputs


def upstream_modules(signal: str) -> set[str]:
    """Return the modules whose output ``signal`` depends on (through the wiring table)."""
    found: set[str] = set()
    frontier = [signal]
    while frontier:
        current = frontier.pop()
        for module in MODULES:
            if current in module.outputs and module.name not in found:
                found.add(module.name)
                frontier.extend(module.inputs)
    return found


def run_chain(
    recorded: Mapping[str, np.ndarray],
    models: Mapping[str, ModuleModel],
    dt: float,
    t: np.ndarray,
    scales: Mapping[str, Scales],
    layouts: Mapping[str, ModuleData] | None = None,
) -> dict[str, np.ndarray]:
    """Run the twin chain and return every signal it simulates, each shape ``(n_samples,)``.

    Parameters
    ----------
    recorded : mapping of str to array
        The recording's signals.
    models : mapping of module name to ModuleModel
        The modules the chain can run (those with known or calibrated parameters).
    dt : float
        Sample period, s.
    t : array, shape (n_samples,)
        Time from the first sample, s.
    scales : mapping of module name to Scales
        Data scales of each module (for effects that need them).
    layouts : mapping of module name to ModuleData, optional
        The diagnosed modules' data, whose discretisation, window and restarts the chain keeps
        (the plant's velocity estimate follows its discretisation).

    Returns
    -------
    dict of str to numpy.ndarray
        Simulated signals; a module whose inputs are neither simulated nor recorded is skipped.
        The plant also returns ``v = (x[k+1] − x[k])/dt``, the Euler plant's own velocity.
    """
    steps = {
        name: _chain_step(module_by_name(name), model, recorded, dt, t, scales, layouts or {})
        for name, model in models.items()
    }
    return run_modules(steps, recorded)


def _chain_step(
    module: Module,
    model: ModuleModel,
    recorded: Mapping[str, np.ndarray],
    dt: float,
    t: np.ndarray,
    scales: Mapping[str, Scales],
    layouts: Mapping[str, ModuleData],
) -> Step:
    """Return module ``module``'s step in :func:`run_chain` (None from it: an input missing)."""
    n = len(t)
    plant = CONTRACTS[module.name].law == "plant"
    layout = layouts.get(module.name)
    options = {}
    if layout is not None:
        options = {
            "discretisation": layout.discretisation,
            "horizon": layout.horizon,
            "restarts": layout.restarts,
        }

    def step(available: Mapping[str, np.ndarray]) -> dict[str, np.ndarray] | None:
        inputs = module_inputs(module.name, available, dt)
        if inputs is None:
            return None
        output = recorded.get(module.output, np.zeros(n))
        velocity = inputs.get("v")
        if plant:
            source = recorded["x"] if "x" in recorded else np.zeros(n)
            if layout is not None and layout.velocity is not None:
                velocity = layout.velocity
            else:
                velocity = velocity_from_position(source, dt)
        data = ModuleData(
            module.name, inputs, output, dt, t, velocity, scales.get(module.name), **options
        )
        out = simulate_module(data, model.lin, model.effect, model.theta)
        if not plant:
            return {module.output: out}
        if "x" in recorded:
            out = np.where(np.isnan(out), recorded["x"], out)  # unscored warm-up samples
        v = np.empty(n)
        v[:-1] = np.diff(out) / dt
        v[-1] = v[-2]
        return {module.output: out, "v": v}

    return step
