"""Detection power (dtwin/gapbench/power.py): one row per recording, the tables and the limits."""

from __future__ import annotations

import numpy as np

from dtwin.gapbench.generator import MIN_MAGNITUDE
from dtwin.gapbench.power import INVALID, detection_limits, power_row, power_table
from tests.conftest import paper_twin

DIAGNOSE = {"train_frac": 0.5, "calibrate": False}


def _row(effect, level, seed):
    return power_row(
        effect, level, seed, nominal=paper_twin(), diagnose_settings=DIAGNOSE, n_samples=1200
    )


def test_an_invisible_effect_is_not_named_and_a_clear_one_is():
    faint = _row("sensor_bias_drift", MIN_MAGNITUDE, 3)
    clear = _row("sensor_bias_drift", 1.0, 3)
    assert faint["snr"] < 0.05 and not faint["named"] and faint["answer"] == "none"
    assert clear["snr"] > 3 and clear["named"] and clear["located"]
    assert clear["gap_ratio"] > 1 >= faint["max_ratio"]
    assert clear["module"] + "=" in clear["module_ratios"]


def test_a_clean_recording_is_named_when_it_reads_none():
    row = _row("wrong_noise__none", None, 5)
    assert np.isnan(row["level"]) and np.isnan(row["gap_ratio"])
    assert row["named"] == (row["answer"] == "none")


def test_tables_count_named_recordings_and_skip_runaway_ones():
    rows = [
        {"effect": "e", "level": 0.0, "snr": 1.0, "named": True, "answer": "e"},
        {"effect": "e", "level": 0.0, "snr": 2.0, "named": False, "answer": "none"},
        {"effect": "e", "level": 1.0, "snr": 9.0, "named": True, "answer": "e"},
        {"effect": "e", "level": 1.0, "snr": np.nan, "named": np.nan, "answer": INVALID},
    ]
    table = power_table(rows).set_index("level")
    assert table.loc[0.0, ["n", "named"]].tolist() == [2, 1]
    assert table.loc[1.0, ["n", "named"]].tolist() == [1, 1]
    assert table.loc[0.0, "low"] < 0.5 < table.loc[0.0, "high"]


def test_detection_limits_rise_with_the_share_and_are_nan_without_a_rise():
    snr = np.repeat([0.5, 1.0, 2.0, 4.0], 20)
    rng = np.random.default_rng(0)
    named = rng.uniform(size=snr.size) < 1 / (1 + (1.4 / snr) ** 4)
    rows = [{"effect": "e", "snr": s, "named": bool(k)} for s, k in zip(snr, named, strict=True)]
    rows += [{"effect": "flat", "snr": s, "named": True} for s in snr]
    limits = detection_limits(rows).set_index("effect")
    assert 0.9 < limits.loc["e", "snr_50"] < limits.loc["e", "snr_90"] < 4.0
    assert np.isnan(limits.loc["flat", ["snr_50", "snr_90"]].astype(float)).all()
