"""Every HMM fit of the pipeline reads its EM settings from its config section.

The sweep once ignored ``var_floor`` (it built its own options and fell back to the library
default). Each stage entry that fits an HMM is run here with unusual settings, and the call that
reaches the HMM fit is recorded; an AST scan makes sure no other module calls the fit.
"""

from __future__ import annotations

import ast
import inspect

import numpy as np
import pandas as pd
import pytest

import dtwin.hmm
import dtwin.stages.regimes
import dtwin.stages.sensitivity
from dtwin._validation import DtwinValueError
from dtwin.config_sections import EmSettings, HmmSettings
from dtwin.hmm import fit_hmm
from dtwin.sensitivity_sweep import SweepPoint
from dtwin.twin.wiring import RESIDUALS
from tests.conftest import REPO

ODD = {"n_restarts": 2, "max_iter": 7, "tol": 3.5e-5, "var_floor": 0.0123}
FIT_FUNCTIONS = {"fit_hmm", "fit_zscored_hmm", "bic_by_k"}


class _FitReachedError(Exception):
    """Raised by the recording stand-in so no EM actually runs."""


@pytest.fixture
def recorded(monkeypatch):
    calls = []

    def stand_in(X, n_states, **options):
        calls.append(options)
        raise _FitReachedError

    # the regime stages fit through dtwin.hmm.fit_zscored_hmm, which calls dtwin.hmm.fit_hmm
    for module in (dtwin.hmm, dtwin.stages.sensitivity):
        monkeypatch.setattr(module, "fit_hmm", stand_in)
    # the BIC sweep fits its starts without fit_hmm; its options pass through _em_options
    monkeypatch.setattr(dtwin.hmm, "_em_options", stand_in)
    return calls


def _assert_em_options(call):
    assert {key: call[key] for key in ("max_iter", "tol", "var_floor")} == {
        key: ODD[key] for key in ("max_iter", "tol", "var_floor")
    }


def test_settings_defaults_are_the_library_defaults():
    defaults = inspect.signature(fit_hmm).parameters
    for key, value in HmmSettings(n_states=4).fit_options().items():
        assert defaults[key].default == value, key


def test_parsed_settings_pass_through(config):
    settings = HmmSettings.from_mapping(config["hmm"])
    assert HmmSettings.from_mapping(settings) is settings
    assert EmSettings.from_mapping(settings.em) is settings.em


def test_settings_name_the_config_key():
    with pytest.raises(DtwinValueError, match=r"sensitivity\.hmm\.var_floor must be > 0"):
        HmmSettings.from_mapping({"n_states": 4, "var_floor": -1}, "sensitivity.hmm")
    with pytest.raises(DtwinValueError, match=r"hmm\.max_iter must be an integer >= 1"):
        HmmSettings.from_mapping({"n_states": 4, "max_iter": 2.5})


def _random_frame(columns) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    return pd.DataFrame(rng.normal(size=(50, len(columns))), columns=list(columns))


def test_nominal_fault_and_crosscheck_fits_read_the_hmm_section(config, recorded):
    """fit_regimes is the one path of the nominal fit, the fault fit and the R crosscheck."""
    hmm = {**config["hmm"], **ODD}
    with pytest.raises(_FitReachedError):
        dtwin.stages.regimes.fit_regimes(_random_frame(RESIDUALS), hmm, "nominal_fit")
    assert recorded[-1]["n_restarts"] == ODD["n_restarts"]
    _assert_em_options(recorded[-1])


def test_bic_sweep_reads_the_hmm_section(config, recorded):
    """The rule passes only seed and the EM options (a change of K must not rerun it)."""
    keys = ("seed", "max_iter", "tol", "var_floor", "engine")
    hmm = {key: {**config["hmm"], **ODD}[key] for key in keys}
    with pytest.raises(_FitReachedError):
        dtwin.stages.regimes.sweep_bic(
            {"nominal_residuals": _random_frame(RESIDUALS)}, config["bic"], hmm
        )
    _assert_em_options(recorded[-1])


def test_every_sweep_point_reads_the_sensitivity_hmm_section(config, recorded):
    sensitivity = {**config["sensitivity"], "hmm": {**config["sensitivity"]["hmm"], **ODD}}
    with pytest.raises(_FitReachedError):
        dtwin.stages.sensitivity.sweep_point(
            SweepPoint(0.6, 1.0, 1.0, 0),
            simulation={**config["simulation"], "T": 4.0},
            command=config["command"],
            twin=config["twin"],
            arx=config["arx"],
            sensitivity=sensitivity,
        )
    assert recorded[-1]["n_restarts"] == ODD["n_restarts"]
    _assert_em_options(recorded[-1])


def test_no_other_module_fits_an_hmm():
    """New callers of the HMM fit must come through HmmSettings and be added above."""
    callers = set()
    for path in (REPO / "dtwin").rglob("*.py"):
        if path == REPO / "dtwin" / "hmm.py":
            continue  # the fits themselves (fit_zscored_hmm is z-scoring, then fit_hmm)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) in FIT_FUNCTIONS:
                callers.add(path.relative_to(REPO).as_posix())
    assert callers == {
        "dtwin/stages/regimes.py",
        "dtwin/stages/sensitivity.py",
        "dtwin/monitor/regime_model.py",  # dtwin regimes: RegimeSettings.em, an EmSettings
    }
