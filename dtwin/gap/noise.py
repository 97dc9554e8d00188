"""What a module's noise explains: noise floors of the local gap (docs/gap.md §Noise floors).

The *noise floor* of a module is the RMS simulation error its twin would show if the twin were
exact and only the noise of that module acted (output units):

- M0: actuator process noise ``w`` through the lag: ``σ_w/√(1 − a²)``;
- M1: acceleration noise ``ξ`` through the Euler plant: ``σ_ξ·√P_xx`` with ``P`` the
  stationary state covariance per unit noise (a discrete Lyapunov equation);
- M2a/M2b: the measurement noise ``σ_s`` itself (its marginal standard deviation);
- M3, M4: no noise in the twin, floor 0.

From the twin (:func:`twin_noise_floor`) when its file gives noise levels; from the data
otherwise (:func:`data_noise_floor`). The data estimate reads the noise from the
*high-frequency* part of a residual, where the structured effects (smooth functions of the
input, or rare jumps) are absent: first differences of the one-step prediction error (M0, M1) or
of the simulation error (sensors, M3, M4), with a robust scale (MAD), so the few jumps an effect
causes at a command step do not count. For M1 it separates process noise (white in the one-step
error) from measurement noise on the position (coloured by the plant polynomial) by their
autocovariances, lags 0–3 (method of moments).

For the sensors, M3 and M4 the noise is taken as AR(1), fitted to the residual's spectrum
above a tenth of the sampling rate (:func:`_ar1_floor`), which removes the plain estimate's
low bias for coloured noise (``√(1 − φ)``, 0.63 at ``φ = 0.6``).

The exact plant (simulated over windows) reads its measurement noise from the linear twin's
simulation error: as AR(1) noise over the whole band when that model explains the error
(:func:`residual_noise_floor`), else from its spectrum above the plant
(:func:`spectral_noise_floor`).

The data estimate is reported beside the twin's but used only when the twin gives no noise: it
cannot tell noise from high-frequency *effects* (a quantizer, an interference), whereas the
twin's level is trusted to the ``noise_tolerance`` that the threshold includes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_lyapunov
from scipy.optimize import nnls
from scipy.stats import chi2

from dtwin._ljung_box import ljung_box_statistic
from dtwin.params import NoiseParams
from dtwin.twin.paper_modules import CONTRACTS, lag_coefficient, plant_matrices
from dtwin.twin.wiring import ACTUATOR, PLANT, SENSOR, role_of

__all__ = [
    "NoiseFloor",
    "robust_std",
    "plant_noise_gain",
    "twin_noise_floor",
    "data_noise_floor",
    "spectral_noise_floor",
    "residual_noise_floor",
    "process_noise_floor",
    "reconcile_noise_floor",
    "effective_samples",
    "gap_threshold",
    "excess_gap",
    "shrink_pct",
    "WHITENING_MAX_ORDER",
    "whitening_filter",
    "whitened",
]

_MAD_TO_STD = 1.482602218505602


@dataclass(frozen=True)
class NoiseFloor:
    """A module's noise floor.

    Attributes
    ----------
    rms : float
        RMS simulation error explained by noise, output units.
    source : str
        ``"twin"`` or ``"data"``.
    acf : numpy.ndarray, shape (n_lags,)
        Autocorrelation of that noise in the simulation error, lags 0, 1, … (for the effective
        sample size of the gap).
    measurement : float, default 0
        The part of ``rms`` that is white measurement noise on the output (M1's position, read
        from the data; no twin file states it), output units.
    identified : bool, default True
        False for a data floor whose process noise could not be told from the model's own
        error (:func:`_plant_data_floor`); it then never overrules a twin's floor.
    process : float, default 0
        The part of ``rms`` that is process noise read from the data by
        :func:`process_noise_floor` (a twin file without noise levels), output units.
    """

    rms: float
    source: str
    acf: np.ndarray
    measurement: float = 0.0
    identified: bool = True
    process: float = 0.0


def robust_std(values: np.ndarray) -> float:
    """Return ``1.4826·median(|v − median(v)|)``, a standard deviation robust to outliers."""
    values = np.asarray(values, dtype=float)
    return float(_MAD_TO_STD * np.median(np.abs(values - np.median(values))))


def plant_noise_gain(m: float, c: float, k: float, dt: float, n_lags: int = 400) -> tuple:
    """Return ``(√P_xx, acf)``: position std per unit acceleration noise and its autocorrelation.

    ``P = A·P·Aᵀ + b·bᵀ`` for the Euler plant's state ``(x, v)``
    (:func:`dtwin.twin.paper_modules.plant_matrices`, ``b`` its acceleration input);
    ``acf[l] = (A^l P)_xx / P_xx``.
    An unstable or undamped plant has no stationary variance; then the variance after
    ``n_lags`` steps is used.
    """
    a, _, b = plant_matrices(m, c, k, dt)
    if np.max(np.abs(np.linalg.eigvals(a))) < 1.0 - 1e-9:
        cov = solve_discrete_lyapunov(a, b @ b.T)
    else:
        cov = np.zeros((2, 2))
        for _ in range(n_lags):
            cov = a @ cov @ a.T + b @ b.T
    acf = np.empty(n_lags)
    row = cov.copy()
    for lag in range(n_lags):
        acf[lag] = row[0, 0]
        row = a @ row
    variance = max(cov[0, 0], 1e-300)
    return math.sqrt(variance), acf / variance


def _white_acf() -> np.ndarray:
    return np.array([1.0])


def twin_noise_floor(module: str, noise: NoiseParams, lin: dict, dt: float) -> NoiseFloor:
    """Return the floor implied by the twin's noise levels (see the module docstring)."""
    role = role_of(module)
    if role == ACTUATOR:
        a = lag_coefficient(lin["tau"], dt)
        n_lags = max(2, min(400, int(10 / max(1e-9, 1 - a))))
        return NoiseFloor(noise.actuator / math.sqrt(1 - a * a), "twin", a ** np.arange(n_lags))
    if role == PLANT:
        gain, acf = plant_noise_gain(lin["m"], lin["c"], lin["k"], dt)
        return NoiseFloor(noise.plant * gain, "twin", acf)
    if role == SENSOR:  # white measurement noise, the sensor's own channel
        return NoiseFloor(getattr(noise, CONTRACTS[module].noise), "twin", _white_acf())
    return NoiseFloor(0.0, "twin", _white_acf())


def _winsorize(values: np.ndarray, width: float = 5.0) -> np.ndarray:
    scale = robust_std(values)
    centre = np.median(values)
    return np.clip(values, centre - width * scale, centre + width * scale)


def _autocov(values: np.ndarray, n_lags: int) -> np.ndarray:
    values = values - values.mean()
    n = len(values)
    return np.array([values[: n - lag] @ values[lag:] / n for lag in range(n_lags)])


def _filter_autocov(coeffs: np.ndarray, n_lags: int) -> np.ndarray:
    full = np.correlate(coeffs, coeffs, mode="full")[len(coeffs) - 1 :]
    out = np.zeros(n_lags)
    out[: min(n_lags, len(full))] = full[:n_lags]
    return out


def data_noise_floor(
    module: str,
    inputs: dict[str, np.ndarray],
    output: np.ndarray,
    simulated: np.ndarray,
    lin: dict,
    dt: float,
) -> NoiseFloor:
    """Return the floor estimated from the high-frequency part of the residuals.

    Parameters
    ----------
    module : str
        ``"M0"`` … ``"M4"``.
    inputs : dict of str to array
        The module's recorded inputs, each shape ``(n,)`` (M1 reads ``u_act``).
    output : array, shape (n,)
        The recorded output.
    simulated : array, shape (n,)
        The twin's simulation of the output (sensors, M3, M4 use ``output − simulated``).
    lin : dict
        The module's linear parameters (M0, M1 form their one-step predictor from them).
    dt : float
        Sample period, s.
    """
    role = role_of(module)
    if role == ACTUATOR:
        a = lag_coefficient(lin["tau"], dt)
        u = inputs["u_cmd"]
        step_error = output[1:] - a * output[:-1] - (1 - a) * u[:-1]
        sigma = robust_std(np.diff(step_error)) / math.sqrt(2.0)
        n_lags = max(2, min(400, int(10 / max(1e-9, 1 - a))))
        return NoiseFloor(sigma / math.sqrt(1 - a * a), "data", a ** np.arange(n_lags))
    if role == PLANT:
        return _plant_data_floor(inputs["u_act"], output, lin, dt)
    return _ar1_floor(output - simulated, dt)


#: Largest AR(1) coefficient :func:`_ar1_floor` reads from the data.
_MAX_PHI = 0.95
#: Lowest frequency (over the sampling rate) of the band the AR(1) spectrum is fitted on.
_AR1_BAND_LOW = 0.1
_AR1_GROUPS = 6


def _ar1_spectrum_fit(residual: np.ndarray, dt: float) -> tuple[float, float]:
    """Return ``(σ, φ)`` of AR(1) noise fitted to a residual's spectrum above 0.1·fs.

    The one-sided PSD of AR(1) noise is ``2q/(fs·(1 − 2φ·cos ω + φ²))`` with ``q = σ²(1 − φ²)``,
    so ``1/PSD`` is linear in ``cos ω``; the line is fitted to the medians of six groups of
    Welch bins between 0.1·fs and the Nyquist frequency. The medians ignore the few lines a
    periodic effect leaves there; smooth effects sit below the band.
    """
    fs = 1.0 / dt
    n = len(residual)
    segment = int(min(256, max(32, 2 ** math.floor(math.log2(max(n // 8, 32))))))
    from scipy.signal import welch

    freqs, density = welch(residual - residual.mean(), fs=fs, nperseg=min(segment, n))
    band = (freqs >= _AR1_BAND_LOW * fs) & (freqs <= 0.5 * fs)
    groups = np.array_split(np.flatnonzero(band), _AR1_GROUPS)
    cosines = np.array([np.median(np.cos(2 * np.pi * freqs[g] / fs)) for g in groups])
    levels = np.array([np.median(density[g]) for g in groups])
    if np.any(levels <= 0):
        return 0.0, 0.0
    slope, intercept = np.polyfit(cosines, 1.0 / levels, 1)
    ratio = min(max(-slope / intercept, 0.0), 0.99) if intercept > 0 else 0.0
    phi = min((1.0 - math.sqrt(1.0 - ratio * ratio)) / ratio if ratio > 0 else 0.0, _MAX_PHI)
    innovation = (1.0 + phi * phi) / intercept * fs / 2.0 if intercept > 0 else 0.0
    return math.sqrt(max(innovation / (1.0 - phi * phi), 0.0)), phi


def _ar1_floor(residual: np.ndarray, dt: float) -> NoiseFloor:
    """Return the floor of AR(1) noise in a residual (sensors, M3, M4; output units).

    ``φ`` and a level ``σ_spec`` come from the spectrum above 0.1·fs
    (:func:`_ar1_spectrum_fit`); a second level from the first differences, whose variance is
    ``2σ²(1 − φ)``: ``σ_diff = robust_std(Δr)/√(2(1 − φ))``. The floor is the lower of the two:
    the spectrum is blind to a quantizer's lattice (its error is white), the robust spread of
    the differences is not (most differences of a quantized reading are 0), while a periodic
    effect inflates the differences but not the spectrum's median. ``φ = 0`` gives the plain
    ``robust_std(Δr)/√2``, which for coloured noise is biased low by ``√(1 − φ)``. The
    autocorrelation ``φ^l`` sets the effective sample size of the gap.
    """
    residual = np.asarray(residual, dtype=float)
    if len(residual) < 64 or robust_std(np.diff(residual)) == 0.0:
        return NoiseFloor(robust_std(np.diff(residual)) / math.sqrt(2.0), "data", _white_acf())
    sigma_spec, phi = _ar1_spectrum_fit(residual, dt)
    sigma_diff = robust_std(np.diff(residual)) / math.sqrt(2.0 * (1.0 - phi))
    n_lags = 1 if phi <= 0 else max(1, int(math.log(1e-3) / math.log(phi)) + 1)
    return NoiseFloor(min(sigma_spec, sigma_diff), "data", phi ** np.arange(n_lags))


#: Poles of the AR(1) measurement noise :func:`spectral_noise_floor` tries (0: white).
NOISE_POLES = np.linspace(0.0, 0.98, 50)
#: Fewest Welch frequencies in the band for a noise pole to be fitted (else white noise).
MIN_POLE_FREQUENCIES = 8
#: Highest start of the band (over the Nyquist frequency) at which a noise pole is fitted: a
#: band from 0.6 of it read white noise of a rig at 4 samples per period as a pole of 0.7 and
#: doubled its floor.
MAX_POLE_BAND_START = 0.3


def spectral_noise_floor(residual: np.ndarray, dt: float, bandwidth_hz: float) -> NoiseFloor:
    """Return the noise floor read from a residual's spectrum above the plant's bandwidth.

    Parameters
    ----------
    residual : array, shape (n,)
        The linear twin's simulation error (output units).
    dt : float
        Sample period, s.
    bandwidth_hz : float
        The plant's bandwidth (its natural frequency or velocity corner, the larger), Hz.

    Returns
    -------
    NoiseFloor
        AR(1) noise ``e[k] = a·e[k−1] + w[k]`` whose one-sided spectrum
        ``2·dt·σ_w²/(1 + a² − 2a·cos(2πf·dt))`` matches the residual's Welch spectrum over the
        band from ``3·bandwidth_hz`` (at most 0.6 of the Nyquist frequency) to 0.95 of it
        (least squares on the whitened log spectrum, deviations clipped at 3 MADs, over the
        poles :data:`NOISE_POLES`; the level is the median of the whitened spectrum); its variance
        ``σ_w²/(1 − a²)``, at most the residual's (``identified`` False: an effect's broadband
        residual looks the same, so it never overrules a twin's level), and its
        autocorrelation ``a^l``. White noise (``a = 0``) is the median spectral density spread
        over the whole band, as before; a band of fewer than :data:`MIN_POLE_FREQUENCIES`
        frequencies, or starting above :data:`MAX_POLE_BAND_START` of the Nyquist frequency,
        keeps it.

    Notes
    -----
    docs/gap.md §Noise floors. Above its bandwidth a plant passes little of its input, so what
    the twin misses there is noise, whatever the sampling rate; structured effects of a plant
    (friction, a stiffness) act at the frequencies of the motion. The median ignores the few
    harmonics an effect may leave in the band. A rig's sensor noise is often coloured (an
    anti-aliasing filter, a slow drift): read as white from the band above the plant, a noise
    whose power sits at low frequencies was 2–6 times too small, and every clean recording of
    the harder rig family read ``unexplained``.
    """
    from scipy.signal import welch

    values = np.asarray(residual, dtype=float)
    nyquist = 0.5 / dt
    segment = int(min(1024, max(16, 2 ** math.floor(math.log2(max(len(values) // 8, 16))))))
    freqs, density = welch(values - values.mean(), fs=1.0 / dt, nperseg=segment)
    low = min(3.0 * bandwidth_hz, 0.6 * nyquist)
    band = (freqs >= low) & (freqs <= 0.95 * nyquist)
    if np.count_nonzero(band) < 3:
        band = freqs >= 0.6 * nyquist
    # a narrow band (a plant near the Nyquist frequency) cannot tell a pole from a level
    wide = low <= MAX_POLE_BAND_START * nyquist
    pole = _noise_pole(freqs[band] * dt, density[band]) if wide else 0.0
    shape = 1.0 + pole * pole - 2.0 * pole * np.cos(2 * math.pi * freqs[band] * dt)
    innovation = max(float(np.median(density[band] * shape)), 0.0) * nyquist
    # a pole near 1 extrapolates the band's level to a large variance: never above the residual's
    sigma = min(math.sqrt(innovation / (1.0 - pole * pole)), float(np.std(values)))
    if pole == 0.0:
        return NoiseFloor(sigma, "data", _white_acf())
    n_lags = max(2, min(400, int(10 / (1.0 - pole))))
    # a coloured level is what an effect's broadband residual (a friction's sign changes) also
    # looks like: it never overrules a twin's noise level (reconcile_noise_floor)
    return NoiseFloor(sigma, "data", pole ** np.arange(n_lags), identified=False)


#: Lags of the Ljung–Box test on the innovations of :func:`residual_noise_floor`'s AR(1) model.
WHITENESS_LAGS = 20


def _runs(finite: np.ndarray) -> list[tuple[int, int]]:
    """Return ``[(start, stop), …]`` of the contiguous runs where ``finite`` is True."""
    edges = np.flatnonzero(np.diff(np.r_[0, finite.astype(np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _lag_products(values: np.ndarray, runs: list[tuple[int, int]], lag: int) -> tuple[float, int]:
    """Return ``(Σ v[k]·v[k−lag], count)`` over the pairs inside one run."""
    total, count = 0.0, 0
    for start, stop in runs:
        if stop - start > lag:
            total += float(values[start + lag : stop] @ values[start : stop - lag])
            count += stop - start - lag
    return total, count


def _white(innovations: np.ndarray, significance: float) -> bool:
    """Return whether centred innovations (NaN between runs) pass the Ljung–Box test of whiteness.

    Lags 1–:data:`WHITENESS_LAGS` over the pairs inside runs, ``χ²`` of ``lags − 1`` degrees
    of freedom (one fitted noise parameter besides the level), size ``significance``.
    """
    kept = np.isfinite(innovations)
    n = int(np.count_nonzero(kept))
    centred = innovations
    variance = float(np.mean(centred[kept] ** 2))
    if variance <= 0.0:
        return False
    inner = _runs(kept)
    acf = [1.0]
    for lag in range(1, WHITENESS_LAGS + 1):
        total, count = _lag_products(centred, inner, lag)
        if count == 0:
            break
        acf.append(total / (n * variance))
    lags = len(acf) - 1
    if lags < 2:
        return False
    return chi2.sf(ljung_box_statistic(np.asarray(acf), n)[-1], lags - 1) >= significance


def residual_noise_floor(residual: np.ndarray, significance: float) -> NoiseFloor | None:
    """Return the AR(1) noise the whole residual is, or None when the residual is not such noise.

    Parameters
    ----------
    residual : array, shape (n,)
        The calibrated linear twin's simulation error over its windows (output units; NaN on the
        unscored warm-ups, which cut it into runs).
    significance : float
        Size of the whiteness test of the model's innovations.

    Returns
    -------
    NoiseFloor or None
        The residual taken as AR(1) noise ``e[k] = a·e[k−1] + w[k]`` over the whole band (the
        output-error fit's residual modelled by the noise model a Box–Jenkins fit would
        give it, with the plant fixed): ``a`` the least-squares lag-1 coefficient within runs,
        the level ``√(σ_w²/(1 − a²))`` with ``σ_w`` the innovations' RMS, the autocorrelation
        ``a^l``, ``identified`` False (it never overrules a twin's level). None when the
        innovations ``w`` are not white — the Ljung–Box statistic over lags 1–
        :data:`WHITENESS_LAGS` (pairs inside runs) reaches ``χ²`` of ``lags − 1`` degrees of
        freedom at ``1 − significance`` — or ``a`` reaches the top of :data:`NOISE_POLES`
        (a drift as slow as the motion is not told from an effect): the residual then holds
        more than AR(1) noise, an effect's structured part among it.

    Notes
    -----
    docs/gap.md §Noise floors. Under the null of no effect this is the consistent estimate of
    the noise's level, whatever its colour: a noise with most of its power below the plant's
    resonance is half missed by a floor read above the plant. An effect either leaves the
    innovations coloured (the floor stays the spectral one) or is faint beside the noise,
    where the nested test (docs/gap.md §Where) is the stronger judge.
    """
    values = np.asarray(residual, dtype=float)
    finite = np.isfinite(values)
    if np.count_nonzero(finite) < 4 * WHITENESS_LAGS:
        return None
    centred = np.where(finite, values - np.mean(values[finite]), np.nan)
    runs = _runs(finite)
    cross, _ = _lag_products(centred, runs, 1)
    lagged = sum(float(centred[a : b - 1] @ centred[a : b - 1]) for a, b in runs if b - a > 1)
    if lagged <= 0.0:
        return None
    pole = cross / lagged
    if not -1.0 < pole < NOISE_POLES[-1]:
        return None
    innovations = np.full_like(centred, np.nan)
    for start, stop in runs:
        innovations[start + 1 : stop] = centred[start + 1 : stop] - pole * centred[start : stop - 1]
    kept = np.isfinite(innovations)
    innovations = np.where(kept, innovations - np.mean(innovations[kept]), np.nan)
    variance = float(np.mean(innovations[kept] ** 2))
    if variance <= 0.0:
        return None
    if not _white(innovations, significance):
        return None
    sigma = math.sqrt(variance / (1.0 - pole * pole))
    if pole <= 0.0:
        return NoiseFloor(sigma, "data", _white_acf(), identified=False)
    n_lags = max(2, min(400, int(10 / (1.0 - pole))))
    return NoiseFloor(sigma, "data", pole ** np.arange(n_lags), identified=False)


#: Ratios of process to measurement noise variance :func:`process_noise_floor` starts from,
#: per unit of the process covariance's mean eigenvalue (a log grid, then a bounded search).
PROCESS_RATIO_GRID = np.logspace(-4.0, 4.0, 33)


def process_noise_floor(
    groups: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    process_acf: np.ndarray,
    pole: float,
    significance: float,
) -> NoiseFloor | None:
    """Return the floor of process noise through the plant beside AR(1) measurement noise.

    Parameters
    ----------
    groups : sequence of ``(errors, process, measurement)``
        Windows of one length each: ``errors`` shape ``(n_windows, n_scored)``, the linear
        twin's error on the windows' scored samples (output units); ``process`` and
        ``measurement`` shape ``(n_scored, n_scored)``, the covariance of that error per unit
        acceleration noise held over each sample and per unit-variance AR(1) measurement noise
        of pole ``pole`` (:func:`~dtwin.gap.models.window_error_covariance`).
    process_acf : array, shape (n_lags,)
        The process noise's stationary autocorrelation in the position, lags 0, 1, ….
    pole : float
        The measurement noise's AR(1) pole (:func:`spectral_noise_floor`'s).
    significance : float
        Size of the whiteness test of the model's innovations.

    Returns
    -------
    NoiseFloor or None
        The windows' error taken as Gaussian with covariance ``σ_e²·(R_e + s·R_p)``: the
        measurement noise's level ``σ_e²`` profiled out and the variance ratio ``s`` by
        maximum likelihood (per window the generalised eigenvalues ``λ`` of ``R_p`` against
        ``R_e``: ``−2 log L = N·ln mean(z²/(1 + s·λ)) + Σ ln(1 + s·λ)``). The floor is that
        covariance's mean diagonal (the mean square the windows show under the model), its
        ``measurement`` and ``process`` parts, its autocorrelation their variance-weighted mix,
        ``identified`` False. None when the likelihood puts no process noise (``s = 0``), or
        the innovations (each window's error through the inverse Cholesky factor of the fitted
        covariance, in time order) are not white (:func:`_white`): the error then holds more
        than the two noises, an effect's structured part among it.

    Notes
    -----
    docs/gap.md §Noise floors. A twin file without noise levels leaves the plant's process
    noise to the data; the band above the plant shows only the measurement noise, and the
    process noise the plant passes near its resonance is what a clean recording's gap holds
    beside it. A faint effect of the motion that passes for process noise raises this floor;
    the nested test (docs/gap.md §Where), which tests each candidate's law and needs no noise
    level, then judges it.
    """
    from scipy.linalg import cholesky, eigh, solve_triangular
    from scipy.optimize import minimize_scalar

    eigen, squares, n_total = [], [], 0
    for errors, process, measurement in groups:
        lower = cholesky(measurement, lower=True)
        reduced = solve_triangular(
            lower, solve_triangular(lower, process, lower=True).T, lower=True
        )
        values, vectors = eigh(reduced)
        rotated = vectors.T @ solve_triangular(lower, np.atleast_2d(errors).T, lower=True)
        eigen.append(np.repeat(np.maximum(values, 0.0)[:, None], rotated.shape[1], axis=1).ravel())
        squares.append((rotated**2).ravel())
        n_total += rotated.size
    lam, z2 = np.concatenate(eigen), np.concatenate(squares)
    scale = float(np.mean(lam))
    if n_total == 0 or scale <= 0.0 or not np.all(np.isfinite(z2)):
        return None

    def deviance(ratio: float) -> float:
        spread = 1.0 + ratio * lam
        return n_total * math.log(float(np.mean(z2 / spread))) + float(np.sum(np.log(spread)))

    grid = PROCESS_RATIO_GRID / scale
    scores = [deviance(r) for r in grid]
    best = int(np.argmin(scores))
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    found = minimize_scalar(lambda t: deviance(math.exp(t)), bounds=(math.log(low), math.log(high)))
    ratio = math.exp(found.x) if found.fun < scores[best] else float(grid[best])
    if deviance(ratio) >= deviance(0.0):
        return None
    level = float(np.mean(z2 / (1.0 + ratio * lam)))
    parts = [[], []]
    runs = []
    for errors, process, measurement in groups:
        fitted = cholesky(level * (measurement + ratio * process), lower=True)
        for error in np.atleast_2d(errors):
            runs.append(solve_triangular(fitted, error, lower=True))
            runs.append([np.nan])
        weight = np.atleast_2d(errors).shape[0]
        parts[0].append(weight * np.diag(measurement))
        parts[1].append(weight * np.diag(process))
    innovations = np.concatenate(runs)
    kept = np.isfinite(innovations)
    innovations[kept] -= np.mean(innovations[kept])
    if not _white(innovations, significance):
        return None
    measurement_ms = level * float(np.sum([p.sum() for p in parts[0]])) / n_total
    process_ms = level * ratio * float(np.sum([p.sum() for p in parts[1]])) / n_total
    total = measurement_ms + process_ms
    n_lags = len(process_acf)
    acf = (
        process_ms * np.asarray(process_acf) + measurement_ms * pole ** np.arange(n_lags)
    ) / total
    return NoiseFloor(
        math.sqrt(total),
        "data",
        acf,
        measurement=math.sqrt(measurement_ms),
        identified=False,
        process=math.sqrt(process_ms),
    )


def window_gain_pole(floor: NoiseFloor) -> float:
    """Return the AR(1) pole a window's noise gain may count for ``floor`` (0: white).

    A pole fitted at the top of the grid :data:`NOISE_POLES` is not an estimate: the residual's
    spectrum above the plant falls at least as steeply as the steepest noise admitted, as the
    sign changes of a friction force do (the EMPS axis reads 0.98 there), so its colour is not
    counted (docs/gap.md §Noise floors): the window gain of such a floor is white noise's,
    whereas a coloured noise inside the grid (a rig's anti-aliasing filter, poles 0.5-0.95) keeps
    the larger gain its correlation carries forward.
    """
    if len(floor.acf) < 2:
        return 0.0
    pole = float(floor.acf[1])
    return 0.0 if pole >= NOISE_POLES[-1] - 1e-12 else pole


def _noise_pole(cycles: np.ndarray, density: np.ndarray) -> float:
    """Return the AR(1) pole whose spectrum shape fits ``density`` at ``cycles`` (f·dt) best."""
    positive = density > 0
    if np.count_nonzero(positive) < MIN_POLE_FREQUENCIES:
        return 0.0
    log_density = np.log(density[positive])
    cosine = np.cos(2 * math.pi * cycles[positive])
    shapes = np.log(1.0 + NOISE_POLES[:, None] ** 2 - 2.0 * NOISE_POLES[:, None] * cosine)
    whitened = log_density[None, :] + shapes
    # robust: deviations beyond 3 MADs (the few harmonics an effect leaves) count as 3 MADs
    deviation = whitened - np.median(whitened, axis=1, keepdims=True)
    limit = 3.0 * np.median(np.abs(deviation), axis=1, keepdims=True)
    spread = np.mean(np.clip(deviation, -limit, limit) ** 2, axis=1)
    return float(NOISE_POLES[int(np.argmin(spread))])


def _plant_noise_moments(u, x, lin, dt):
    """Return ``(var_process, var_meas, process_share)`` of the one-step error's differences."""
    m, c, k = lin["m"], lin["c"], lin["k"]
    delay = int(lin.get("delay_samples", 0))
    a1, a2 = -(2 - c * dt / m), 1 - c * dt / m + k * dt * dt / m
    lag = 2 + delay
    rows = len(x) - lag
    step_error = x[lag:] + a1 * x[lag - 1 : -1] + a2 * x[lag - 2 : -2] - dt * dt / m * u[:rows]
    diffs = _winsorize(np.diff(step_error))
    n_lags = 4
    observed = _autocov(diffs, n_lags)
    process = _filter_autocov(np.array([1.0, -1.0]), n_lags)
    measurement = _filter_autocov(np.convolve([1.0, -1.0], [1.0, a1, a2]), n_lags)
    (var_process, var_meas), _ = nnls(np.column_stack([process, measurement]), observed)
    total = var_process * process[0] + var_meas * measurement[0]
    return var_process, var_meas, (var_process * process[0] / total if total > 0 else 1.0)


#: Longest block (samples) on which :func:`_plant_data_floor` counts the process noise as
#: identified: on longer blocks the Euler recursion's own error (block means in a
#: second-order recursion, a miscalibrated twin) passes for process noise.
MAX_IDENTIFIED_BLOCK = 4


def _plant_data_floor(u: np.ndarray, x: np.ndarray, lin: dict, dt: float) -> NoiseFloor:
    """Process and measurement noise of the plant from the one-step error (method of moments).

    When measurement noise dominates the one-step error (fast sampling), the process noise is
    read on block averages of 2, 4, 8, … samples: over a step h its share grows like h⁴. The
    per-sample acceleration noise at dt is ``σ_h·√(h/dt)`` (white noise of fixed intensity).
    The floor is ``identified`` when the process noise dominated on blocks of at most
    :data:`MAX_IDENTIFIED_BLOCK` samples: a position measured with 1 % white noise read its
    process noise on blocks of 16, 10–30× too large (the Euler recursion's own error).
    """
    u = u - lin.get("u_offset", 0.0)
    _, var_meas, _ = _plant_noise_moments(u, x, lin, dt)
    factor, sigma_accel, share = 1, 0.0, 0.0
    while len(x) // factor >= 200:
        n_blocks = len(x) // factor
        xs = x[: n_blocks * factor].reshape(n_blocks, factor).mean(axis=1)
        us = u[: n_blocks * factor].reshape(n_blocks, factor).mean(axis=1)
        lin_h = dict(lin, delay_samples=int(lin.get("delay_samples", 0)) // factor)
        step = dt * factor
        var_process, _, share = _plant_noise_moments(us, xs, lin_h, step)
        sigma_accel = math.sqrt(var_process) / (step * step) * math.sqrt(step / dt)
        if share >= 0.5:
            break
        factor *= 2
    gain, acf = plant_noise_gain(lin["m"], lin["c"], lin["k"], dt)
    total = (sigma_accel * gain) ** 2 + var_meas
    weight = (sigma_accel * gain) ** 2 / total if total > 0 else 1.0
    mixed = weight * acf + (1 - weight) * np.r_[1.0, np.zeros(len(acf) - 1)]
    identified = share >= 0.5 and factor <= MAX_IDENTIFIED_BLOCK
    return NoiseFloor(math.sqrt(total), "data", mixed, math.sqrt(var_meas), identified)


def reconcile_noise_floor(
    twin: NoiseFloor | None, data: NoiseFloor, noise_tolerance: float = 0.0
) -> NoiseFloor:
    """Return the floor a module's gap is tested against, from the twin's and the data's.

    Parameters
    ----------
    twin : NoiseFloor or None
        From the twin file's noise levels (:func:`twin_noise_floor`); None when it has none.
    data : NoiseFloor
        Estimated from the recording (:func:`data_noise_floor`).
    noise_tolerance : float, default 0
        Relative uncertainty of the twin's noise levels (``GapSettings.noise_tolerance``).

    Returns
    -------
    NoiseFloor
        The data's floor without a twin floor. Otherwise the twin's, with the data's white
        measurement noise on the output added in quadrature (a twin file states the process
        and sensor noise, never the noise of the recorded position); and the data's floor
        instead when it exceeds that by more than ``noise_tolerance`` and its process noise
        was ``identified``: the recording then contradicts the twin's level. A twin floor of
        white noise (a sensor's: a twin file gives levels, not colours) takes the data's
        autocorrelation. Its ``source`` says which
        (``"twin"``, ``"twin+data"`` or ``"data"``).

    Notes
    -----
    docs/gap.md §Noise floors. The data floors are read where the structured effects are
    absent (differences, a high band, robust spreads), so a data floor above the twin's is more
    noise, not an effect; the exceptions are high-frequency effects the estimators cannot tell
    from noise (a broadband interference), which a twin with too low a level would otherwise
    flag as well.
    """
    if twin is None:
        return data
    floor = twin
    if len(twin.acf) == 1 and len(data.acf) > 1:
        floor = NoiseFloor(twin.rms, twin.source, data.acf, twin.measurement)
    if data.measurement > 0:
        total = twin.rms**2 + data.measurement**2
        weight = twin.rms**2 / total if total > 0 else 1.0
        white = np.r_[1.0, np.zeros(len(twin.acf) - 1)]
        acf = weight * twin.acf + (1 - weight) * white
        floor = NoiseFloor(math.sqrt(total), "twin+data", acf, data.measurement)
    overruled = data.identified and data.rms > floor.rms * (1.0 + noise_tolerance)
    return data if overruled else floor


def effective_samples(acf: np.ndarray, n: int) -> float:
    """Return the effective sample size of a mean square over ``n`` samples of coloured noise.

    ``n_eff = n / (1 + 2·Σ_{l≥1} (1 − l/n)·ρ_l²)`` (the variance of a sample variance of a
    Gaussian process).
    """
    lags = np.arange(1, min(len(acf), n))
    inflation = 1.0 + 2.0 * float(np.sum((1 - lags / n) * acf[lags] ** 2))
    return max(1.0, n / inflation)


def gap_threshold(
    floor_rms: float,
    n_eff: float,
    *,
    noise_tolerance: float,
    significance: float,
    min_gap: float,
) -> float:
    """Return the largest gap noise alone explains, normalised like the gap.

    ``floor·(1 + noise_tolerance)·√(χ²_{n_eff}(1 − significance)/n_eff)``, at least
    ``√(floor² + min_gap²)``: the floor with its level uncertain by ``noise_tolerance``, and
    the upper quantile of a mean square of Gaussian noise over ``n_eff`` effective samples; the
    excess over the floor must reach ``min_gap`` (an excess of 0.3 % of the signal's spread made
    3 of 10 rig recordings without an effect read ``unexplained``).
    """
    n_eff = max(n_eff, 1.0)
    sampling = math.sqrt(chi2.ppf(1.0 - significance, n_eff) / n_eff)
    # the part of the gap noise does not explain must itself reach min_gap (docs/gap.md §Where)
    return max(math.hypot(floor_rms, min_gap), floor_rms * (1.0 + noise_tolerance) * sampling)


def excess_gap(gap: float, floor: float) -> float:
    """Return ``√(gap² − floor²)``: the part of a gap its noise floor does not explain (≥ 0)."""
    return math.sqrt(max(gap * gap - floor * floor, 0.0))


def shrink_pct(before: float, after: float) -> float:
    """Return ``100·(1 − after/before)``, the percentage a gap shrank (0 when ``before ≤ 0``)."""
    if before <= 0:
        return 0.0
    return 100.0 * (1.0 - after / before)


#: Highest order of the autoregressive noise model that whitens an error series
#: (:func:`whitening_filter`).
WHITENING_MAX_ORDER = 8


def _lagged(residual: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(rows, lags)``: the samples whose ``order`` predecessors are all finite.

    ``rows`` are sample indices, ``lags`` shape ``(len(rows), order)`` their values at lags
    1 … ``order``.
    """
    finite = np.isfinite(residual)
    run = np.convolve(finite.astype(float), np.ones(order + 1))[: len(residual)]
    rows = np.flatnonzero(run >= order + 1 - 0.5)
    lags = np.zeros((len(rows), order))
    for lag in range(1, order + 1):
        lags[:, lag - 1] = residual[rows - lag]
    return rows, lags


def whitening_filter(residual: np.ndarray, max_order: int = WHITENING_MAX_ORDER) -> np.ndarray:
    """Return the monic whitening filter ``[1, a₁, …, a_p]`` of an AR(p) model of a residual.

    Parameters
    ----------
    residual : array, shape (n,)
        An error series, NaN where unscored (a window's warm-up): only stretches of finite
        samples are used.
    max_order : int
        Highest order tried.

    Returns
    -------
    numpy.ndarray, shape (p + 1,)
        ``e[k] + a₁·e[k−1] + … + a_p·e[k−p]`` is the model's innovation; ``p`` minimises BIC
        ``n·ln σ̂²_p + p·ln n`` over the same samples for every order (least squares,
        ``p = 0``: white).
    """
    residual = np.asarray(residual, dtype=float)
    rows, lags = _lagged(residual, max_order)
    if len(rows) <= 10 * (max_order + 1):
        return np.array([1.0])
    target = residual[rows]
    best, best_bic = np.array([1.0]), len(rows) * math.log(max(float(target @ target), 1e-300))
    for order in range(1, max_order + 1):
        coeffs, *_ = np.linalg.lstsq(lags[:, :order], target, rcond=None)
        error = target - lags[:, :order] @ coeffs
        bic = len(rows) * math.log(max(float(error @ error), 1e-300)) + order * math.log(len(rows))
        if bic < best_bic:
            best, best_bic = np.concatenate([[1.0], -coeffs]), bic
    return best


def whitened(residual: np.ndarray, whiten: np.ndarray) -> np.ndarray:
    """Return the innovations ``Σ a_i·e[k−i]`` of ``residual`` (NaN without ``p`` finite lags)."""
    order = len(whiten) - 1
    rows, lags = _lagged(np.asarray(residual, dtype=float), order)
    out = np.full(len(residual), np.nan)
    out[rows] = residual[rows] + lags @ whiten[1:]
    return out
