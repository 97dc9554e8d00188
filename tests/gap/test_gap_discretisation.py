"""The diagnoser's exact plant (dtwin.twin.exact) against the continuous solution.

docs/gap.md §Modules: zero- and first-order hold discretisations must match the continuous
mass-spring-damper at 3, 10 and 150 samples per period, damping ratios 0.005–1, and k = 0; the
band-limited hold must match its response to a sinusoid below the Nyquist frequency.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from dtwin.twin.exact import (
    EXACT_HOLDS,
    exact_plant_response,
    free_response_basis,
    hold_matrices,
)
from dtwin.twin.paper_modules import BANDLIMITED, FOH, ZOH

#: The holds with a piecewise-polynomial input between samples (a continuous reference exists
#: sample by sample).
PIECEWISE_HOLDS = (ZOH, FOH)


def _continuous(u, m, c, k, dt, hold, x0=0.3, v0=-0.2):
    """Integrate m·ẍ = u(t) − c·ẋ − k·x sample by sample at tolerance 1e-13."""

    def between(j):
        if hold == ZOH:
            return lambda s: u[j]
        return lambda s: u[j] + (u[j + 1] - u[j]) * s / dt

    state = np.array([x0, v0])
    xs = [x0]
    for j in range(len(u) - 1):
        force = between(j)
        sol = solve_ivp(
            lambda s, y, f=force: [y[1], (f(s) - c * y[1] - k * y[0]) / m],
            (0.0, dt),
            state,
            rtol=1e-13,
            atol=1e-15,
            method="DOP853",
        )
        state = sol.y[:, -1]
        xs.append(state[0])
    return np.array(xs)


@pytest.mark.parametrize("samples_per_period", [3, 10, 150])
@pytest.mark.parametrize("hold", PIECEWISE_HOLDS)
@pytest.mark.parametrize("zeta", [0.005, 1.0])
def test_exact_discretisation_matches_the_continuous_plant(samples_per_period, hold, zeta):
    m, period = 2.0, 0.5
    omega = 2 * np.pi / period
    k, c = m * omega**2, 2 * zeta * m * omega
    dt = period / samples_per_period
    rng = np.random.default_rng(samples_per_period)
    u = rng.normal(size=60) * k
    x = exact_plant_response(
        u,
        m,
        c,
        k,
        dt,
        windows=[(0, 60)],
        x_start=np.full(60, 0.3),
        v_start=np.full(60, -0.2),
        hold=hold,
    )
    reference = _continuous(u, m, c, k, dt, hold)
    assert np.max(np.abs(x - reference)) < 1e-9 * np.max(np.abs(reference))


@pytest.mark.parametrize("hold", PIECEWISE_HOLDS)
def test_integrating_plant_and_windows_restart_from_the_given_state(hold):
    m, c, k, dt = 95.0, 200.0, 0.0, 1e-3
    rng = np.random.default_rng(1)
    u = rng.normal(size=400) * 50
    x_start = rng.normal(size=400)
    v_start = rng.normal(size=400)
    windows = [(0, 150), (150, 300), (300, 400)]
    x = exact_plant_response(
        u, m, c, k, dt, windows=windows, x_start=x_start, v_start=v_start, hold=hold
    )
    for start, stop in windows:
        reference = _continuous(u[start:stop], m, c, k, dt, hold, x_start[start], v_start[start])
        assert np.max(np.abs(x[start:stop] - reference)) < 1e-9 * np.max(np.abs(reference))


@pytest.mark.parametrize("hold", EXACT_HOLDS)
@pytest.mark.parametrize(
    ("dt", "substeps", "seed", "rtol", "atol"),
    [(0.05, 1, 2, 1e-10, 1e-12), (0.3, 8, 3, 1e-9, 1e-9)],
    ids=["one_step", "substepped"],
)
def test_force_loop_equals_the_linear_filter_for_a_zero_force(hold, dt, substeps, seed, rtol, atol):
    """With a zero force the loop (one step or sub-steps per sample) is the hold's linear filter."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=300)
    start = dict(x_start=rng.normal(size=300), v_start=rng.normal(size=300))
    windows = [(0, 100), (100, 300)]
    linear = exact_plant_response(u, 1.0, 0.3, 40.0, dt, windows=windows, hold=hold, **start)
    looped = exact_plant_response(
        u,
        1.0,
        0.3,
        40.0,
        dt,
        windows=windows,
        hold=hold,
        force=lambda x, v: 0.0 * v,
        substeps=substeps,
        **start,
    )
    np.testing.assert_allclose(looped, linear, rtol=rtol, atol=atol)


@pytest.mark.parametrize("k3", [30.0, -3e4])  # a stiffening spring; one that diverges
def test_one_window_float_loop_equals_the_lockstep_array_loop_bit_for_bit(k3):
    """Windows run one by one (Python floats) and in lockstep (numpy arrays): the same bits."""
    from dtwin.twin.exact import SCALAR_WINDOWS

    rng = np.random.default_rng(5)
    n_windows, length = SCALAR_WINDOWS + 2, 40
    n = n_windows * length
    u = np.sign(np.sin(np.arange(n) * 0.05)) + 0.1 * rng.normal(size=n)
    start = dict(x_start=rng.normal(size=n) * 0.1, v_start=rng.normal(size=n))

    def cubic(x, v):
        offset = x - 0.02
        return k3 * 1e3 * offset * offset * offset

    common = dict(hold=FOH, force=cubic, **start)
    windows = [(a, a + length) for a in range(0, n, length)]
    together = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=windows, **common)
    for a, b in windows:
        alone = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=[(a, b)], **common)
        assert together[a:b].tobytes() == alone[a:b].tobytes()
    assert np.isinf(together).any() == (k3 < 0)


def _law_force(name: str, params: tuple[float, ...]):
    """A force of a known law: the Python callable, and the same with its ``law`` attached."""
    import math

    from dtwin.twin._force_kernels import ForceLaw

    laws = {
        "tanh_friction": lambda x, v: params[0] * np.tanh(v / params[1]),
        "cubic_spring": lambda x, v: (
            params[0] * (x - params[1]) * (x - params[1]) * (x - params[1])
        ),
        "quadratic_damping": lambda x, v: params[0] * v * np.abs(v),
        "stribeck_friction": lambda x, v: (
            (params[0] + params[1] * np.exp(-(v / params[2]) * (v / params[2])))
            * np.tanh(v / params[3])
        ),
    }
    scalars = {
        "tanh_friction": lambda x, v: params[0] * math.tanh(v / params[1]),
        "cubic_spring": lambda x, v: (
            params[0] * (x - params[1]) * (x - params[1]) * (x - params[1])
        ),
        "quadratic_damping": lambda x, v: params[0] * v * abs(v),
        "stribeck_friction": lambda x, v: (
            (params[0] + params[1] * math.exp(-(v / params[2]) * (v / params[2])))
            * math.tanh(v / params[3])
        ),
    }
    plain = laws[name]
    plain.scalar = scalars[name]

    def compiled(x, v):
        return plain(x, v)

    compiled.law = ForceLaw(name, params)
    return plain, compiled


@pytest.mark.parametrize("windows_count", [3, 12])  # one by one, and in lockstep
@pytest.mark.parametrize(
    ("name", "params"),
    [
        ("tanh_friction", (0.4, 0.01)),
        ("cubic_spring", (3e4, 0.02)),
        ("cubic_spring", (-3e6, 0.0)),  # diverges
        ("quadratic_damping", (0.7,)),
        ("stribeck_friction", (0.3, 0.2, 0.05, 0.01)),
    ],
)
def test_compiled_force_loop_equals_the_python_loop(name, params, windows_count):
    """The numba loop of a known law gives the Python loop's positions."""
    rng = np.random.default_rng(8)
    length = 300
    n = windows_count * length
    u = np.sign(np.sin(np.arange(n) * 0.05)) + 0.1 * rng.normal(size=n)
    start = dict(x_start=rng.normal(size=n) * 0.1, v_start=rng.normal(size=n))
    windows = [(a, a + length) for a in range(0, n, length)]
    plain, compiled = _law_force(name, params)
    for hold in (ZOH, FOH, BANDLIMITED):
        kwargs = dict(windows=windows, hold=hold, **start)
        expected = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, force=plain, **kwargs)
        got = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, force=compiled, **kwargs)
        np.testing.assert_array_equal(np.isinf(got), np.isinf(expected))
        finite = np.isfinite(expected)
        np.testing.assert_allclose(got[finite], expected[finite], rtol=1e-12, atol=1e-14)
    assert np.isinf(got).any() == (params[0] < -1e5)


def test_first_order_hold_uses_the_same_sample_input():
    """Only the first-order hold lets u[k] act on x[k] (a band-limited input's same-sample term)."""
    u = np.zeros(5)
    u[2] = 1.0
    kwargs = dict(windows=[(0, 5)], x_start=np.zeros(5), v_start=np.zeros(5))
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=FOH, **kwargs)[2] > 0
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=ZOH, **kwargs)[2] == 0
    assert exact_plant_response(u, 1.0, 1.0, 1.0, 0.1, hold=BANDLIMITED, **kwargs)[1] != 0


def test_free_response_basis_is_the_first_row_of_the_matrix_powers():
    step = hold_matrices(0.3, 40.0, 0.05, FOH)
    power, rows = np.eye(2), []
    for _ in range(7):
        rows.append(power[0])
        power = step.a @ power
    np.testing.assert_allclose(free_response_basis(step, 7), np.array(rows), atol=1e-14)


@pytest.mark.parametrize("samples_per_period", [3, 10, 150])
@pytest.mark.parametrize("input_per_nyquist", [0.1, 0.6])
def test_bandlimited_hold_matches_the_steady_response_to_a_sinusoid(
    samples_per_period, input_per_nyquist
):
    """A sinusoid below the Nyquist frequency: the response is ``Re(H(iω)·e^{iωt})`` exactly.

    Measured (ζ = 0.05): the band-limited hold errs by ≤ 7e-4 of the amplitude up to 0.6 of the
    Nyquist frequency; the first-order hold by 1.2–46 %.
    """
    m, period, zeta = 2.0, 0.5, 0.05
    omega_n = 2 * np.pi / period
    k, c = m * omega_n**2, 2 * zeta * m * omega_n
    dt = period / samples_per_period
    omega = input_per_nyquist * np.pi / dt
    t = np.arange(600) * dt
    gain = 1.0 / (k - m * omega**2 + 1j * c * omega)
    exact = gain * np.exp(1j * omega * t)
    start = dict(x_start=exact.real, v_start=(1j * omega * exact).real)
    window = slice(100, 500)  # the input is known 8 samples beyond the window on both sides

    def error(hold):
        x = exact_plant_response(
            np.cos(omega * t), m, c, k, dt, windows=[(100, 500)], hold=hold, **start
        )
        return np.max(np.abs(x[window] - exact.real[window])) / abs(gain)

    assert error(BANDLIMITED) < 1e-3
    assert error(BANDLIMITED) < error(FOH) / 10


@pytest.mark.parametrize(("samples_per_period", "seed"), [(5, 3), (500, 9)])
def test_calibration_recovers_a_rigs_parameters_and_offset(samples_per_period, seed):
    """A linear rig (open loop, volts-like units, offsets) from scratch: m, c, k, u_offset to 2 %.

    Measured: within 0.4 % at 5 samples per period (band-limited hold chosen) and 500 (first-order).
    """
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping
    from dtwin.gapbench.rigs import generate_rig_case

    case = generate_rig_case("none", seed, samples_per_period=samples_per_period, n_samples=4000)
    recording = recording_from_frame(case.recording)
    twin = twin_from_mapping(case.twin, dt=recording.dt)
    used = diagnose(recording, twin, calibrate=True).modules["M1"].lin_used
    for name in ("m", "c", "k"):
        assert used[name] == pytest.approx(case.key["plant"][name], rel=0.02), name
    assert used["u_offset"] == pytest.approx(case.key["u_offset"], rel=0.02)


def _ramped_duffing(n: int, seed: int) -> pd.DataFrame:
    """A stiffening-spring rig at 10 samples per period whose input grows over its first 30 %."""
    rng = np.random.default_rng(seed)
    sub, dt = 8, 1.0 / 610.0
    omega = 2 * np.pi * 61.0
    spectrum = np.zeros(n * sub + 1, dtype=complex)  # band-limited noise on the fine grid
    freqs = np.fft.rfftfreq(2 * n * sub, dt / (2 * sub))
    band = (freqs > 0.5) & (freqs < 200.0)
    spectrum[band] = np.exp(2j * np.pi * rng.uniform(size=band.sum()))
    fine = np.fft.irfft(spectrum, 2 * n * sub)
    envelope = np.minimum(np.arange(len(fine)) / (0.3 * len(fine)), 1.0)
    force = [*(fine / fine.std() * envelope * omega**2 * 0.08).tolist(), 0.0]
    c, k, k3, h = 0.2 * omega, omega**2, 1.5 * omega**2, dt / sub
    x = v = 0.0
    positions = []
    for i in range(n * sub):
        if i % sub == 0:
            positions.append(x)
        u0, um, u1 = force[2 * i], force[2 * i + 1], force[2 * i + 2]
        k1x, k1v = v, u0 - c * v - k * x - k3 * x**3
        x2, v2 = x + h / 2 * k1x, v + h / 2 * k1v
        k2v = um - c * v2 - k * x2 - k3 * x2**3
        x3, v3 = x + h / 2 * v2, v + h / 2 * k2v
        k3v = um - c * v3 - k * x3 - k3 * x3**3
        x4, v4 = x + h * v3, v + h * k3v
        k4v = u1 - c * v4 - k * x4 - k3 * x4**3
        x += h / 6 * (k1x + 2 * v2 + 2 * v3 + v4)
        v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    x_rec = np.asarray(positions) + 0.002 * rng.normal(size=n)
    u_rec = np.asarray(force[: 2 * n * sub : 2 * sub]) / omega**2
    return pd.DataFrame({"t": np.arange(n) * dt, "u_act": u_rec, "x": x_rec})


def test_calibrated_twin_matches_an_oe_fit_on_a_stiffening_rig_with_a_ramped_input():
    """On a rig like a measured resonant circuit (10 samples per period, input
    ramped up over the first 30 %): the calibrated linear twin's scoring-part gap is within 5 %
    of a plain OE(3, 2) fit's on the same split and windows (measured 0.1017 vs 0.1020), and
    the stiffening spring is named.
    """
    from dtwin.gap import diagnose, recording_from_frame, twin_from_mapping

    recording = recording_from_frame(_ramped_duffing(24_000, seed=4))
    result = diagnose(recording, twin_from_mapping({"dt": recording.dt}, dt=recording.dt))
    plant = result.modules["M1"]
    assert plant.reference_gap is not None
    assert plant.scoring_gap_refit <= 1.05 * plant.reference_gap
    assert result.effect == "cubic_stiffness"


def test_a_long_window_fit_spreads_over_the_whole_training_part():
    """With windows longer than the fit's budget allows, the fit sees the whole training part.

    Fitting only the first window (the old behaviour) saw only the ramp's start of a long
    recording: held-out gap 0.20 against an OE fit's 0.12 on a 131,072-sample rig.
    """
    from dtwin.gap.fit import MAX_FIT_SAMPLES, training_view
    from dtwin.gap.models import ModuleData, warmup_samples

    n_train, n = 65_536, 131_072
    signal = np.sin(np.arange(n) * 0.6)
    data = ModuleData(
        name="M1",
        inputs={"u_act": signal},
        output=signal,
        dt=1.0 / 610.0,
        t=np.arange(n) / 610.0,
        discretisation=BANDLIMITED,
        horizon=16_384,
    )
    fit_data, segments = training_view(data, n_train)
    assert segments[0][0] < 0.1 * n_train and segments[-1][1] > 0.9 * n_train
    assert sum(b - a for a, b in segments) <= MAX_FIT_SAMPLES + fit_data.horizon // 2  # a tail
    assert all(b - a > 2 * warmup_samples(fit_data.horizon) for a, b in segments)


def test_substeps_bring_a_coarsely_sampled_friction_to_the_continuous_plant():
    """A friction's smoothed sign at 6 samples per period: 16 sub-steps, not one step per sample.

    The reference integrates ``m·ẍ = u − c·ẋ − k·x − Fc·tanh(ẋ/δ)`` with the input held over
    each sample (Radau, tolerance 1e-8: within 3e-10 of the reference at 1e-10, against rms
    errors of 0.098 and 0.0037); ``δ`` is far below the velocity change of a sample, so the
    force changes sign inside the sample that holds a reversal.
    """
    from dtwin.twin.exact import force_substeps

    m, period, zeta = 1.0, 1.0, 0.1
    omega = 2 * np.pi / period
    k, c, dt = m * omega**2, 2 * zeta * m * omega, period / 6
    rng = np.random.default_rng(4)
    n = 40
    u = rng.normal(size=n) * k * 0.5
    friction, smoothing = 0.3 * k * 0.5, 0.01
    law = lambda x, v: friction * np.tanh(v / smoothing)  # noqa: E731
    state, reference = np.array([0.0, 0.0]), [0.0]
    for j in range(n - 1):
        sol = solve_ivp(
            lambda s, y, f=u[j]: [y[1], (f - c * y[1] - k * y[0] - law(0.0, y[1])) / m],
            (0.0, dt),
            state,
            method="Radau",
            rtol=1e-8,
            atol=1e-10,
        )
        state = sol.y[:, -1]
        reference.append(state[0])
    reference = np.array(reference)
    substeps = force_substeps(friction / smoothing, m, dt)
    assert substeps == 16
    common = dict(windows=[(0, n)], x_start=np.zeros(n), v_start=np.zeros(n), hold=ZOH, force=law)
    errors = [
        np.sqrt(
            np.mean((exact_plant_response(u, m, c, k, dt, **common, substeps=s) - reference) ** 2)
        )
        for s in (1, substeps)
    ]
    assert errors[1] < 0.2 * errors[0]


@pytest.mark.parametrize(
    ("name", "params"),
    [
        (None, ()),
        ("tanh_friction", (0.4, 0.01)),
        ("cubic_spring", (3e4, 0.02)),
        ("cubic_spring", (-3e6, 0.0)),  # diverges: the guard fills the rest
        ("quadratic_damping", (0.7,)),
        ("stribeck_friction", (0.3, 0.2, 0.05, 0.01)),
    ],
)
def test_compiled_euler_loop_gives_the_python_loops_bits(name, params):
    """The diagnoser's Euler twin stepped by numba: plant_response's positions, bit for bit."""
    from dtwin.twin._force_kernels import ForceLaw, euler_response
    from dtwin.twin.paper_modules import plant_response

    rng = np.random.default_rng(5)
    u = np.sign(np.sin(np.arange(600) * 0.05)) + 0.1 * rng.normal(size=600)
    force, law = None, None
    if name is not None:
        force, law = _law_force(name, params)[0].scalar, ForceLaw(name, params)
    x0, v0 = np.float64(0.01), np.float64(-0.2)
    for limit in (1e3, 0.5):
        expected = plant_response(
            u.tolist(), 1.3, 0.3, 40.0, 0.01, x0=x0, v0=v0, force=force, limit=limit
        )
        xs, vs = euler_response(u, 1.3, 0.3, 40.0, 0.01, x0, v0, law, limit)
        np.testing.assert_array_equal(xs, expected.x)
        np.testing.assert_array_equal(vs, expected.v)


@pytest.mark.parametrize(
    ("name", "params"),
    [("tanh_friction", (0.4, 0.001)), ("cubic_spring", (-3e6, 0.0)), ("quadratic_damping", (0.7,))],
)
@pytest.mark.parametrize("hold", [ZOH, FOH, BANDLIMITED])
def test_substepped_compiled_loop_gives_the_lockstep_loops_bits(name, params, hold):
    """Sub-stepped windows of a known law: the in-place compiled loop (windows in order) gives
    the bits of the loop over gathered fine windows (the same windows, listed out of order)."""
    rng = np.random.default_rng(9)
    n = 900
    u = np.sign(np.sin(np.arange(n) * 0.05)) + 0.1 * rng.normal(size=n)
    start = dict(x_start=rng.normal(size=n) * 0.1, v_start=rng.normal(size=n))
    windows = [(0, 200), (200, 400), (400, 600), (650, 900)]  # a gap, a longer last one
    _, compiled = _law_force(name, params)
    compiled.slope = 1e9
    kwargs = dict(hold=hold, force=compiled, substeps=8, **start)
    in_order = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=windows, **kwargs)
    reordered = exact_plant_response(u, 1.3, 0.3, 40.0, 0.01, windows=windows[::-1], **kwargs)
    np.testing.assert_array_equal(in_order, reordered)
    assert np.isinf(in_order).any() == (params[0] < -1e5)
