"""dtwin._lfilter: scipy.signal's lfilter and lfiltic, bit for bit, without importing it."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter as scipy_lfilter
from scipy.signal import lfiltic as scipy_lfiltic

from dtwin import _lfilter
from tests.conftest import REPO


@pytest.fixture
def python_path(monkeypatch):
    """Take the Python recursion although this test process has scipy.signal loaded."""
    real = dict(sys.modules)
    monkeypatch.setattr(sys, "modules", {k: v for k, v in real.items() if k != "scipy.signal"})


def same_bits(ours, theirs) -> bool:
    """Equal shapes and bytes (signed zeros and every last bit)."""
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    return (
        ours.shape == theirs.shape
        and ours.dtype == theirs.dtype
        and (ours.tobytes() == theirs.tobytes())
    )


def coefficients(rng, n_b: int, n_a: int, a0: float) -> tuple[np.ndarray, np.ndarray]:
    """Random numerator/denominator (stable enough that 400 samples stay finite)."""
    b = rng.normal(size=n_b)
    a = np.concatenate([[a0], 0.4 * a0 * rng.uniform(-1, 1, size=n_a - 1) / (n_a - 1)])
    return b, a


@pytest.mark.parametrize("n_b, n_a", [(1, 2), (2, 2), (3, 2), (1, 3), (3, 3), (5, 4)])
@pytest.mark.parametrize("a0", [1.0, 0.7])
def test_lfilter_is_scipys_to_the_bit(python_path, n_b, n_a, a0):
    rng = np.random.default_rng(100 * n_b + n_a)
    b, a = coefficients(rng, n_b, n_a, a0)
    n_delays = max(n_a, n_b) - 1
    x = rng.normal(size=400)
    x[5] = 0.0
    assert same_bits(_lfilter.lfilter(b, a, x), scipy_lfilter(b, a, x))
    zi = rng.normal(size=n_delays)
    for ours, theirs in zip(
        _lfilter.lfilter(list(b), list(a), x, zi=zi), scipy_lfilter(b, a, x, zi=zi), strict=True
    ):
        assert same_bits(ours, theirs)
    grid = rng.normal(size=(300, 3))
    for axis, zi in ((0, rng.normal(size=(n_delays, 3))), (-1, rng.normal(size=(300, n_delays)))):
        ours = _lfilter.lfilter(b, a, grid, axis=axis, zi=zi)
        theirs = scipy_lfilter(b, a, grid, axis=axis, zi=zi)
        assert all(same_bits(o, t) for o, t in zip(ours, theirs, strict=True))
    assert same_bits(_lfilter.lfilter(b, a, grid, axis=0), scipy_lfilter(b, a, grid, axis=0))


def test_lfilter_broadcasts_singleton_delays_as_scipy(python_path):
    """bias_correction's moving average: zi of shape (1, n_channels) on a (T, n_channels) signal."""
    x = np.random.default_rng(3).normal(size=(50, 4))
    ours = _lfilter.lfilter([0.3], [1.0, -0.7], x, axis=0, zi=0.7 * x[:1])
    theirs = scipy_lfilter([0.3], [1.0, -0.7], x, axis=0, zi=0.7 * x[:1])
    assert all(same_bits(o, t) for o, t in zip(ours, theirs, strict=True))
    wide = _lfilter.lfilter([0.3], [1.0, -0.7], x, axis=0, zi=np.ones((1, 1)))
    theirs = scipy_lfilter([0.3], [1.0, -0.7], x, axis=0, zi=np.ones((1, 1)))
    assert all(same_bits(o, t) for o, t in zip(wide, theirs, strict=True))


@pytest.mark.parametrize(
    "b, a, y, x",
    [
        ([0.0, 0.4, 0.2], [1.0, -0.5, 0.1], [1.5, -0.3], [0.2, 0.9]),  # the ARX rollout's case
        ([0.0, 0.4], [1.0, -0.5, 0.1], [1.5], None),  # short y, no x
        ([0.3, 0.4, 0.2, 0.1], [2.0, -0.5], [0.7], [0.1]),  # a[0] != 1, short x
    ],
)
def test_lfiltic_is_scipys_to_the_bit(python_path, b, a, y, x):
    y = np.array(y)[::-1]  # a reversed view, as dtwin.arx passes the past
    x = None if x is None else np.array(x)[::-1]
    assert same_bits(_lfilter.lfiltic(b, a, y, x), scipy_lfiltic(b, a, y, x))


def test_what_python_does_not_take_goes_to_scipy(python_path):
    """A one-coefficient denominator, float32 and long signals: scipy's own result."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=20)
    assert same_bits(_lfilter.lfilter([0.5, 0.5], [2.0], x), scipy_lfilter([0.5, 0.5], [2.0], x))
    x32 = x.astype(np.float32)
    assert same_bits(
        _lfilter.lfilter([0.5], [1.0, -0.5], x32), scipy_lfilter([0.5], [1, -0.5], x32)
    )
    long = rng.normal(size=_lfilter.MAX_PYTHON_SAMPLES + 1)
    assert _lfilter._use_python([1.0], [1.0, -0.5], long, -1, None) is None
    with pytest.raises(ValueError):
        _lfilter.lfilter([1.0], [1.0, -0.5], x, zi=np.zeros(3))


def test_the_short_jobs_filters_import_no_scipy_signal():
    """Simulating, rolling out the ARX chain and the correction's moving average stay light."""
    code = (
        "import sys, yaml\n"
        "from dtwin.bias_correction import exponential_moving_average\n"
        "from dtwin.stages.twin import fit_twin_surrogates, roll_out_twin, simulate_asset\n"
        "config = yaml.safe_load(open('config/config.yaml'))\n"
        "physics = simulate_asset(config['simulation'], config['command'], config['twin'])\n"
        "theta = fit_twin_surrogates(physics, config['arx'])\n"
        "surrogate, residuals = roll_out_twin(physics, theta, config['twin'], 'physics')\n"
        "exponential_moving_average(residuals[['e1', 'e2a']].to_numpy(), 0.3)\n"
        "print('scipy.signal' in sys.modules)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True
    )
    assert done.stdout.split() == ["False"]
