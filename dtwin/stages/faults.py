"""Stage "faults" (paper §4.4; Figs. 7, 8): fault injection, regime HMM, Hungarian scoring.

The scheduled faults are injected into the twin's surrogate streams (r_notes.md §5), the
faulted residuals give the ten z-scored features, a K-state HMM is fitted to them, its
Viterbi path is mapped to the regimes by maximum overlap (Hungarian) and scored. The run is
scored for both drift origins (the configured one writes the tables; the other is scored
beside it), and every EM start's Viterbi path is scored too, to show how much the answer
depends on the start.

Figures of this stage live in :mod:`dtwin.figures.fig07_fault_posteriors` and
:mod:`dtwin.figures.fig08_feature_separability`. Config sections: ``faults``, ``hmm`` and the
``dt``/``fusion``/``kpi`` keys of ``twin``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dtwin._validation import require_seed
from dtwin.fault_injection import (
    DRIFT_ORIGINS,
    REGIMES,
    FaultMagnitudes,
    fault_schedule,
    inject_faults,
    regime_features,
)
from dtwin.hmm import HmmFit
from dtwin.params import ALGEBRAIC_SECTIONS, TwinParams, twin_params_from_mapping
from dtwin.regime_matching import (
    StateMapping,
    classification_scores,
    hungarian_map,
    mapped_posteriors,
)
from dtwin.stages.regimes import fit_regimes, hmm_summary, states_table
from dtwin.surrogate import compute_residuals

__all__ = [
    "POSTERIOR_COLUMNS",
    "inject_scenario",
    "score_regime_fit",
    "FaultScenario",
    "run_fault_scenario",
]

#: Columns of ``results/faults/posteriors.csv`` (a contract other stages rely on).
POSTERIOR_COLUMNS: tuple[str, ...] = (
    "t",
    "regime",
    "state",
    "mapped_regime",
    *(f"p_{regime}" for regime in REGIMES),
)


def inject_scenario(
    physics: pd.DataFrame,
    surrogate: pd.DataFrame,
    faults: Mapping[str, Any],
    twin: TwinParams | Mapping[str, Any],
    drift_origin: str | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Inject the scheduled faults into the surrogate streams; return them and the residuals.

    The SensorNoisy noise comes from ``numpy.random.default_rng(faults.seed)``, so both drift
    origins see the same noise draws.

    Returns
    -------
    (faulted, residuals)
        ``faulted``: columns ``t``, ``regime`` and the surrogate signals with the faults in
        (``y_fused``, ``v`` and ``z`` recomputed); ``residuals``: ``t``, ``regime``,
        ``e0 … e4`` (faulted surrogate − physics).
    """
    twin = twin_params_from_mapping(twin, require_all=False, required=ALGEBRAIC_SECTIONS)
    faulted = inject_faults(
        surrogate,
        np.random.default_rng(require_seed("faults.seed", faults["seed"])),
        alpha=twin.fusion.alpha,
        w1=twin.kpi.w1,
        w2=twin.kpi.w2,
        dt=twin.dt,
        schedule=fault_schedule(faults["schedule"]),
        magnitudes=FaultMagnitudes.from_mapping(faults, drift_origin=drift_origin),
    )
    columns = ["t", "regime", *(c for c in faulted.columns if c not in ("t", "regime"))]
    faulted = faulted[columns]
    residuals = compute_residuals(faulted, physics)
    residuals.insert(1, "regime", faulted["regime"].to_numpy())
    return faulted, residuals


def _scores_record(predicted: np.ndarray, regimes: np.ndarray) -> dict[str, Any]:
    scores = classification_scores(predicted, regimes, labels=REGIMES)
    return {
        "accuracy": scores.accuracy,
        "macro_f1": scores.macro_f1,
        "kappa": scores.kappa,
        "confusion": scores.confusion.to_dict(orient="index"),
        "per_class": scores.per_class.to_dict(orient="records"),
    }


def _nominal_sensor_share(confusion: Mapping[str, Mapping[str, int]]) -> float:
    """Share of the misclassified samples that are Nominal ↔ SensorNoisy confusions."""
    off = sum(n for p, row in confusion.items() for a, n in row.items() if p != a)
    pair = confusion.get("Nominal", {}).get("SensorNoisy", 0) + confusion.get(
        "SensorNoisy", {}
    ).get("Nominal", 0)
    return float(pair / off) if off else float("nan")


def score_regime_fit(fit: HmmFit, regimes: Any) -> dict[str, Any]:
    """Map the states of ``fit`` to ``regimes`` (Hungarian on the Viterbi path) and score it.

    Parameters
    ----------
    fit : HmmFit
        A fit to the fault features.
    regimes : array of str, shape (T,)
        Scheduled regime of every sample.

    Returns
    -------
    dict
        ``mapping`` (state label → regime), ``contingency`` (state × regime counts),
        ``accuracy``, ``macro_f1``, ``kappa``, ``confusion`` (predicted → actual → count),
        ``per_class``, ``nominal_sensor_share`` (share of the errors that are Nominal ↔
        SensorNoisy), ``restarts`` (per EM start: log-likelihood, status, the scores of its
        own Viterbi path mapped by its own Hungarian assignment, and ``agreement_with_best``,
        the share of samples whose mapped regime equals the best start's) and
        ``restart_accuracy`` (min, max, mean, sd over the usable starts).
    """
    regimes = np.asarray(regimes, dtype=str)
    mapping = _map_states(fit.viterbi, regimes, fit.n_states)
    record = _scores_record(mapping.predicted, regimes)
    rows = []
    for i, row in enumerate(fit.restarts.to_dict(orient="records")):
        path = fit.restart_viterbi[i]
        entry = {key: row[key] for key in ("restart", "seed", "log_likelihood", "n_iter", "status")}
        if path.min() < 0:
            entry.update(accuracy=None, macro_f1=None, kappa=None, agreement_with_best=None)
        else:
            own = _map_states(path, regimes, fit.n_states)
            scores = classification_scores(own.predicted, regimes, labels=REGIMES)
            entry.update(
                accuracy=scores.accuracy,
                macro_f1=scores.macro_f1,
                kappa=scores.kappa,
                agreement_with_best=float(np.mean(own.predicted == mapping.predicted)),
            )
        rows.append(entry)
    accuracies = np.array([r["accuracy"] for r in rows if r["accuracy"] is not None])
    return {
        "mapping": {f"S{state}": regime for state, regime in mapping.mapping.items()},
        "contingency": {
            f"S{state}": counts for state, counts in mapping.contingency.to_dict("index").items()
        },
        **record,
        "nominal_sensor_share": _nominal_sensor_share(record["confusion"]),
        "restarts": rows,
        "restart_accuracy": {
            "n_usable": int(accuracies.size),
            "min": float(accuracies.min()),
            "max": float(accuracies.max()),
            "mean": float(accuracies.mean()),
            "sd": float(accuracies.std(ddof=1)) if accuracies.size > 1 else 0.0,
        },
    }


@dataclass(frozen=True)
class FaultScenario:
    """Result of :func:`run_fault_scenario` (the configured drift origin's tables).

    Attributes
    ----------
    surrogate : DataFrame
        Faulted surrogate streams: ``t``, ``regime``, ``u_cmd``, ``u_act``, ``x``, ``v``,
        ``y_A``, ``y_B``, ``y_fused``, ``z``.
    residuals : DataFrame
        ``t``, ``regime``, ``e0 … e4``: faulted surrogate − physics.
    states : DataFrame
        :func:`dtwin.stages.regimes.states_table` with ``regime``: Viterbi state (1 … K),
        smoothed ``gamma_S*`` and filtered ``filtered_S*`` state posteriors.
    posteriors : DataFrame
        :data:`POSTERIOR_COLUMNS`: Viterbi ``state``, its Hungarian-mapped regime and the
        smoothed posteriors summed per mapped regime, renormalised per row.
    summary : dict
        ``drift_origin`` (the configured one), ``model`` (:func:`hmm_summary`) and
        ``origins``: :func:`score_regime_fit` per drift origin, each with its own
        ``model`` summary.
    """

    surrogate: pd.DataFrame
    residuals: pd.DataFrame
    states: pd.DataFrame
    posteriors: pd.DataFrame
    summary: dict[str, Any]


def _map_states(path: np.ndarray, regimes: np.ndarray, n_states: int) -> StateMapping:
    """Hungarian map of a 0-based state path (labelled 1 … K) onto the schedule's regimes."""
    states = list(range(1, n_states + 1))
    return hungarian_map(path + 1, regimes, all_states=states, all_regimes=REGIMES)


def _regime_posteriors(states: pd.DataFrame, fit: HmmFit) -> pd.DataFrame:
    state_mapping = _map_states(fit.viterbi, states["regime"].to_numpy(dtype=str), fit.n_states)
    regime_gamma = mapped_posteriors(fit.smoothed, state_mapping)
    table = states[["t", "regime", "state"]].copy()
    table["mapped_regime"] = state_mapping.predicted
    for regime in REGIMES:
        table[f"p_{regime}"] = regime_gamma[regime].to_numpy()
    return table[list(POSTERIOR_COLUMNS)]


def run_fault_scenario(
    physics: pd.DataFrame,
    surrogate: pd.DataFrame,
    faults: Mapping[str, Any],
    hmm: Mapping[str, Any],
    twin: TwinParams | Mapping[str, Any],
    *,
    both_origins: bool = True,
) -> FaultScenario:
    """Run the fault scenario of paper §4.4 for both drift origins (or the configured one).

    Parameters
    ----------
    physics, surrogate : DataFrame
        The twin stage's physics and (unfaulted) surrogate tables (``t`` and the signals).
    faults : mapping
        The ``faults`` section: ``schedule``, ``magnitudes``, ``drift_origin``, ``seed``.
    hmm : mapping
        The ``hmm`` section; both origins use the same EM starts (seed stream ``fault_fit``).
    twin : TwinParams or mapping
        ``dt`` and :data:`dtwin.params.ALGEBRAIC_SECTIONS` of the ``twin`` section.
    both_origins : bool, default True
        Score the other drift origin beside the configured one (False: the configured one
        only, half the cost; the tables are the same either way).

    Returns
    -------
    FaultScenario
    """
    twin = twin_params_from_mapping(twin, require_all=False, required=ALGEBRAIC_SECTIONS)
    configured = faults["drift_origin"]
    origins = [configured, *(o for o in DRIFT_ORIGINS if o != configured and both_origins)]
    summary: dict[str, Any] = {"drift_origin": configured, "origins": {}}
    for origin in origins:
        faulted, residuals = inject_scenario(physics, surrogate, faults, twin, origin)
        scaled, fit = fit_regimes(regime_features(residuals), hmm, "fault_fit")
        scores = score_regime_fit(fit, residuals["regime"])
        summary["origins"][origin] = {"model": hmm_summary(fit, scaled), **scores}
        if origin == configured:
            states = states_table(residuals["t"], fit, residuals["regime"])
            posteriors = _regime_posteriors(states, fit)
            tables = (faulted, residuals, states, posteriors)
    summary["model"] = summary["origins"][configured]["model"]
    faulted, residuals, states, posteriors = tables
    return FaultScenario(faulted, residuals, states, posteriors, summary)
