"""Typed config sections (dtwin.config_sections, the twin's sections a stage needs): errors name
the key, the shipped config parses, a parsed object passes through a stage entry unchanged."""

from __future__ import annotations

import pytest

from dtwin._validation import DtwinTypeError, DtwinValueError
from dtwin.config_sections import (
    AcfSettings,
    ArHmmSettings,
    CorrectionSettings,
    SimulationSettings,
)
from dtwin.params import ALGEBRAIC_SECTIONS, twin_params_from_mapping

SECTIONS = {
    "simulation": SimulationSettings,
    "acf": AcfSettings,
    "correction": CorrectionSettings,
    "ar_hmm": ArHmmSettings,
}


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_the_shipped_config_parses_and_a_parsed_section_passes_through(config, section):
    settings = SECTIONS[section].from_mapping(config[section])
    assert SECTIONS[section].from_mapping(settings) is settings
    for key, value in config[section].items():
        parsed = getattr(settings, key)
        assert (list(parsed) if isinstance(parsed, tuple) else parsed) == value


def test_the_sweep_shapings_parse_as_correction_settings(config):
    for method, raw in config["sensitivity"]["correction"].items():
        if method != "method":
            CorrectionSettings.from_mapping(raw, f"sensitivity.correction.{method}")


@pytest.mark.parametrize(
    ("section", "key", "value", "error", "message"),
    [
        ("simulation", "T", -1.0, DtwinValueError, "simulation.T must be > 0"),
        ("simulation", "seed", 1.5, DtwinValueError, "simulation.seed must be an integer >= 0"),
        ("acf", "nlags", 0, DtwinValueError, "acf.nlags must be an integer >= 1"),
        ("acf", "white_noise_n", 5, DtwinValueError, "acf.white_noise_n must be an integer >= 10"),
        ("acf", "ljungbox_lags", [], DtwinValueError, "acf.ljungbox_lags must be a non-empty"),
        ("acf", "ljungbox_lags", [10, 0], DtwinValueError, "acf.ljungbox_lags must be an integer"),
        ("acf", "significance", 1.0, DtwinValueError, r"acf.significance must be in \(0, 1\)"),
        ("acf", "strong_lag1", 1.5, DtwinValueError, r"acf.strong_lag1 must be in \[-1, 1\]"),
        ("correction", "kappa", "x", DtwinTypeError, "correction.kappa must be a number"),
        (
            "correction",
            "ema_alpha",
            1.3,
            DtwinValueError,
            r"correction.ema_alpha must be in \(0, 1\]",
        ),
        ("correction", "rate_max", -0.1, DtwinValueError, "correction.rate_max must be >= 0"),
        ("ar_hmm", "ks", [2, 0], DtwinValueError, "ar_hmm.ks must be an integer >= 1"),
        ("ar_hmm", "k_max", 2.5, DtwinValueError, "ar_hmm.k_max must be an integer >= 1"),
        ("ar_hmm", "var_floor", 0, DtwinValueError, "ar_hmm.var_floor must be > 0"),
        ("ar_hmm", "engine", "r", DtwinValueError, "ar_hmm.engine must be one of compiled"),
    ],
)
def test_a_bad_value_names_its_key(config, section, key, value, error, message):
    with pytest.raises(error, match=message):
        SECTIONS[section].from_mapping({**config[section], key: value})


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_missing_and_unknown_keys_are_named(config, section):
    raw = dict(config[section])
    first = next(iter(raw))
    with pytest.raises(DtwinValueError, match=f"{section} is missing key\\(s\\): {first}"):
        SECTIONS[section].from_mapping({k: v for k, v in raw.items() if k != first})
    with pytest.raises(DtwinValueError, match=f"{section} has unknown key\\(s\\): typo"):
        SECTIONS[section].from_mapping({**raw, "typo": 1})
    with pytest.raises(DtwinTypeError, match=f"{section} must be a mapping"):
        SECTIONS[section].from_mapping([1, 2])


def test_a_stage_names_the_twin_section_it_needs(config):
    """The correction and fault injection read dt, fusion and kpi of twin, parsed once."""
    assert ALGEBRAIC_SECTIONS == ("fusion", "kpi")
    part = {k: config["twin"][k] for k in ("dt", *ALGEBRAIC_SECTIONS)}
    twin = twin_params_from_mapping(part, require_all=False, required=ALGEBRAIC_SECTIONS)
    assert twin_params_from_mapping(twin, required=ALGEBRAIC_SECTIONS) is twin
    with pytest.raises(DtwinValueError, match="twin is missing key: kpi"):
        twin_params_from_mapping(
            {"dt": 0.02, "fusion": {"alpha": 0.6}}, require_all=False, required=ALGEBRAIC_SECTIONS
        )
    with pytest.raises(DtwinValueError, match=r"twin.fusion.alpha must be in \[0, 1\] \(got 1.3\)"):
        twin_params_from_mapping(
            {**part, "fusion": {"alpha": 1.3}}, require_all=False, required=ALGEBRAIC_SECTIONS
        )


def test_the_bic_section_parses_with_the_library_defaults(config):
    from dtwin.config_sections import BicSettings

    settings = BicSettings.from_mapping(config["bic"])
    assert settings.ks == tuple(config["bic"]["ks"]) and settings.k_max == config["bic"]["k_max"]
    assert BicSettings.from_mapping(settings) is settings
    short = BicSettings.from_mapping({"ks": [2, 3], "n_restarts": 2})
    assert (short.k_max, short.stop_after_rises, short.split_starts) == (None, 2, False)
    with pytest.raises(DtwinValueError, match=r"bic\.split_starts must be true or false"):
        BicSettings.from_mapping({**config["bic"], "split_starts": "yes"})
    with pytest.raises(DtwinValueError, match="bic is missing key\\(s\\): n_restarts"):
        BicSettings.from_mapping({"ks": [2]})
    with pytest.raises(DtwinValueError, match=r"draws\.bic\.k_max must be an integer >= 1"):
        BicSettings.from_mapping({**config["bic"], "k_max": 0}, "draws.bic")


def test_the_sensitivity_section_parses_and_keeps_what_fig11_records(config):
    from dtwin.config_sections import SensitivitySettings, SweepPointSettings

    raw = config["sensitivity"]
    settings = SensitivitySettings.from_mapping(raw)
    assert SensitivitySettings.from_mapping(settings) is settings
    assert len(settings.grid()) == len(raw["alphas"]) * 9 * raw["n_replicates"]
    # Fig. 11's JSON records the sweep's HMM and shapings as the config has them
    assert settings.point.hmm.summary() == raw["hmm"]
    assert settings.point.code.options() == raw["correction"]["code"]
    assert settings.point.paper.options() == raw["correction"]["paper"]
    # a sweep chunk gets the point's keys only (and the engine)
    part = {k: raw[k] for k in ("seed", "correction", "r_signals")}
    point = SweepPointSettings.from_mapping({**part, "hmm": {**raw["hmm"], "engine": "hmmlearn"}})
    assert point.hmm.em.engine == "hmmlearn" and point.seed == raw["seed"]


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"alphas": [0.2, 1.2]}, r"sensitivity\.alphas\[1\] must be in \[0, 1\]"),
        ({"sensor_B_mults": [0.5, 0.5]}, r"sensitivity\.sensor_B_mults must not repeat"),
        ({"interval": 1.0}, r"sensitivity\.interval must be in \(0, 1\)"),
        ({"r_signals": "yes"}, r"sensitivity\.r_signals must be true or false"),
        ({"seed": -1}, r"sensitivity\.seed must be an integer >= 0"),
        ({"typo": 1}, r"sensitivity has unknown key\(s\): typo"),
        ({"hmm": {"n_states": 4, "tol": 0}}, r"sensitivity\.hmm\.tol must be > 0"),
        ({"correction": {"method": "code"}}, r"sensitivity\.correction is missing key\(s\): code"),
    ],
)
def test_a_bad_sensitivity_value_names_its_key(config, edit, message):
    from dtwin.config_sections import SensitivitySettings

    with pytest.raises(DtwinValueError, match=message):
        SensitivitySettings.from_mapping({**config["sensitivity"], **edit})


def test_a_bad_correction_method_names_its_key(config):
    from dtwin.config_sections import SensitivitySettings

    raw = config["sensitivity"]
    correction = {**raw["correction"], "method": "both"}
    with pytest.raises(DtwinValueError, match=r"sensitivity\.correction\.method must be one of"):
        SensitivitySettings.from_mapping({**raw, "correction": correction})


def test_the_draws_section_parses_and_names_a_bad_key(config):
    from dtwin.config_sections import DrawsSettings

    settings = DrawsSettings.from_mapping(config["draws"])
    assert DrawsSettings.from_mapping(settings) is settings
    assert settings.bic.n_restarts == config["draws"]["bic"]["n_restarts"]
    bic = {**config["draws"]["bic"], "chunk_size": 0}
    with pytest.raises(DtwinValueError, match=r"draws\.bic\.chunk_size must be an integer >= 1"):
        DrawsSettings.from_mapping({**config["draws"], "bic": bic})
    with pytest.raises(DtwinValueError, match=r"draws has unknown key\(s\): typo"):
        DrawsSettings.from_mapping({**config["draws"], "typo": 1})


def test_the_arx_section_parses_and_names_a_bad_key(config):
    from dtwin.config_sections import ArxSettings

    raw = config["arx"]
    settings = ArxSettings.from_mapping(raw)
    assert ArxSettings.from_mapping(settings) is settings
    assert list(settings.orders) == list(raw["orders"])
    assert {name: o.__dict__ for name, o in settings.orders.items()} == raw["orders"]
    assert (settings.train_frac, settings.rollout_init) == (raw["train_frac"], raw["rollout_init"])
    # Fig. 1's rule passes the orders alone
    assert ArxSettings.from_mapping({"orders": raw["orders"]}).orders == settings.orders
    orders = {**raw["orders"], "M1": {"na": 2, "nb": 0}}
    with pytest.raises(DtwinValueError, match=r"arx\.orders\.M1\.nb must be an integer >= 1"):
        ArxSettings.from_mapping({**raw, "orders": orders})
    with pytest.raises(DtwinValueError, match=r"arx\.orders is missing key\(s\): M2a, M2b"):
        ArxSettings.from_mapping({**raw, "orders": {k: raw["orders"][k] for k in ("M0", "M1")}})
    with pytest.raises(DtwinValueError, match=r"arx\.rollout_init must be one of physics, zeros"):
        ArxSettings.from_mapping({**raw, "rollout_init": "r"})


def test_the_sweeps_shapings_are_the_sweeps_correction_methods():
    """config_sections names them itself so that reading a config loads no pandas."""
    from dtwin.config_sections import _SHAPINGS
    from dtwin.sensitivity_sweep import CORRECTION_METHODS

    assert _SHAPINGS == CORRECTION_METHODS
