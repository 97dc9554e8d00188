"""The benchmark families of other physics (tanks, motor, thermal): docs/gap.md §Benchmark."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from dtwin._validation import DtwinValueError
from dtwin.gapbench import rigs
from dtwin.gapbench.families import (
    FAMILIES,
    FAMILY_CASE_TYPES,
    FAMILY_EFFECTS,
    generate_family_case,
    parse_family_case_type,
    run_family_case,
    score_family_case,
    summarise_family_scores,
    write_family_case,
)
from dtwin.gapbench.family_effects import SCALE_ERROR_MIN
from dtwin.gapbench.rigs import generate_any_case
from dtwin.twin.table import table_from_mapping

#: Samples of the quick cases (the benchmark's are 2000–10,000).
SHORT = 200
#: Keys every case's key holds.
KEY_FIELDS = {
    "family", "arm", "effect", "expected_effect", "accepted_effects", "module", "group",
    "at", "in_list", "magnitude", "snr", "snr_by_signal", "form", "params", "true_params", "noise",
    "noise_pole", "noise_declared", "internal", "seed", "n_samples", "dt", "columns",
}  # fmt: skip
EFFECT_TYPES = [case for case in FAMILY_CASE_TYPES if not case.endswith("_none")]


def test_the_same_seed_writes_the_same_bytes(tmp_path):
    for folder in ("a", "b"):
        write_family_case("tanks_state_limit", 3, 11, tmp_path / folder, n_samples=SHORT)
    for name in ("recording.csv", "twin.yaml", "key.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    other = generate_family_case("tanks_state_limit", 12, n_samples=SHORT).recording
    assert not other.equals(
        generate_family_case("tanks_state_limit", 11, n_samples=SHORT).recording
    )


@pytest.mark.parametrize("case_type", EFFECT_TYPES)
def test_every_effect_generates_and_grows_with_its_magnitude(case_type):
    weak = generate_family_case(case_type, 5, magnitude=0.1, n_samples=SHORT)
    strong = generate_family_case(case_type, 5, magnitude=0.9, n_samples=SHORT)
    key = strong.key
    assert set(key) >= KEY_FIELDS
    assert key["family"] == case_type.partition("_")[0]
    assert np.isfinite(strong.recording.to_numpy()).all()
    assert list(strong.recording.columns) == key["columns"]
    assert key["module"] in key["group"]
    assert key["expected_effect"] in (key["effect"], "unexplained")
    if case_type.endswith("output_scale_error"):  # both may sit at the smallest gain error
        assert 0 < weak.key["snr"] <= key["snr"]
        assert abs(key["params"]["gain"] - 1.0) >= SCALE_ERROR_MIN
    else:
        assert 0 < weak.key["snr"] < key["snr"]


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_a_clean_recording_carries_the_declared_noise(family):
    run = run_family_case(f"{family}_none", 2, internal=True, n_samples=1500)
    twin, key = run.case.twin, run.case.key
    assert key["noise_declared"] and key["snr"] == 0.0 and key["module"] is None
    for signal, declared in twin["noise"].items():
        observed = float(np.std(run.case.recording[signal] - run.clean[signal]))
        assert observed == pytest.approx(declared, rel=0.3), signal
        assert declared == pytest.approx(key["noise"][signal], rel=0.1)
        spread = float(np.std(run.clean[signal]))
        assert 0.004 * spread < key["noise"][signal] < 0.025 * spread
    assert run.case.recording[FAMILIES[family].input].equals(run.clean[FAMILIES[family].input])


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_the_twin_file_is_a_modules_table_within_two_percent_of_the_truth(family):
    case = generate_family_case(f"{family}_bare_none", 4, n_samples=SHORT)
    twin = yaml.safe_load(yaml.safe_dump(case.twin, sort_keys=False))
    assert set(twin) == {"dt", "modules", "noise"}
    assert twin["dt"] == pytest.approx(case.recording.t[1])
    for name, module in twin["modules"].items():
        assert {"inputs", "outputs", "params"} <= set(module)
        assert ("block" in module) != ("derivatives" in module)
        for param, value in module["params"].items():
            truth = case.key["true_params"][name][param]
            assert abs(value - truth) <= 0.02 * abs(truth) + 1e-12, f"{name}.{param}"
    table = table_from_mapping(twin)  # the parser accepts it
    assert set(table.signals) >= set(case.recording.columns) - {"t", FAMILIES[family].input}
    assert set(twin["noise"]) == set(case.recording.columns) - {"t", FAMILIES[family].input}


def test_a_mismatched_param_is_off_beyond_the_calibration_tolerance():
    case = generate_family_case("thermal_parameter_mismatch", 6, magnitude=0.0, n_samples=SHORT)
    key = case.key
    declared = case.twin["modules"][key["module"]]["params"][key["at"]]
    true = key["true_params"][key["module"]][key["at"]]
    assert 0.14 < abs(true / declared - 1.0) < 0.41
    assert key["params"]["true"] == pytest.approx(true)


@pytest.mark.parametrize("family, state", [("tanks", "h1"), ("thermal", "T1")])
def test_a_state_limit_is_reached_in_the_training_half(family, state):
    for seed in range(2):
        run = run_family_case(f"{family}_internal_state_limit", seed, magnitude=0.0, n_samples=800)
        key, clean = run.case.key, run.clean
        limit = key["params"]["limit_upper"]
        first = clean[state].to_numpy()[: len(clean) // 2]
        overshoot = 0.02 * float(np.ptp(first)) if key["form"] == "steep" else 1e-9
        assert key["at"] == state and key["expected_effect"] == "state_limit"
        assert first.max() >= limit - 1e-9, seed  # reached in the training half
        assert clean[state].max() <= limit + overshoot, seed  # and never passed


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_without_internal_signals_the_internal_columns_are_absent(family):
    inside = generate_family_case(f"{family}_internal_input_saturation", 3, n_samples=SHORT)
    bare = generate_family_case(f"{family}_bare_input_saturation", 3, n_samples=SHORT)
    internal = FAMILIES[family].internal
    assert set(internal) <= set(inside.recording.columns)
    assert not set(internal) & set(bare.recording.columns)
    for column in bare.recording.columns:  # the same run, fewer columns
        assert bare.recording[column].equals(inside.recording[column])
    assert (inside.key["arm"], bare.key["arm"]) == ("internal", "bare")
    assert bare.key["group"] == list(bare.twin["modules"])  # one unit: every module
    assert len(inside.key["group"]) == 1  # the input's reader is recorded on both sides


def test_case_types_parse_and_dispatch(monkeypatch):
    assert len(FAMILY_CASE_TYPES) == sum(len(e) for e in FAMILY_EFFECTS.values())
    family, effect, internal = parse_family_case_type("motor_bare_state_sign")
    assert (family.name, effect, internal) == ("motor", "state_sign", False)
    assert parse_family_case_type("thermal_none")[2] is None
    with pytest.raises(DtwinValueError, match="motor effect"):
        parse_family_case_type("motor_state_limit")
    with pytest.raises(DtwinValueError, match="family case type"):
        parse_family_case_type("boiler_none")
    calls = []
    monkeypatch.setattr(rigs, "generate_family_case", lambda *args: calls.append(args))
    monkeypatch.setattr(rigs, "generate_rig_case", lambda *args: calls.append(("rig", *args)))
    generate_any_case("motor_cogging", 3, nominal={})  # as the benchmark calls it
    generate_any_case("rig_none", 4)
    assert calls == [("motor_cogging", 3), ("rig", "none", 4)]


def test_scores_locate_by_unit_and_name_states_by_their_name():
    key = generate_family_case("tanks_bare_state_limit", 3, n_samples=SHORT).key
    group = {"module": "pump", "modules": ["pump", "tanks", "sensor"]}
    right = score_family_case(key, {**group, "effect": "state_limit", "at": "tanks.h1"})
    assert right["located"] and right["at_ok"] and right["named"]
    wrong_state = score_family_case(key, {**group, "effect": "state_limit", "at": "tanks.h2"})
    assert wrong_state["located"] and not wrong_state["named"]
    elsewhere = score_family_case(key, {"module": "pump", "modules": ["pump"],
                                        "effect": "state_limit", "at": "h1"})  # fmt: skip
    assert not elsewhere["located"] and not elsewhere["named"]
    none_key = {**key, "expected_effect": "none", "effect": "none", "module": None,
                "in_list": False, "at": None, "accepted_effects": ["none"]}  # fmt: skip
    assert score_family_case(none_key, {"module": None, "modules": [], "effect": "none"})["named"]
    assert score_family_case(none_key, {**group, "effect": "unexplained"})["located"] is None
    out = {**key, "expected_effect": "unexplained", "effect": "clogging", "in_list": False,
           "accepted_effects": ["unexplained"]}  # fmt: skip
    assert score_family_case(out, {**group, "effect": "unexplained"})["named"]
    assert not score_family_case(out, {**group, "effect": "parameter_mismatch"})["named"]


def test_a_delay_is_either_delay_when_the_unit_cannot_tell_them_apart():
    bare = generate_family_case("motor_bare_output_delay", 3, n_samples=SHORT).key
    inside = generate_family_case("motor_internal_output_delay", 3, n_samples=SHORT).key
    assert bare["accepted_effects"] == ["output_delay", "input_delay"]
    assert inside["accepted_effects"] == ["output_delay"]
    answer = {"module": "electrical", "modules": ["electrical", "mechanical"],
              "effect": "input_delay", "at": "V"}  # fmt: skip
    assert score_family_case(bare, answer)["named"]
    assert not score_family_case(inside, {**answer, "modules": ["electrical"]})["named"]


def test_the_summary_gives_wilson_intervals_per_family_and_arm():
    rows = [
        {"family": "tanks", "arm": arm, "effect": effect, "expected_effect": expected,
         "in_list": expected not in ("none", "unexplained"), "located": located, "named": named}
        for arm, effect, expected, located, named in [
            ("bare", "state_limit", "state_limit", True, True),
            ("bare", "output_delay", "output_delay", True, False),
            ("internal", "none", "none", None, True),
            ("internal", "clogging", "unexplained", False, False),
        ]
    ]  # fmt: skip
    summary = summarise_family_scores(rows)["tanks"]
    assert summary["n_cases"] == 4
    assert (summary["module"]["k"], summary["module"]["n"]) == (2, 3)
    assert (summary["effect"]["k"], summary["effect"]["n"]) == (1, 2)
    assert summary["none"]["rate"] == 1.0 and summary["unexplained"]["rate"] == 0.0
    assert 0.0 < summary["effect"]["low"] < 0.5 < summary["effect"]["high"] < 1.0
    assert summary["arms"]["bare"]["effect"]["n"] == 2
    assert math.isnan(summary["arms"]["bare"]["none"]["low"])


@pytest.mark.parametrize("seed", range(4))
def test_a_battery_cycled_by_pulses_keeps_its_charge_within_bounds(seed):
    """The cycler's pulses turn sign rather than take the charge out of 0.2–0.8 (an integrating
    state: nothing else would bring it back), both directions in either half."""
    from dtwin.gapbench.family_assets import BATTERY

    asset = BATTERY.draw(np.random.default_rng(seed), 6000)
    charge = asset.params["soc0"] - np.cumsum(asset.u) * asset.dt / asset.params["Q"]
    assert charge.min() >= 0.2 - 1e-9 and charge.max() <= 0.8 + 1e-9
    for half in (asset.u[:3000], asset.u[3000:]):
        assert half.min() < 0.0 < half.max()
