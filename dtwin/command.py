"""Input command generator (paper §3.1, "Input Command Generator"; r_notes.md §1)."""

from __future__ import annotations

import numpy as np

from dtwin._validation import DtwinValueError, require_positive
from dtwin.params import CommandParams

__all__ = ["time_axis", "n_steps_for", "make_command"]


def n_steps_for(duration_s: float, dt: float) -> int:
    """Return the number of samples ``round(duration_s / dt)`` of a run (R: 20 / 0.02 = 1000)."""
    duration_s = require_positive("simulation.T", duration_s)
    dt = require_positive("twin.dt", dt)
    n_steps = int(round(duration_s / dt))
    if n_steps < 2:
        raise DtwinValueError(
            f"simulation.T / twin.dt must give at least 2 samples (got {n_steps})"
        )
    return n_steps


def time_axis(n_steps: int, dt: float) -> np.ndarray:
    """Return ``t_k = k·dt`` for k = 0 … n_steps−1, shape ``(n_steps,)``, seconds."""
    return np.arange(n_steps) * dt


def make_command(
    n_steps: int, dt: float, params: CommandParams, rng: np.random.Generator
) -> np.ndarray:
    """Return the command ``u_cmd``, shape ``(n_steps,)``.

    Parameters
    ----------
    n_steps : int
        Number of samples.
    dt : float
        Sample period, s.
    params : CommandParams
        Amplitudes (signal units), frequencies (Hz), step period (s) and step std.
    rng : numpy.random.Generator
        Draws one standard normal per step, ``ceil(n_steps / step_every)`` in all.

    Returns
    -------
    numpy.ndarray, shape (n_steps,)

    Notes
    -----
    Paper §3.1: ``u_base = 0.6 sin(2π·0.25 t) + 0.4 sign(sin(2π·0.05 t))`` and
    ``u_cmd,k = amp·(u_base,k + Σ_i δ_i 1{k ≥ i})`` with step indices ``i = 0, s, 2s, …``
    (``s = round(step_every_s / dt)``, 125 samples by default) and ``δ_i ~ N(0, step_std²)``:
    a cumulative random-walk offset. ``sign(0) = 0`` at t = 0, as in R.

    Examples
    --------
    >>> from dtwin.params import CommandParams
    >>> p = CommandParams(1.0, 0.6, 0.25, 0.4, 0.05, 2.5, 0.0)
    >>> u = make_command(1000, 0.02, p, np.random.default_rng(0))
    >>> u.shape, float(u[0])
    ((1000,), 0.0)
    """
    t = time_axis(n_steps, dt)
    base = params.sine_amp * np.sin(
        2 * np.pi * params.sine_freq_hz * t
    ) + params.square_amp * np.sign(np.sin(2 * np.pi * params.square_freq_hz * t))
    step_every = max(1, int(round(params.step_every_s / dt)))
    offsets = np.zeros(n_steps)
    for start in range(0, n_steps, step_every):
        offsets[start:] += params.step_std * rng.standard_normal()
    return params.amp * (base + offsets)
