"""Detection power of the gap diagnoser: the share of recordings in which an effect is named.

Specification: docs/gap.md §Detection power.

For each catalogue effect, recordings of the paper's asset (:func:`dtwin.gapbench.generator.
generate_case`, the default arm) are generated at a ladder of magnitudes (the generator's
``magnitude``, log-uniform in the effect's strength: 0 its faintest random case, 1 strong, below
0 extrapolated down to invisible) and diagnosed; every row keeps the
effect's signal-to-noise ratio (the key's ``snr``: RMS of the effect's contribution over its
module's noise floor), so the share named can be read against the magnitude in units of the
noise. Clean recordings (``none``) under the same conditions give the false-alarm rate.
:func:`detection_limits` reads, per effect, the signal-to-noise ratio at which the effect is
named in 50 % and 90 % of recordings.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from dtwin.proportions import wilson_interval

__all__ = ["POWER_COLUMNS", "INVALID", "power_row", "power_table", "detection_limits"]

#: ``answer`` of a row whose recording ran away (not finite: a strong softening spring); such
#: rows are left out of every table.
INVALID = "invalid_recording"

#: Columns of a power table (one row per diagnosed recording).
POWER_COLUMNS: tuple[str, ...] = (
    "effect",
    "level",
    "seed",
    "module",
    "snr",
    "answer_module",
    "answer",
    "named",
    "located",
    "gap_ratio",
    "max_ratio",
    "module_ratios",
    "cpu_s",
)


def power_row(
    effect: str,
    level: float | None,
    seed: int,
    *,
    nominal: Mapping[str, Any],
    diagnose_settings: Mapping[str, Any],
    n_samples: int,
) -> dict[str, Any]:
    """Generate one recording at ``level`` and diagnose it; return its row of the power table.

    Parameters
    ----------
    effect : str
        A case type: a catalogue effect of the default arm, or ``none`` of any arm
        (``[<arm>__]none``: the false alarms under that arm's conditions).
    level : float in [``MIN_MAGNITUDE``, 1] or None
        The generator's ``magnitude`` (None for a clean recording).
    seed : int
        The case's seed (every random draw of the recording).
    nominal : mapping
        The twin the asset is generated from (config ``twin``).
    diagnose_settings : mapping
        The ``gap.diagnose`` section (``train_frac``, ``calibrate`` and the decision constants).
    n_samples : int
        Length of the recording.

    Returns
    -------
    dict
        The :data:`POWER_COLUMNS`: ``named`` is whether the answer is one of the key's accepted
        effects in its module (for a clean recording: whether the answer is ``none``),
        ``located`` whether the module is the key's; ``gap_ratio`` the key's module's gap over
        its noise threshold (docs/gap.md §Where; NaN for a clean recording), ``max_ratio``
        the largest over the modules and ``module_ratios`` every module's
        (``M0=0.81;M1=0.64;…``): a module is flagged above 1, so the ratios show what a lower
        or higher threshold would flag.
    """
    import time

    from dtwin.gap import GapSettings, diagnose, twin_discretisation, twin_from_mapping
    from dtwin.gap.recording import recording_from_frame
    from dtwin.gapbench.generator import generate_case

    case = generate_case(effect, seed, magnitude=level, n_samples=n_samples, nominal=nominal)
    settings = dict(diagnose_settings)
    train_frac = settings.pop("train_frac")
    calibrate = bool(settings.pop("calibrate"))
    key = case.key
    if not np.isfinite(case.recording.drop(columns="t").to_numpy()).all():
        # a softening spring strong enough to run away: no recording to diagnose
        return {
            **dict.fromkeys(POWER_COLUMNS, float("nan")),
            "effect": effect,
            "level": float("nan") if level is None else float(level),
            "seed": int(seed),
            "module": key["module"],
            "answer": INVALID,
        }
    start = time.process_time()
    recording = recording_from_frame(case.recording)
    twin = twin_from_mapping(case.twin, dt=recording.dt)
    result = diagnose(
        recording,
        twin,
        calibrate=calibrate,
        train_frac=train_frac,
        settings=GapSettings.from_mapping(settings),
        discretisation=twin_discretisation(case.twin),
    )
    located = result.module == key["expected_module"]
    clean = key["expected_effect"] == "none"
    named = (
        result.effect == "none" if clean else located and result.effect in key["accepted_effects"]
    )
    ratios = {
        name: report.gap_calibrated / report.threshold
        for name, report in result.modules.items()
        if report.gap_calibrated is not None and report.threshold
    }
    return {
        "effect": effect,
        "level": float("nan") if level is None else float(level),
        "seed": int(seed),
        "module": key["module"],
        "snr": float("nan") if key["snr"] is None else float(key["snr"]),
        "answer_module": result.module,
        "answer": result.effect,
        "named": bool(named),
        "located": bool(located),
        "gap_ratio": ratios.get(key["expected_module"], float("nan")),
        "max_ratio": max(ratios.values(), default=float("nan")),
        "module_ratios": ";".join(f"{name}={value:.4f}" for name, value in ratios.items()),
        "cpu_s": round(time.process_time() - start, 2),
    }


def power_table(rows: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """Return the share named per effect and level, with its 95 % Wilson interval.

    Columns ``effect``, ``level``, ``n``, ``named``, ``share``, ``low``, ``high`` and
    ``snr_median`` (the median signal-to-noise ratio of the level's recordings).
    """
    table = pd.DataFrame(list(rows), columns=list(POWER_COLUMNS))
    table = table[table["answer"] != INVALID]
    out = []
    for (effect, level), group in table.groupby(["effect", "level"], dropna=False, sort=True):
        named, n = int(group["named"].sum()), len(group)
        low, high = wilson_interval(named, n)
        out.append(
            {
                "effect": effect,
                "level": level,
                "n": n,
                "named": named,
                "share": named / n,
                "low": low,
                "high": high,
                "snr_median": float(np.nanmedian(group["snr"])) if n else math.nan,
            }
        )
    return pd.DataFrame(out)


def detection_limits(rows: Sequence[Mapping[str, Any]], shares=(0.5, 0.9)) -> pd.DataFrame:
    """Return per effect the signal-to-noise ratio at which it is named in each share of cases.

    The share named is fitted as a logistic function of ``log(snr)`` (maximum likelihood over
    the recordings, Newton's method); the limit for a share ``p`` is where the fit reaches it.
    NaN where the fit does not rise (no limit inside the data: every recording named, or none).

    Parameters
    ----------
    rows : sequence of mapping
        Rows of :func:`power_row` (``effect``, ``snr``, ``named``); clean rows (``none`` of any
        arm) are skipped.
    shares : sequence of float, default (0.5, 0.9)

    Returns
    -------
    DataFrame
        ``effect``, ``n``, and ``snr_<100p>`` per share (e.g. ``snr_50``, ``snr_90``).

    Examples
    --------
    >>> snr = np.repeat([1.0, 2.0, 4.0, 8.0], 10)
    >>> named = np.r_[[0] * 10, [0] * 7 + [1] * 3, [1] * 8 + [0] * 2, [1] * 10]
    >>> rows = [{"effect": "e", "snr": s, "named": bool(k)} for s, k in zip(snr, named)]
    >>> round(float(detection_limits(rows)["snr_50"].iloc[0]), 1)
    2.6
    """
    table = pd.DataFrame(list(rows))
    if "answer" in table:
        table = table[table["answer"] != INVALID]
    out = []
    with_effect = ~table["effect"].str.endswith("none")
    for effect, group in table[with_effect].groupby("effect", sort=True):
        group = group[np.isfinite(group["snr"]) & (group["snr"] > 0)]
        named = group["named"].astype(bool)
        if named.all() or not named.any():  # no rise inside the data
            slope, intercept = math.nan, math.nan
        else:
            slope, intercept = _logistic_fit(np.log(group["snr"].to_numpy()), named)
        row: dict[str, Any] = {"effect": effect, "n": len(group)}
        for share in shares:
            logit = math.log(share / (1 - share))
            row[f"snr_{round(100 * share)}"] = (
                math.exp((logit - intercept) / slope) if slope > 0 else math.nan
            )
        out.append(row)
    return pd.DataFrame(out)


def _logistic_fit(x: np.ndarray, y) -> tuple[float, float]:
    """Return ``(slope, intercept)`` of ``P(y) = 1/(1 + exp(−(a·x + b)))`` by Newton's method.

    A ridge of 1e-6 keeps separable data finite (their slope is then large, the limit the
    boundary between the classes).
    """
    y = np.asarray(y, dtype=float)
    design = np.column_stack([x, np.ones_like(x)])
    beta = np.zeros(2)
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-(design @ beta)))
        gradient = design.T @ (y - p) - 1e-6 * beta
        hessian = design.T @ (design * (p * (1 - p))[:, None]) + 1e-6 * np.eye(2)
        step = np.linalg.solve(hessian, gradient)
        beta = beta + step
        if np.max(np.abs(step)) < 1e-10:
            break
    return float(beta[0]), float(beta[1])
