"""Sensitivity sweep of the HMM-guided plant correction (paper §5, Eq. (27), Fig. 11).

The authors' ``RobustnessAnalysis.R`` (r_notes.md §9): for every fusion weight α and pair of
sensor-noise multipliers ``(m_A, m_B)``, rerun the physics with the sensor noise standard
deviations scaled by the multipliers, refit the ARX surrogates on the first half, z-score the
six residuals, fit a K-state Gaussian HMM and correct the plant position; report

- ``ΔRMSE_e1 % = 100·(RMSE_pre − RMSE_post)/RMSE_pre`` (paper Eq. (27)), the same for the MAE;
- ``ΔL2 %`` of the aggregate residual norm, R's ``L2 = mean_t ‖e(t)‖₂`` over the six channels
  with only ``e1`` replaced by the corrected one.

Two corrections are computed on the same fit (both are cheap next to the HMM):

- ``code`` — the authors' sweep (r_notes.md §7C,
  :func:`dtwin.bias_correction.correct_plant_bias_viterbi`): Viterbi-hard state means of z-scored
  ``e1``, κ 0.6, EMA 0.15, rate limit 5e-4 m/sample;
- ``paper`` — the paper's targeted-intervention values (§4.3: κ 0.8, EMA 0.15, rate limit
  0.05) with posterior-weighted state means of the raw ``e1`` (Eq. (25),
  :func:`dtwin.bias_correction.correct_bias`), applied to the plant position only. (The sweep
  paragraph of §5 itself describes Viterbi-state means converted back to physical units, i.e.
  the ``code`` variant; only κ and the rate limit come from §4.3.)

Random draws: all noise is standard normals scaled by the noise standard deviation
(:mod:`dtwin.physics`), so within one replicate every configuration sees the same draws, only
scaled — R's ``set.seed(11)`` per configuration. Replicate 0 uses the base seeds
(``simulation.seed`` for the physics, ``sensitivity.seed`` for the EM starts); replicate
``r > 0`` derives both from ``SeedSequence([base, r])`` (:func:`replicate_seed`).

numpy cannot replay R's random stream. To compare with R on identical inputs,
:func:`dtwin.stages.sensitivity.r_sweep_physics` rebuilds every configuration of R's sweep from
R's seed-11 physics (sensor noise = reading − noise-free sensor response, rescaled), which
reproduces R's pre-correction RMSE, MAE and L2 of all 36 runs; only the HMM fit then differs.

This module is the sweep as data — grid points (:class:`SweepPoint`), seeds, one run's result
(:class:`SweepRun`), the long table of all runs (:func:`sweep_table`) and its aggregation
(:func:`summarize_sweep`, :func:`alpha_trends`) — and imports only numpy and pandas, so the
aggregate rule stays light. Running one point is :mod:`dtwin.stages.sensitivity`
(:func:`~dtwin.stages.sensitivity.sweep_point`). Arrays are time-first.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from dtwin._validation import (
    DtwinTypeError,
    DtwinValueError,
    require_in_range,
    require_nonnegative,
)
from dtwin.params import TwinParams, twin_params_from_mapping

__all__ = [
    "CORRECTION_METHODS",
    "SOURCES",
    "SWEEP_COLUMNS",
    "SweepPoint",
    "sweep_grid",
    "replicate_seed",
    "scale_twin",
    "CorrectionScore",
    "SweepRun",
    "read_sweep_rows",
    "sweep_table",
    "summarize_sweep",
    "alpha_trends",
    "bimodality_coefficient",
]

#: Corrections computed for every configuration (see the module docstring).
CORRECTION_METHODS: tuple[str, ...] = ("code", "paper")

#: Where a run's physics comes from: our simulation, or R's seed-11 signals rescaled.
SOURCES: tuple[str, ...] = ("ours", "r_signals")

_GRID_KEYS = ("alpha", "m_A", "m_B")

#: Columns of :func:`sweep_table`, one row per (configuration, replicate, source, method).
SWEEP_COLUMNS: tuple[str, ...] = (
    "alpha",
    "m_A",
    "m_B",
    "replicate",
    "source",
    "method",
    "physics_seed",
    "hmm_seed",
    "n_steps",
    "log_likelihood",
    "n_iter",
    "converged",
    "n_usable_starts",
    "rmse_e1_before",
    "rmse_e1_after",
    "mae_e1_before",
    "mae_e1_after",
    "l2_before",
    "l2_after",
    "drmse_e1_pct",
    "dmae_e1_pct",
    "dl2_pct",
)


class SweepPoint(NamedTuple):
    """One job of the sweep: fusion weight, sensor-noise multipliers, replicate number."""

    alpha: float
    m_A: float
    m_B: float
    replicate: int


def _unique_values(name: str, values: Any, check) -> list[float]:
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise DtwinTypeError(f"{name} must be a list of numbers (got {values!r})")
    out = [check(f"{name}[{i}]", v) for i, v in enumerate(values)]
    if not out:
        raise DtwinValueError(f"{name} must list at least one value (got none)")
    if len(set(out)) != len(out):
        raise DtwinValueError(f"{name} must not repeat values (got {out})")
    return out


def sweep_grid(
    alphas: Sequence[float],
    sensor_A_mults: Sequence[float],
    sensor_B_mults: Sequence[float],
    n_replicates: int = 1,
) -> list[SweepPoint]:
    """Return every (α, m_A, m_B, replicate) of the factorial sweep.

    Parameters
    ----------
    alphas : sequence of float
        Fusion weights on sensor A, each in [0, 1] (paper: 0.2, 0.4, 0.6, 0.8).
    sensor_A_mults, sensor_B_mults : sequence of float
        Multipliers (≥ 0) of the sensors' measurement-noise standard deviations (paper: 0.5,
        1, 1.5).
    n_replicates : int, default 1
        Independent repetitions of every configuration (R: 1).

    Returns
    -------
    list of SweepPoint
        ``len(alphas)·len(sensor_A_mults)·len(sensor_B_mults)·n_replicates`` points; α varies
        fastest, then m_A, then m_B, then the replicate (R's ``expand.grid`` order).

    Examples
    --------
    >>> points = sweep_grid([0.2, 0.8], [1.0], [0.5, 1.5], n_replicates=2)
    >>> len(points), points[1]
    (8, SweepPoint(alpha=0.8, m_A=1.0, m_B=0.5, replicate=0))
    """
    alphas = _unique_values(
        "sensitivity.alphas", alphas, lambda n, v: require_in_range(n, v, 0.0, 1.0)
    )
    mults_a = _unique_values("sensitivity.sensor_A_mults", sensor_A_mults, require_nonnegative)
    mults_b = _unique_values("sensitivity.sensor_B_mults", sensor_B_mults, require_nonnegative)
    if isinstance(n_replicates, bool) or not isinstance(n_replicates, (int, np.integer)):
        raise DtwinTypeError(f"sensitivity.n_replicates must be an integer (got {n_replicates!r})")
    if n_replicates < 1:
        raise DtwinValueError(f"sensitivity.n_replicates must be >= 1 (got {n_replicates})")
    return [
        SweepPoint(alpha, m_a, m_b, replicate)
        for replicate, m_b, m_a, alpha in itertools.product(
            range(int(n_replicates)), mults_b, mults_a, alphas
        )
    ]


def replicate_seed(base_seed: int, replicate: int) -> int:
    """Return the seed of one replicate: ``base_seed`` for replicate 0, else a derived seed.

    Replicate ``r > 0`` gets the first 32-bit word of ``numpy.random.SeedSequence([base_seed,
    r])``, so replicates are independent streams and the default single replicate uses the
    configured seed itself (R's design: the same seed for every configuration).

    Examples
    --------
    >>> replicate_seed(11, 0)
    11
    >>> replicate_seed(11, 1) == replicate_seed(11, 1) != replicate_seed(11, 2)
    True
    """
    for name, value in (("seed", base_seed), ("replicate", replicate)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise DtwinValueError(f"{name} must be an integer >= 0 (got {value!r})")
    if replicate == 0:
        return int(base_seed)
    sequence = np.random.SeedSequence([int(base_seed), int(replicate)])
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def scale_twin(
    twin: TwinParams | Mapping[str, Any], alpha: float, m_A: float, m_B: float
) -> TwinParams:
    """Return the twin with fusion weight α and scaled sensor noise.

    ``noise.sensor_A`` and ``noise.sensor_B`` (standard deviations) are multiplied by ``m_A``
    and ``m_B``; every other parameter is unchanged. A ``twin:`` mapping is parsed first
    (:func:`dtwin.params.twin_params_from_mapping`, every section required).
    """
    twin = twin_params_from_mapping(twin)
    alpha = require_in_range("alpha", alpha, 0.0, 1.0)
    m_A = require_nonnegative("m_A", m_A)
    m_B = require_nonnegative("m_B", m_B)
    noise = replace(
        twin.noise, sensor_A=twin.noise.sensor_A * m_A, sensor_B=twin.noise.sensor_B * m_B
    )
    return replace(twin, fusion=replace(twin.fusion, alpha=alpha), noise=noise)


@dataclass(frozen=True)
class CorrectionScore:
    """Plant-residual scores of one correction (RMSE and MAE in m, L2 in mixed units).

    Attributes
    ----------
    method : str
        ``"code"`` or ``"paper"``.
    rmse_e1_before, rmse_e1_after, mae_e1_before, mae_e1_after : float
        RMSE and MAE of ``e1`` over all samples, before and after the correction.
    l2_before, l2_after : float
        ``mean_t ‖e(t)‖₂`` over the six residuals (only ``e1`` corrected).
    """

    method: str
    rmse_e1_before: float
    rmse_e1_after: float
    mae_e1_before: float
    mae_e1_after: float
    l2_before: float
    l2_after: float

    @staticmethod
    def _reduction(before: float, after: float) -> float:
        return 100.0 * (before - after) / before if before > 0 else math.nan

    @property
    def drmse_e1_pct(self) -> float:
        """Paper Eq. (27): ``100·(RMSE_pre − RMSE_post)/RMSE_pre``."""
        return self._reduction(self.rmse_e1_before, self.rmse_e1_after)

    @property
    def dmae_e1_pct(self) -> float:
        """The same reduction for the MAE of ``e1``."""
        return self._reduction(self.mae_e1_before, self.mae_e1_after)

    @property
    def dl2_pct(self) -> float:
        """The same reduction for the aggregate L2 norm."""
        return self._reduction(self.l2_before, self.l2_after)


@dataclass(frozen=True)
class SweepRun:
    """The result of one configuration and replicate on one source of physics.

    Attributes
    ----------
    point : SweepPoint
    source : str
        ``"ours"`` (our simulation) or ``"r_signals"`` (R's seed-11 physics, rescaled).
    physics_seed : int or None
        Seed of the simulation (None for R's signals).
    hmm_seed : int
        Seed of the EM starts.
    n_steps : int
        Samples of the run.
    log_likelihood : float
        Of the best EM start.
    n_iter : int
        EM iterations of the best start.
    converged : bool
        Whether the best start met the tolerance.
    n_usable_starts : int
        Starts that neither failed nor left a state empty.
    scores : tuple of CorrectionScore
        One per method of :data:`CORRECTION_METHODS`.
    """

    point: SweepPoint
    source: str
    physics_seed: int | None
    hmm_seed: int
    n_steps: int
    log_likelihood: float
    n_iter: int
    converged: bool
    n_usable_starts: int
    scores: tuple[CorrectionScore, ...]

    def rows(self) -> list[dict[str, Any]]:
        """Return one flat record per method, with the columns of :data:`SWEEP_COLUMNS`."""
        common = {
            **self.point._asdict(),
            "source": self.source,
            "physics_seed": self.physics_seed,
            "hmm_seed": self.hmm_seed,
            "n_steps": self.n_steps,
            "log_likelihood": self.log_likelihood,
            "n_iter": self.n_iter,
            "converged": self.converged,
            "n_usable_starts": self.n_usable_starts,
        }
        records = [
            {
                **common,
                "method": score.method,
                "rmse_e1_before": score.rmse_e1_before,
                "rmse_e1_after": score.rmse_e1_after,
                "mae_e1_before": score.mae_e1_before,
                "mae_e1_after": score.mae_e1_after,
                "l2_before": score.l2_before,
                "l2_after": score.l2_after,
                "drmse_e1_pct": score.drmse_e1_pct,
                "dmae_e1_pct": score.dmae_e1_pct,
                "dl2_pct": score.dl2_pct,
            }
            for score in self.scores
        ]
        return [{column: record[column] for column in SWEEP_COLUMNS} for record in records]


# --- aggregation -----------------------------------------------------------------------------


def _point_name(alpha: float, m_A: float, m_B: float, replicate: int) -> str:
    return f"alpha={alpha:g}, m_A={m_A:g}, m_B={m_B:g}, replicate {replicate}"


def read_sweep_rows(paths: Iterable[str | os.PathLike]) -> list[dict[str, Any]]:
    """Return the run records of the per-job JSON files (``{"point": ..., "rows": [...]}``)."""
    rows: list[dict[str, Any]] = []
    for path in paths:
        with open(path, encoding="utf-8") as handle:
            payload = json.load(handle)
        if "rows" not in payload:
            raise DtwinValueError(f"{path} is not a sweep result (no 'rows')")
        rows.extend(payload["rows"])
    return rows


def sweep_table(rows: Iterable[Mapping[str, Any]], grid: Sequence[SweepPoint]) -> pd.DataFrame:
    """Collect run records into one long table and check it covers the grid.

    Parameters
    ----------
    rows : iterable of mapping
        Records of :meth:`SweepRun.rows` (from the per-job JSON files).
    grid : sequence of SweepPoint
        The expected points (:func:`sweep_grid`).

    Returns
    -------
    DataFrame
        Columns :data:`SWEEP_COLUMNS`, sorted by source, method, replicate, m_A, m_B, α.

    Raises
    ------
    DtwinValueError
        If a grid point has no ``source = "ours"`` result (the message names the first missing
        configurations), or a record lies outside the grid.
    """
    table = pd.DataFrame(list(rows))
    missing_columns = [c for c in SWEEP_COLUMNS if c not in table.columns]
    if table.empty or missing_columns:
        raise DtwinValueError(
            f"sweep results are missing column(s) {', '.join(missing_columns) or 'all'}"
        )
    table = table[list(SWEEP_COLUMNS)]
    keys = [*_GRID_KEYS, "replicate"]
    found = {
        tuple(row)
        for row in table.loc[table["source"] == "ours", keys].itertuples(index=False, name=None)
    }
    expected = [tuple(point) for point in grid]
    missing = [point for point in expected if point not in found]
    if missing:
        names = "; ".join(_point_name(*p) for p in missing[:5])
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise DtwinValueError(
            f"sweep results are missing {len(missing)} of {len(expected)} configurations: "
            f"{names}{more}"
        )
    extra = sorted(found - set(expected))
    if extra:
        raise DtwinValueError(f"sweep result outside the grid: {_point_name(*extra[0])}")
    return table.sort_values(["source", "method", "replicate", "m_A", "m_B", "alpha"]).reset_index(
        drop=True
    )


def summarize_sweep(table: pd.DataFrame, interval: float = 0.9) -> pd.DataFrame:
    """Return the mean and a central interval over replicates of every configuration.

    Parameters
    ----------
    table : DataFrame
        From :func:`sweep_table`.
    interval : float, default 0.9
        Probability mass of the central empirical interval (quantiles ``(1 ∓ interval)/2`` of
        the replicates; with one replicate the interval is the value itself).

    Returns
    -------
    DataFrame
        One row per ``source, method, alpha, m_A, m_B``: ``n_replicates``,
        ``drmse_e1_mean``, ``drmse_e1_sd`` (ddof 1; NaN for one replicate), ``drmse_e1_lo``,
        ``drmse_e1_hi``, ``dmae_e1_mean``, ``dl2_mean``, ``rmse_e1_before_mean``,
        ``rmse_e1_after_mean``, ``l2_before_mean`` and ``converged_frac``.
    """
    interval = require_in_range("sensitivity.interval", interval, 0.0, 1.0)
    low, high = (1.0 - interval) / 2.0, (1.0 + interval) / 2.0
    keys = ["source", "method", *_GRID_KEYS]
    grouped = table.groupby(keys, sort=True)
    values = grouped["drmse_e1_pct"]
    summary = pd.DataFrame(
        {
            "n_replicates": grouped["replicate"].nunique(),
            "drmse_e1_mean": values.mean(),
            "drmse_e1_sd": values.std(ddof=1),
            "drmse_e1_lo": values.quantile(low),
            "drmse_e1_hi": values.quantile(high),
            "dmae_e1_mean": grouped["dmae_e1_pct"].mean(),
            "dl2_mean": grouped["dl2_pct"].mean(),
            "rmse_e1_before_mean": grouped["rmse_e1_before"].mean(),
            "rmse_e1_after_mean": grouped["rmse_e1_after"].mean(),
            "l2_before_mean": grouped["l2_before"].mean(),
            "converged_frac": grouped["converged"].mean(),
        }
    )
    return summary.reset_index()


def alpha_trends(table: pd.DataFrame) -> pd.DataFrame:
    """Return the least-squares slope of ΔRMSE_e1 % on α per facet and replicate.

    Returns
    -------
    DataFrame
        One row per ``source, method, m_A, m_B, replicate`` with ``slope_pct_per_unit_alpha``
        (NaN when the facet has a single α).
    """
    rows = []
    for key, facet in table.groupby(["source", "method", "m_A", "m_B", "replicate"], sort=True):
        alphas = facet["alpha"].to_numpy(dtype=float)
        values = facet["drmse_e1_pct"].to_numpy(dtype=float)
        slope = math.nan
        if len(np.unique(alphas)) > 1:
            slope = float(np.polyfit(alphas, values, 1)[0])
        rows.append(
            dict(
                zip(["source", "method", "m_A", "m_B", "replicate"], key, strict=True),
                slope_pct_per_unit_alpha=slope,
            )
        )
    return pd.DataFrame(rows)


def bimodality_coefficient(values: Any) -> float:
    """Return Sarle's bimodality coefficient of a sample (> 5/9 suggests two modes).

    Notes
    -----
    ``BC = (g² + 1) / (k + 3(n−1)²/((n−2)(n−3)))`` with ``g`` the bias-corrected sample
    skewness and ``k`` the bias-corrected excess kurtosis; 5/9 is the value of a uniform
    distribution. NaN for fewer than 4 values or zero variance.

    Examples
    --------
    >>> bimodality_coefficient([1, 1, 1, 1, 1, 1, 1, 1, 10, 10, 10, 10]) > 5 / 9
    True
    """
    x = np.asarray(values, dtype=float)
    n = x.size
    if n < 4:
        return math.nan
    deviations = x - x.mean()
    m2 = np.mean(deviations**2)
    if m2 <= 0:
        return math.nan
    g1 = np.mean(deviations**3) / m2**1.5
    g2 = np.mean(deviations**4) / m2**2 - 3.0
    skew = g1 * math.sqrt(n * (n - 1)) / (n - 2)
    kurt = (n - 1) / ((n - 2) * (n - 3)) * ((n + 1) * g2 + 6.0)
    return float((skew**2 + 1.0) / (kurt + 3.0 * (n - 1) ** 2 / ((n - 2) * (n - 3))))
