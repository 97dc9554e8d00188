"""Process noise in a twin table (docs/gap.md §Twin file): the floor it sets, and the answers.

A disturbance of the asset's states is not noise on its recording: the twin, restarted from the
recording at each window, drifts from it by what the disturbance moved the states since. The
floor of a lag's process noise is checked against its closed form, and a valve feeding a tank,
both disturbed, reads ``none`` when the twin declares the disturbance, not when it declares
the same levels as measurement noise; an effect under that noise is still named.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from dtwin.gap.noise import effective_samples
from dtwin.gap.recording import recording_with_columns
from dtwin.gap.results import GapSettings
from dtwin.gap.table_diagnose import (
    PROCESS_NOISE_DRAWS,
    _nominal_fit,
    _prepare_unit,
    _process_noise_floor,
    _split,
    diagnose_table,
)
from dtwin.gap.table_fit import state_guess
from dtwin.twin.simulate import units_of
from dtwin.twin.table import table_from_mapping
from tests.gap.test_table_diagnose import TANK as TWO_MODULE_TANK

DT = 0.1
#: The valve's and the tank's disturbances (per sample, state units) and the sensors' noise.
PROCESS = {"valve.y": 0.01, "tank.h": 0.01}
MEASUREMENT = {"q": 0.005, "level": 0.01}
TANK = {k: v for k, v in TWO_MODULE_TANK.items() if k != "noise"}  # no noise declared


def _asset(n: int, seed: int, *, level_limit=None) -> pd.DataFrame:
    """The valve and the tank with each state disturbed by ``w_k/dt`` held over sample ``k``
    (the table's definition of process noise), integrated by RK4 in 20 steps per sample."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.3, 1.6, n // 40 + 1), 40)[:n]
    w = rng.standard_normal((n, 2)) * [PROCESS["valve.y"], PROCESS["tank.h"]] / DT

    def rhs(s, k):
        return np.array([(u[k] - s[0]) / 0.5, s[0] - 0.8 * math.sqrt(max(s[1], 0.0))]) + w[k]

    states = np.empty((n, 2))
    s, h = np.array([0.5, 1.0]), DT / 20
    for k in range(n):
        states[k] = s
        for _ in range(20):
            k1 = rhs(s, k)
            k2 = rhs(s + h / 2 * k1, k)
            k3 = rhs(s + h / 2 * k2, k)
            k4 = rhs(s + h * k3, k)
            s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    level = states[:, 1] + MEASUREMENT["level"] * rng.standard_normal(n)
    if level_limit is not None:
        level = np.minimum(level, level_limit)
    q = states[:, 0] + MEASUREMENT["q"] * rng.standard_normal(n)
    return pd.DataFrame({"t": np.arange(n) * DT, "u": u, "q": q, "level": level})


def _diagnose(frame: pd.DataFrame, **twin):
    table = table_from_mapping({**TANK, **twin})
    recording = recording_with_columns(frame, (*table.signals, *table.exogenous))
    return diagnose_table(recording, table)


def test_the_floor_of_a_lag_s_process_noise_is_its_error_since_each_window_start():
    """Held over a sample, a disturbance of level σ moves the lag by ``σ·φ``, ``φ = (1 − a)·τ/dt``;
    restarted from the recording, the twin's error ``i`` samples into a window has the variance
    ``(σφ)²·(1 − a^{2i})/(1 − a²)`` and ``E[e_i·e_{i+l}] = a^l·var_i``: the floor's level and
    autocorrelation are those, pooled over the windows, within sampling error."""
    sigma, tau = 0.02, 0.5
    table = table_from_mapping({**TANK, "process_noise": {"valve.y": sigma}})
    frame = _asset(4000, 3)
    recording = recording_with_columns(frame, (*table.signals, *table.exogenous))
    spec = units_of(table, list(recording.signals))[0]
    assert spec.name == "valve"
    settings = GapSettings()
    parts = _split(recording.n_samples, 0.5, settings.choose_frac)
    data = _prepare_unit(spec, recording, table, parts, settings, calibrate=False)
    fit = _nominal_fit(data, settings, calibrate=False)
    data.guess = state_guess(data, fit.theta, fit.variant)
    (floor,) = _process_noise_floor(data, fit, table.process_noise)

    a = math.exp(-DT / tau)
    step = sigma * (1 - a) * tau / DT
    starts, stops = data.windows("choose")
    offsets = [np.arange(stop - start) for start, stop in zip(starts, stops, strict=True)]
    variances = [step**2 * (1 - a ** (2 * i)) / (1 - a * a) for i in offsets]
    total = sum(float(v.sum()) for v in variances)
    assert floor.rms == pytest.approx(math.sqrt(total / sum(len(v) for v in variances)), rel=0.05)
    expected_acf = [sum(float(v[: len(v) - lag].sum()) for v in variances) * a**lag / total
                    for lag in range(1, 6)]  # fmt: skip
    assert floor.acf[1:6] == pytest.approx(expected_acf, abs=0.04)
    assert floor.source == "process" and floor.process == floor.rms
    # coloured: far fewer effective samples than samples, so a higher threshold
    n_choose = parts["choose"][1] - parts["choose"][0]
    assert effective_samples(floor.acf, n_choose) < 0.4 * n_choose
    # seeded: the same draws every time; none for a table without process noise
    assert _process_noise_floor(data, fit, table.process_noise)[0].rms == floor.rms
    assert _process_noise_floor(data, fit, {}) == [None]
    assert PROCESS_NOISE_DRAWS > 1


def test_a_disturbed_asset_reads_none_when_the_twin_declares_its_process_noise():
    frame = _asset(1500, 1)
    declared = _diagnose(frame, noise=MEASUREMENT, process_noise=PROCESS)
    assert declared.effect == "none", (declared.module, declared.effect)
    assert all("process" in unit.floor_source for unit in declared.units.values())
    # the same levels said as white measurement noise on the readings: the drift is a gap
    as_measurement = _diagnose(frame, noise={"q": 0.01, "level": 0.01})
    assert any(unit.flagged for unit in as_measurement.units.values())
    assert not any("process" in unit.floor_source for unit in as_measurement.units.values())


def test_a_level_sensor_that_clips_is_named_under_the_process_noise():
    frame = _asset(1500, 2)
    limit = float(np.quantile(frame["level"], 0.85))
    result = _diagnose(_asset(1500, 2, level_limit=limit), noise=MEASUREMENT,
                       process_noise=PROCESS)  # fmt: skip
    assert (result.module, result.effect, result.at) == ("tank", "output_saturation", "level")
