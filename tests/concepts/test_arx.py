"""ARX least squares and rollout (paper §3.2, Eqs. (22)–(24)); crosschecks against R."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dtwin._validation import DtwinValueError
from dtwin.arx import ArxFit, ArxOrders, fit_arx, simulate_arx
from dtwin.reference.arx_crosscheck import crosscheck_arx
from tests.conftest import REFERENCE


def _simulate_known(theta_a, theta_b, d, n=600, seed=3):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(max(len(theta_a), len(theta_b) + d), n):
        y[t] = sum(a * y[t - i] for i, a in enumerate(theta_a, 1)) + sum(
            b * u[t - d - j] for j, b in enumerate(theta_b, 1)
        )
    return y, u


@pytest.mark.parametrize("d", [0, 1, 2])
def test_fit_recovers_known_coefficients_noise_free(d):
    y, u = _simulate_known([1.5, -0.7], [0.3, 0.2], d)
    fit = fit_arx(y, u, ArxOrders(2, 2, d))
    np.testing.assert_allclose(fit.theta, [1.5, -0.7, 0.3, 0.2], atol=1e-9)


@pytest.mark.parametrize(("na", "nb", "d"), [(1, 1, 0), (2, 2, 0), (2, 1, 1), (1, 3, 0), (0, 2, 0)])
def test_rollout_equals_explicit_recursion(na, nb, d):
    rng = np.random.default_rng(na * 10 + nb + d)
    theta = np.concatenate([rng.uniform(-0.3, 0.3, na), rng.standard_normal(nb)])
    fit = ArxFit(ArxOrders(na, nb, d), theta, n_train=0)
    u = rng.standard_normal(80)
    initial = rng.standard_normal(na)
    p = max(na, nb + d)
    expected = np.zeros(80)
    expected[:na] = initial
    for t in range(p, 80):
        expected[t] = sum(fit.a[i - 1] * expected[t - i] for i in range(1, na + 1)) + sum(
            fit.b[j - 1] * u[t - d - j] for j in range(1, nb + 1)
        )
    np.testing.assert_allclose(simulate_arx(fit, u, initial), expected, atol=1e-12)


def test_reproduces_r_coefficients_and_rollout(config, twin):
    orders = {k: ArxOrders(**v) for k, v in config["arx"]["orders"].items()}
    checks, deviations = crosscheck_arx(
        REFERENCE / "faulted_pipeline_seed11_rerun.csv",
        REFERENCE / "arx_theta_seed11_rerun.csv",
        orders,
        config["arx"]["train_frac"],
        twin,
    )
    assert all(check.passed for check in checks), deviations
    assert max(deviations["theta_max_rel_dev"].values()) < 1e-6
    assert max(deviations["rollout_max_abs_dev"].values()) < 1e-9


def test_constant_input_is_rank_deficient():
    with pytest.raises(DtwinValueError, match="rank-deficient"):
        fit_arx(np.linspace(0, 1, 50), np.ones(50), ArxOrders(1, 2))


def test_bad_inputs_give_clear_errors():
    with pytest.raises(DtwinValueError, match="at least"):
        fit_arx(np.ones(3), np.ones(3), ArxOrders(2, 2))
    with pytest.raises(DtwinValueError, match="finite"):
        fit_arx(np.array([1.0, np.nan, 2.0, 3.0, 4.0, 5.0]), np.ones(6), ArxOrders(1, 1))
    with pytest.raises(DtwinValueError, match="nb >= 1"):
        ArxOrders(1, 0)
    fit = ArxFit(ArxOrders(2, 1), np.array([0.5, 0.1, 1.0]), 10)
    with pytest.raises(DtwinValueError, match="initial_y"):
        simulate_arx(fit, np.ones(10), np.zeros(1))


def test_r_rollout_csv_agrees_with_zero_seeded_chain(config, twin):
    """ARX_vs_Phys.R seeds rollouts with zeros; our chain with rollout_init='zeros' matches."""
    from dtwin.reference.loaders import load_r_physics
    from dtwin.surrogate import fit_surrogates, run_surrogate_chain

    physics, _ = load_r_physics(REFERENCE / "faulted_pipeline_seed11_rerun.csv")
    orders = {k: ArxOrders(**v) for k, v in config["arx"]["orders"].items()}
    fits = fit_surrogates(physics, orders, 0.5)
    ours = run_surrogate_chain(physics, fits, twin, rollout_init="zeros")
    r = pd.read_csv(REFERENCE / "arx_vs_phys_nominal_zeroseed_rerun.csv")
    for signal, column in [("x", "M1_x_pos_A"), ("y_fused", "M3_y_fused_A"), ("z", "M4_z_A")]:
        np.testing.assert_allclose(ours[signal], r[column], atol=1e-9)
