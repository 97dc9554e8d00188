"""The benchmark's case effects: how each is drawn and where its real form acts in the asset.

Specification: docs/gap.md §Generator, §Benchmark.

A :class:`CaseEffect` is the one place of a generated effect (a catalogue effect, an out-of-list
one or an arm's): its random draw and the hooks through which its *real* form enters the asset,
one per place in the chain. The asset (:mod:`dtwin.gapbench.generator`) calls the hooks of the
module's effect and never branches on an effect's name; a hook it does not have leaves that place
as the paper's asset. A catalogue effect's case sits in its own module of :mod:`dtwin.gap.effects`
beside the :class:`~dtwin.gap.effects.Effect` the diagnoser fits (whose textbook form the real
one differs from on purpose); the out-of-list and the arms' cases are :mod:`dtwin.gapbench`'s.
The diagnoser never reads a case.

A module's ``spec`` is the drawn form and parameters plus ``effect`` (its name). Arrays are
time-first, shape ``(n_samples,)``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["CaseEffect", "Draw", "Truth", "log_between", "spec_value"]

#: ``draw(module, level, rng, scale) -> spec``: the real effect's form and parameters.
#: ``level`` in [0, 1] maps the strength log-uniformly (0: barely above the noise, 1: strong);
#: ``scale`` holds the clean run's signal sizes (``u_max``, ``u_std``, ``x_max``, ``x_std``,
#: ``v_max``, ``v_std``, ``sigma``: the sensor's noise standard deviation).
Draw = Callable[[str, float, np.random.Generator, Mapping[str, float]], dict[str, Any]]


def log_between(low: float, high: float, level: float) -> float:
    """Return ``low·(high/low)^level``: a draw's strength ``level`` in [0, 1] mapped log-uniformly.

    Examples
    --------
    >>> log_between(1.0, 100.0, 0.5)
    10.0
    """
    return float(low * (high / low) ** level)


#: ``truth(spec, key, dt) -> (name, true value, value without the effect)`` or None: the
#: catalogue parameter that sets the drawn effect's size, in the catalogue's name and units
#: (``key`` is the case's key, ``dt`` the sample time in s); None when the real form drawn has no
#: catalogue parameter (docs/gap.md §Scores).
Truth = Callable[[Mapping[str, Any], Mapping[str, Any], float], tuple[str, float, float] | None]


def spec_value(name: str, without: float = 0.0) -> Truth:
    """Return the :data:`Truth` that reads catalogue parameter ``name`` from the spec as drawn.

    ``without`` is its value without the effect (0; 1 for a gain).

    Examples
    --------
    >>> spec_value("gain", without=1.0)({"gain": 1.2}, {}, 0.01)
    ('gain', 1.2, 1.0)
    """

    def truth(spec, key, dt):
        return name, spec[name], without

    return truth


@dataclass(frozen=True)
class CaseEffect:
    """One generated effect: its draw and the hooks of its real form.

    Attributes
    ----------
    name : str
        The case effect (``"coulomb_friction"``, ``"backlash"``).
    draw : Draw
        Its random draw (see :data:`Draw`).
    actuator : callable, optional
        ``actuator(u_cmd, spec, dt) -> u``: the command after the effect, before the lag.
    force : callable, optional
        ``force(spec, c, k, min_smoothing) -> (law, params)``: an extra plant force ``F(x, v)``
        (N), a law of :data:`dtwin.twin._force_kernels.LAWS` and its parameters (the Euler plant and
        the continuous asset step the same law); a friction's sign is smoothed over at least
        ``min_smoothing`` (m/s).
    plant : callable, optional
        ``plant(u, m, c, k, dt, noise, spec, n) -> (x, v)``: the whole plant run, in place of
        the contract's Euler plant (stick-slip friction, a change of ``k``).
    sensor_input : callable, optional
        ``sensor_input(x, spec) -> x_read``: the position the sensor reads, before its lag.
    sensor_gain : callable, optional
        ``sensor_gain(lag, spec) -> lag'``: a map on the sensor's lag before bias and noise.
    reading : callable, optional
        ``reading(y, spec, t, x) -> y'``: a map on the sensor's noisy reading (``t`` in s, ``x``
        the true position).
    asset : callable, optional
        ``asset(asset, nominal, spec)``: the effect changes the asset's parameters (in place;
        ``parameter_mismatch``) instead of acting in the chain; it records what it changed in
        ``spec``.
    continuous_delay : bool
        The continuous asset delays the sensor's continuous position by ``delay_samples`` (its
        ``sensor_input`` acts on samples, which that asset does not have).
    truth : callable, optional
        The catalogue parameter that sets the effect's size (see :data:`Truth`); None: the
        effect has none (its answer is not scored on a parameter).
    """

    name: str
    draw: Draw
    actuator: Callable[..., np.ndarray] | None = None
    force: Callable[..., tuple[str, tuple[float, ...]]] | None = None
    plant: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None
    sensor_input: Callable[..., np.ndarray] | None = None
    sensor_gain: Callable[..., np.ndarray] | None = None
    reading: Callable[..., np.ndarray] | None = None
    asset: Callable[..., None] | None = None
    continuous_delay: bool = False
    truth: Truth | None = None
