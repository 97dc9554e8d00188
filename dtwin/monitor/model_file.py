"""``regimes.json``: the fitted regime model of a twin, everything ``dtwin monitor`` needs.

Specification: docs/monitor.md §regimes.json. :func:`regimes_file_mapping` writes a
:class:`~dtwin.monitor.batch_regimes.RegimesResult` as plain data (floats as Python prints
them, so they read back to the same bits); :func:`monitor_model_from_mapping` reads it back,
refusing a file that is not one (another schema, a missing or malformed key) or that belongs to
another twin (other units, signals or equations: :func:`dtwin.monitor.causal_twin.
frozen_units_from_mapping`) with one line.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from dtwin._validation import DtwinValueError
from dtwin.hmm import hmm_summary
from dtwin.monitor.action_table import ActionTable, action_table_from_mapping
from dtwin.monitor.causal_twin import FrozenUnit, frozen_units_from_mapping
from dtwin.monitor.regime_model import RegimeModel

__all__ = ["REGIMES_SCHEMA", "MonitorModel", "regimes_file_mapping", "monitor_model_from_mapping"]

#: The ``schema`` of ``regimes.json``.
REGIMES_SCHEMA = "dtwin.regimes/1"


@dataclass(frozen=True)
class MonitorModel:
    """What the monitor reads from ``regimes.json``.

    Attributes
    ----------
    dt : float
        Sample period, s.
    units : list of FrozenUnit
    model : RegimeModel
    actions : ActionTable or None
    hold : int
        Samples a change of regime must hold (the default of ``--hold``).
    settling : int
        Samples of the settling period.
    false_alarms : dict
        As ``dtwin regimes`` measured them (docs/monitor.md §False alarms).
    ranges : dict of str to (float, float)
        Each column's admitted range (:func:`dtwin.monitor.batch_regimes.column_ranges`).
    """

    dt: float
    units: list[FrozenUnit]
    model: RegimeModel
    actions: ActionTable | None
    hold: int
    settling: int
    false_alarms: dict[str, Any]
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)


def regimes_file_mapping(result) -> dict[str, Any]:
    """Return ``regimes.json``'s content for a ``RegimesResult`` (:mod:`.batch_regimes`)."""
    fit = result.regime_fit
    model = fit.model
    occupancy = dict(
        zip(model.labels, result.tracked.posteriors.mean(axis=0).tolist(), strict=True)
    )
    return {
        "schema": REGIMES_SCHEMA,
        "dt": result.dt,
        "columns": list(result.columns),
        "column_ranges": {name: list(r) for name, r in result.ranges.items()},
        "channels": list(result.channels),
        "dropped_channels": result.dropped,
        "settling": {"samples": result.settling, "seconds": result.settling * result.dt},
        "nominal_stretch": {
            "samples": list(result.rows),
            "seconds": [float(result.t[result.rows[0]]), float(result.t[result.rows[1] - 1])],
        },
        "twin": {"units": [u.to_mapping() for u in result.units]},
        "model": model.to_mapping(),
        "n_states": model.n_states,
        "k_chosen_by": "given" if fit.bic is None else "bic",
        "bic": None if fit.bic is None else fit.bic.to_dict(orient="records"),
        "bic_samples": fit.sweep_samples,
        "hmm": hmm_summary(fit.fit, fit.scaled),
        "filtered_occupancy": occupancy,
        "hold": result.hold,
        "false_alarms": result.false_alarms,
        "actions": None if result.actions is None else result.actions.to_mapping(),
        "action_per_regime": result.per_regime,
    }


def _require(raw: Mapping, key: str, kind) -> Any:
    if key not in raw or not isinstance(raw[key], kind):
        raise DtwinValueError(f"regimes file: {key} is missing or malformed")
    return raw[key]


def monitor_model_from_mapping(raw: Any, table, actions: ActionTable | None = None) -> MonitorModel:
    """Return the :class:`MonitorModel` of ``regimes.json``'s content, checked against ``table``.

    Parameters
    ----------
    raw : any
        The file's parsed JSON.
    table : dtwin.twin.table.TwinTable
        The twin being monitored.
    actions : ActionTable, optional
        Replaces the file's actions.

    Raises
    ------
    DtwinValueError
        One line: not a regimes file, malformed, or fitted for another twin.
    """
    if not isinstance(raw, Mapping) or raw.get("schema") != REGIMES_SCHEMA:
        raise DtwinValueError(f"regimes file: not a {REGIMES_SCHEMA} file (run dtwin regimes)")
    twin = _require(raw, "twin", Mapping)
    units = frozen_units_from_mapping(_require(twin, "units", list), table)
    model = RegimeModel.from_mapping(_require(raw, "model", Mapping))
    channels = [f"{u.name}:{s}" for u in units for s in u.outputs]
    foreign = [c for c in model.channels if c not in channels]
    if foreign:
        raise DtwinValueError(
            f"regimes file does not match the twin: model channel(s) {', '.join(foreign)} "
            f"(the twin's units give {', '.join(channels)})"
        )
    if actions is None and raw.get("actions") is not None:
        actions = action_table_from_mapping(raw["actions"])
    if actions is not None:
        actions.stacked(model.labels, model.nominal_mask)  # every regime has a matrix
    settling = max(u.settle for u in units)
    try:
        dt, hold = float(raw["dt"]), int(raw.get("hold", 10))
    except (KeyError, TypeError, ValueError) as error:
        raise DtwinValueError(f"regimes file: dt or hold is malformed ({error})") from error
    if not dt > 0 or hold < 1:
        raise DtwinValueError(f"regimes file: dt must be > 0 and hold >= 1 (got {dt}, {hold})")
    alarms = dict(raw.get("false_alarms") or {})
    return MonitorModel(dt, units, model, actions, hold, settling, alarms, _ranges(raw))


def _ranges(raw: Mapping) -> dict[str, tuple[float, float]]:
    entries = raw.get("column_ranges") or {}
    try:
        return {str(k): (float(v[0]), float(v[1])) for k, v in entries.items()}
    except (TypeError, ValueError, IndexError, AttributeError) as error:
        raise DtwinValueError(f"regimes file: column_ranges is malformed ({error})") from error
