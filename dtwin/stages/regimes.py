"""Stage "regimes" (paper §4.2, §5; Figs. 4, 9): K-state HMM on the nominal residuals, BIC over K.

Figures of this stage live in :mod:`dtwin.figures.fig04_hmm_posteriors` and
:mod:`dtwin.figures.fig09_bic`.
Config sections (``config/config.yaml``): ``hmm`` and ``bic``.

Every EM random start derives from the one config seed ``hmm.seed``: each *use* of it (the
nominal fit, the fault-feature fit, a BIC sweep, the crosscheck fit on R's features) gets its
own entropy ``[hmm.seed, SEED_STREAMS[use]]`` of :class:`numpy.random.SeedSequence`, so no two
uses share random draws and adding a use does not change the others.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import DtwinValueError
from dtwin.config_sections import BicSettings, EmSettings, HmmSettings
from dtwin.fault_injection import regime_features
from dtwin.hmm import HmmFit, ZScored, bic_by_k, bic_row, fit_zscored_hmm, hmm_summary, zscore
from dtwin.params import twin_params_from_mapping
from dtwin.physics import backward_velocity, fuse, kpi
from dtwin.reference.columns import R_PHYSICS_COLUMNS, R_SURROGATE_COLUMNS
from dtwin.state_tables import posterior_matrix, state_labels
from dtwin.surrogate import compute_residuals
from dtwin.twin.wiring import RESIDUALS

__all__ = [
    "SEED_STREAMS",
    "hmm_seed",
    "state_labels",
    "fit_regimes",
    "states_table",
    "posterior_matrix",
    "hmm_summary",
    "fit_nominal_regimes",
    "BIC_DATASETS",
    "given_bic_row",
    "bic_dataset",
    "sweep_bic",
    "bic_sweep_dataset",
    "r_nominal_residuals",
    "bic_r_signals",
]

logger = logging.getLogger(__name__)

#: Stream number of each random use of ``hmm.seed`` (entropy ``[hmm.seed, stream]``).
SEED_STREAMS: dict[str, int] = {
    "nominal_fit": 1,
    "fault_fit": 2,
    "r_crosscheck_fit": 3,
    "bic_nominal_residuals": 4,
    "bic_fault_features": 5,
}

#: Data sets of the BIC sweep (r_notes.md §6 (a) and (b)).
BIC_DATASETS: tuple[str, ...] = ("nominal_residuals", "fault_features")


def hmm_seed(hmm: Mapping[str, Any], use: str) -> list[int]:
    """Return the seed entropy ``[hmm.seed, stream]`` of one random use (see :data:`SEED_STREAMS`).

    Examples
    --------
    >>> hmm_seed({"seed": 123}, "fault_fit")
    [123, 2]
    """
    if use not in SEED_STREAMS:
        raise DtwinValueError(f"use must be one of {', '.join(SEED_STREAMS)} (got {use!r})")
    return [int(hmm["seed"]), SEED_STREAMS[use]]


def fit_regimes(features: pd.DataFrame, hmm: Mapping[str, Any], use: str) -> tuple[ZScored, HmmFit]:
    """z-score ``features`` (R's ``scale``) and fit the K-state HMM of the ``hmm`` section.

    Parameters
    ----------
    features : DataFrame, shape (T, D)
        Raw feature columns (residuals in physical units, or the ten fault features).
    hmm : mapping
        The ``hmm`` config section (``n_states``, ``n_restarts``, ``seed``, ``max_iter``,
        ``tol``, ``var_floor``).
    use : str
        Key of :data:`SEED_STREAMS` naming this random use.

    Returns
    -------
    (ZScored, HmmFit)
    """
    settings = HmmSettings.from_mapping(hmm)
    start = time.perf_counter()
    scaled, fit = fit_zscored_hmm(
        features, settings.n_states, seed=hmm_seed(hmm, use), **settings.fit_options()
    )
    logger.info(
        "%s: K=%d, D=%d, T=%d, %d starts in %.3f s; best logL %.4f (start %d, %d EM iterations)",
        use,
        fit.n_states,
        fit.n_features,
        len(scaled.values),
        settings.n_restarts,
        time.perf_counter() - start,
        fit.log_likelihood,
        fit.best_restart,
        fit.n_iter,
    )
    return scaled, fit


def states_table(t: Any, fit: HmmFit, regime: Any = None) -> pd.DataFrame:
    """Return the decoded states as a table.

    Columns: ``t`` (s), ``regime`` (only if given), ``state`` (Viterbi, 1 … K),
    ``gamma_S1 … gamma_SK`` (smoothed posteriors P(S_t = k | e_1:T)) and
    ``filtered_S1 … filtered_SK`` (filtered posteriors P(S_t = k | e_1:t)).
    """
    table = pd.DataFrame({"t": np.asarray(t, dtype=float)})
    if regime is not None:
        table["regime"] = np.asarray(regime, dtype=str)
    table["state"] = fit.viterbi + 1
    labels = state_labels(fit.n_states)
    for j, label in enumerate(labels):
        table[f"gamma_{label}"] = fit.smoothed[:, j]
    for j, label in enumerate(labels):
        table[f"filtered_{label}"] = fit.filtered[:, j]
    return table


def fit_nominal_regimes(
    residuals: pd.DataFrame, hmm: Mapping[str, Any]
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Fit the K-state HMM to the z-scored nominal residuals (paper §4.2, Fig. 4).

    Parameters
    ----------
    residuals : DataFrame
        Columns ``t`` (s) and ``e0 … e4`` (the nominal residuals of the twin stage).
    hmm : mapping
        The ``hmm`` config section.

    Returns
    -------
    (states, summary)
        :func:`states_table` and :func:`hmm_summary` of the best start.
    """
    scaled, fit = fit_regimes(residuals[list(RESIDUALS)], hmm, "nominal_fit")
    return states_table(residuals["t"], fit), hmm_summary(fit, scaled)


def given_bic_row(model: Mapping[str, Any]) -> dict[str, Any]:
    """Return the BIC-table row of a dedicated fit from its summary (:func:`hmm_summary`).

    The nominal fit of Fig. 4 and the fault fit of Fig. 7 are the sweep's points at their K,
    so that the figures and the BIC curve share one fit (``source = "given"``). The row also
    carries the fit's ``means_z`` and ``sds_z``, from which the sweep grows K + 1
    (``bic.split_starts``); :func:`dtwin.hmm.bic_by_k` does not tabulate them.
    """
    row = bic_row(
        model["n_states"],
        pd.DataFrame(model["restarts"]),
        model["n_params"],
        model["bic"],
        model["converged"],
        "given",
    )
    return {**row, "means_z": model["means_z"], "sds_z": model["sds_z"]}


def bic_dataset(
    name: str, features_csv: str | os.PathLike, model_json: str | os.PathLike
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Return one BIC data set's raw features and the summary of its dedicated K-state fit.

    ``nominal_residuals``: columns e0 … e4 of ``results/residuals.csv`` and
    ``results/regimes/nominal_model.json``; ``fault_features``: the ten features
    (:func:`dtwin.fault_injection.regime_features`) of ``results/faults/residuals.csv`` and the
    ``model`` of ``results/faults/summary.json``. The inputs of :func:`sweep_bic` for one data set.
    """
    if name not in BIC_DATASETS:
        raise DtwinValueError(f"name must be one of {BIC_DATASETS} (got {name!r})")
    table = pd.read_csv(features_csv)
    summary = json.loads(Path(model_json).read_text())
    if name == "nominal_residuals":
        return table[list(RESIDUALS)], summary
    return regime_features(table), summary["model"]


def sweep_bic(
    datasets: Mapping[str, pd.DataFrame],
    bic: BicSettings | Mapping[str, Any],
    hmm: Mapping[str, Any],
    models: Mapping[str, Mapping[str, Any]] | None = None,
) -> pd.DataFrame:
    """BIC over K on each data set, extended until its minimum is bracketed (§5, Eq. (26)).

    Parameters
    ----------
    datasets : mapping of str to DataFrame
        Raw features per data set, keys from :data:`BIC_DATASETS` (each is z-scored here).
    bic : BicSettings or mapping
        The ``bic`` section (:class:`dtwin.config_sections.BicSettings`): ``ks`` (always
        fitted), ``n_restarts`` (starts per K; the best of the first half is reported beside
        the best of all), optional ``k_max`` and ``stop_after_rises`` (extend K past
        ``max(ks)`` until the BIC rose that many times in a row, at most to ``k_max``),
        ``split_starts`` (also grow the best K − 1 fit by splitting each of its states,
        :func:`dtwin.hmm.split_fits`) and ``max_restarts``; parsed here unless it comes parsed.
    hmm : mapping
        The ``hmm`` section (``seed`` and the EM options).
    models : mapping of str to dict, optional
        Per data set, the summary (:func:`hmm_summary`) of its dedicated fit, used as the
        sweep's point at that K (:func:`given_bic_row`).

    Returns
    -------
    DataFrame
        Columns ``dataset``, ``n_features`` and those of :func:`dtwin.hmm.bic_by_k`
        (``K``, ``log_likelihood``, ``n_params``, ``bic``, ``converged``, ``n_usable``,
        ``log_likelihood_half``, ``n_starts``, ``source``); one row per data set and K.
    """
    bic = BicSettings.from_mapping(bic)
    em_options = EmSettings.from_mapping(hmm).options()
    tables = []
    for name, features in datasets.items():
        if name not in BIC_DATASETS:
            raise DtwinValueError(f"datasets keys must be in {BIC_DATASETS} (got {name!r})")
        model = (models or {}).get(name)
        start = time.perf_counter()
        table = bic_by_k(
            zscore(features).values,
            list(bic.ks),
            n_restarts=bic.n_restarts,
            seed=hmm_seed(hmm, f"bic_{name}"),
            k_max=bic.k_max,
            stop_after_rises=bic.stop_after_rises,
            split_starts=bic.split_starts,
            max_restarts=bic.max_restarts,
            given=None if model is None else {model["n_states"]: given_bic_row(model)},
            **em_options,
        )
        logger.info(
            "BIC sweep on %s (D=%d): K=%s, %d starts each, %.2f s",
            name,
            features.shape[1],
            table["K"].tolist(),
            bic.n_restarts,
            time.perf_counter() - start,
        )
        table.insert(0, "n_features", features.shape[1])
        table.insert(0, "dataset", name)
        tables.append(table)
    return pd.concat(tables, ignore_index=True)


def bic_sweep_dataset(
    name: str,
    features_csv: str | os.PathLike,
    model_json: str | os.PathLike,
    bic: BicSettings | Mapping[str, Any],
    hmm: Mapping[str, Any],
) -> pd.DataFrame:
    """Rule ``bic_sweep_dataset``: the BIC over K of one data set (:func:`sweep_bic`).

    Reads the data set and its dedicated fit with :func:`bic_dataset`; returns its rows of
    ``results/bic_sweep.csv`` (rule ``bic_sweep`` joins the data sets,
    :func:`dtwin.stages.bic_table.bic_sweep`).
    """
    features, model = bic_dataset(name, features_csv, model_json)
    return sweep_bic({name: features}, bic, hmm, {name: model})


def r_nominal_residuals(r_pipeline: pd.DataFrame, twin: Mapping[str, Any]) -> pd.DataFrame:
    """Return R's nominal residuals ``e0 … e4``, rebuilt from R's own seed-11 signals.

    R's physics columns of ``config/reference/faulted_pipeline_seed11_rerun.csv`` and its
    unfaulted surrogate rollouts (the ``*_nofault`` columns, seeded from physics as
    ``BIC_vs_K.R`` seeds them); the surrogate's fusion and KPI follow from them with the twin's
    ``fusion.alpha``, ``kpi.w1``, ``kpi.w2`` and ``dt`` (velocity by backward difference,
    R's ``c(0, diff(x)/dt)``). These are the six channels ``BIC_vs_K.R`` sweeps
    (r_notes.md §6 (a)); over the fault scenario's Nominal window they equal R's ``e0 … e4``.

    Parameters
    ----------
    r_pipeline : DataFrame
        ``faulted_pipeline_seed11_rerun.csv`` as read, R's column names.
    twin : mapping
        The ``twin`` section, at least ``dt``, ``fusion`` and ``kpi``.

    Returns
    -------
    DataFrame
        Columns ``t`` and :data:`dtwin.twin.wiring.RESIDUALS`, one row per sample (T = 1000).
    """
    params = twin_params_from_mapping(twin, require_all=False, required=("fusion", "kpi"))
    physics = pd.DataFrame({ours: r_pipeline[theirs] for ours, theirs in R_PHYSICS_COLUMNS.items()})
    surrogate = pd.DataFrame(
        {
            ours: r_pipeline[theirs].to_numpy(dtype=float)
            for ours, theirs in R_SURROGATE_COLUMNS.items()
        }
    )
    x = surrogate["x"].to_numpy()
    velocity = backward_velocity(x, params.dt)
    surrogate["y_fused"] = fuse(surrogate["y_A"], surrogate["y_B"], params.fusion.alpha)
    surrogate["z"] = kpi(x, velocity, params.kpi.w1, params.kpi.w2)
    return compute_residuals(surrogate, physics)


def bic_r_signals(
    name: str,
    r_pipeline: pd.DataFrame,
    bic: BicSettings | Mapping[str, Any],
    hmm: Mapping[str, Any],
    twin: Mapping[str, Any],
) -> pd.DataFrame:
    """Fig. 9's sweep of one data set on R's own seed-11 signals (paper §5).

    The same :func:`sweep_bic` (settings, seed stream, EM) as on our draw, run on the data
    set as R built it from the signals of ``config/reference/faulted_pipeline_seed11_rerun.csv``:
    ``fault_features``, the ten features of R's faulted residuals (R's K = 8 came from them with
    5 EM starts per K ≤ 9); ``nominal_residuals``, R's nominal residuals
    (:func:`r_nominal_residuals`; R: one EM start per K). Where our minimum is not at 8 on
    R's own signals either, the draw cannot explain it: Fig. 9 then names the optimiser.

    Parameters
    ----------
    name : str
        One of :data:`BIC_DATASETS`.
    r_pipeline : DataFrame
        ``faulted_pipeline_seed11_rerun.csv`` as read.
    bic, hmm : mapping
        As :func:`sweep_bic`.
    twin : mapping
        The ``twin`` section (``dt``, ``fusion``, ``kpi``): the surrogate's fusion and KPI of
        the nominal residuals.

    Returns
    -------
    DataFrame
        :func:`sweep_bic`'s table for the one data set ``name``.
    """
    if name not in BIC_DATASETS:
        raise DtwinValueError(f"name must be one of {BIC_DATASETS} (got {name!r})")
    if name == "nominal_residuals":
        features = r_nominal_residuals(r_pipeline, twin)[list(RESIDUALS)]
    else:
        features = regime_features(r_pipeline)
    return sweep_bic({name: features}, bic, hmm)
