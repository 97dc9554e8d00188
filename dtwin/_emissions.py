"""Emission log-densities and the AR(1) M-step, shared by the HMM fits and the EM engines.

Gaussian (paper Eq. (3), :mod:`dtwin.hmm`) and AR(1) (:mod:`dtwin.hmm_ar`) emissions, read by
the model modules and by hmmlearn's reference engine (:mod:`dtwin._em_reference`); they import
nothing of dtwin's, so the engine never imports the model modules back.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__: list[str] = []


def _log_emission(X: np.ndarray, means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """``log N(x_t | μ_k, diag σ_k²)``, shape (T, K), as two matrix products.

    ``−½[Σ_d x²/σ² − 2 x·(μ/σ²) + Σ_d μ²/σ² + Σ_d log(2πσ²)]``, evaluated in place on two
    T×K arrays; the one T×D temporary (``X²``) is freed before the second product.
    ``2·(X·M)`` is bit-identical to ``(2X)·M`` (doubling is exact in floating point outside
    the subnormal range), so the values are those of the plain expression.
    """
    precision = 1.0 / variances
    quadratic = (X**2) @ precision.T
    cross = X @ (means * precision).T
    cross *= 2.0
    quadratic -= cross
    del cross
    quadratic += (means**2 * precision).sum(axis=1) + np.log(2.0 * np.pi * variances).sum(axis=1)
    quadratic *= -0.5
    return quadratic


def _ar_log_emission(
    design: np.ndarray, intercepts: np.ndarray, coefs: np.ndarray, variances: np.ndarray
) -> np.ndarray:
    """``log N(y_t | c_k + φ_k x_t, diag σ_k²)``, shape (T, K), from design rows.

    The rows are ``(y, x, y², y·x, x²)`` (:func:`dtwin.hmm_ar._design`).

    ``Σ_d (y − c − φx)²/σ²`` expanded: the weights of ``(y, x, y², yx, x²)`` are
    ``(−2c, 2cφ, 1, −2φ, φ²)/σ²``, plus the constant ``Σ_d c²/σ²``.
    """
    w = 1.0 / variances  # (K, D)
    weights = np.hstack(
        [-2.0 * intercepts * w, 2.0 * intercepts * coefs * w, w, -2.0 * coefs * w, coefs**2 * w]
    )
    constant = (intercepts**2 * w).sum(axis=1) + np.log(2.0 * np.pi * variances).sum(axis=1)
    return -0.5 * (design @ weights.T + constant)


def _moments(weights: np.ndarray, design: np.ndarray) -> dict[str, np.ndarray]:
    """Weighted sums per state and feature: ``n`` (K, 1) and ``y, x, yy, xy, xx`` (K, D)."""
    sums = np.split(weights.T @ design, 5, axis=1)
    return {
        "n": weights.sum(axis=0)[:, None],
        **dict(zip(("y", "x", "yy", "xy", "xx"), sums, strict=True)),
    }


def _ar_mstep(
    moments: Mapping[str, np.ndarray], var_floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least squares of y on (1, x) per state and feature; returns (c, φ, σ²).

    ``φ = cov_w(x, y)/var_w(x)``, ``c = ȳ − φ x̄``, ``σ² = max(var_w(y) − φ·cov_w(x, y),
    var_floor)``. A state whose lagged values do not vary (var_w(x) ≈ 0) gets ``φ = 0``.
    """
    n = np.maximum(moments["n"], np.finfo(float).tiny)
    mean_x, mean_y = moments["x"] / n, moments["y"] / n
    var_x = moments["xx"] / n - mean_x**2
    var_y = moments["yy"] / n - mean_y**2
    cov = moments["xy"] / n - mean_x * mean_y
    varies = var_x > 1e-12 * np.maximum(1.0, moments["xx"] / n)
    coefs = np.where(varies, cov / np.where(varies, var_x, 1.0), 0.0)
    intercepts = mean_y - coefs * mean_x
    variances = np.maximum(var_y - coefs * cov, var_floor)
    return intercepts, coefs, variances
