"""The AR-HMM stage and Fig. 13's checks: parameter count, notes, errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.figures.fig13_ar_hmm import ar_hmm_checks
from dtwin.stages.ar_regimes import ar_regime_sweep
from dtwin.twin.wiring import RESIDUALS

SETTINGS = {
    "seed": 3,
    "ks": [2, 3],
    "k_max": 3,
    "stop_after_rises": 2,
    "n_restarts": 2,
    "max_iter": 40,
    "tol": 1e-6,
    "var_floor": 1e-6,
}


def _residuals(n_steps: int = 160) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    regimes = np.repeat(["Nominal", "SensorNoisy", "DynamicsOff", "Drift"], n_steps // 4)
    level = np.repeat([0.0, 1.0, -1.0, 2.0], n_steps // 4)[:, None]
    values = np.cumsum(rng.normal(0, 0.1, (n_steps, len(RESIDUALS))), axis=0) * 0.1 + level
    table = pd.DataFrame(values, columns=list(RESIDUALS))
    table.insert(0, "regime", regimes)
    return table


def test_the_sweep_scores_every_k_and_counts_three_parameters_per_state_and_feature():
    table, summary = ar_regime_sweep(_residuals(), SETTINGS, n_states=4)
    assert table["K"].tolist() == [2, 3, 4]  # ks, then K = n_states added; k_max 3 < 4
    k = table["K"]
    assert (table["n_params"] == (k - 1) + k * (k - 1) + 3 * 10 * k).all()
    assert table["accuracy"].between(0, 1).all()
    assert summary["n_states"] == 4 and set(summary["at_n_states"]["states"]) == {
        "S1",
        "S2",
        "S3",
        "S4",
    }
    assert summary["k_star"] in (2, 3, 4)


def test_a_missing_key_or_regime_column_is_one_clear_error():
    with pytest.raises(DtwinValueError, match=r"ar_hmm is missing key\(s\): seed"):
        ar_regime_sweep(_residuals(), {k: v for k, v in SETTINGS.items() if k != "seed"}, 4)
    with pytest.raises(DtwinValueError, match="'regime' column"):
        ar_regime_sweep(_residuals().drop(columns="regime"), SETTINGS, 4)


def _table(bics, gains) -> pd.DataFrame:
    ks = list(range(2, 2 + len(bics)))
    log_likelihood = [1000.0 * k for k in ks]
    return pd.DataFrame(
        {
            "K": ks,
            "log_likelihood": log_likelihood,
            "log_likelihood_half": [ll - g for ll, g in zip(log_likelihood, gains, strict=True)],
            "bic": bics,
            "n_params": [(k - 1) + k * (k - 1) + 3 * 10 * k for k in ks],
            "n_usable": 4,
            "n_starts": 4,
        }
    )


def test_every_failed_target_carries_its_cause():
    summary = {
        "k_star": 5,
        "bracketed": True,
        "n_states": 4,
        "features": [f"f{i}" for i in range(10)],
        "at_n_states": {"accuracy": 0.5},
    }
    # K = 4 is 900 BIC units above the minimum at K = 5; more starts moved the BIC by <= 20.
    checks = ar_hmm_checks(
        _table([3000, 2000, 1000, 100, 300, 500], [0, 0, 10, 0, 0, 0]), summary, 9, 0.8
    )
    by_id = {c.id: c for c in checks}
    assert all(c.passed for c in checks if c.kind == "validity")
    assert not by_id["ar_bic_chooses_the_injected_regimes"].passed
    assert by_id["ar_bic_chooses_the_injected_regimes"].note.startswith("method:")
    assert by_id["ar_accuracy_above_gaussian"].note.startswith("method:")
    assert by_id["ar_best_loglik_stable_in_starts"].note.startswith("optimiser:")
    assert all(c.note for c in checks if c.kind in ("claim", "target") and not c.passed)
    # the same BIC gap within what more starts still change is the optimiser's
    close = ar_hmm_checks(
        _table([3000, 2000, 1000, 100, 300, 500], [0, 0, 400, 0, 0, 0]), summary, 9, 0.8
    )
    note = {c.id: c for c in close}["ar_bic_chooses_the_injected_regimes"].note
    assert note.startswith("optimiser:")
