"""The paper's six-module twin (paper §3, Fig. 1) as a twin table.

Specification: docs/gap.md §Twin file. :func:`paper_table` builds from the sections of the
``twin:`` shape (``actuator``, ``plant``, ``sensor_A``, ``sensor_B``, ``fusion``, ``kpi``,
``noise``, ``dt``, ``discretisation``) the table

======  =======================  ==================  ==============  ====================
module  block                    inputs              outputs         params
======  =======================  ==================  ==============  ====================
M0      ``lag``                  ``u_cmd``           ``u_act``       ``tau``
M1      ``mass_spring_damper``   ``u_act``           ``x, v``        ``m, c, k``
M2a     ``lag``                  ``x``               ``y_A``         ``tau, bias``
M2b     ``lag``                  ``x``               ``y_B``         ``tau, bias``
M3      ``weighted_sum``         ``y_A, y_B``        ``y_fused``     ``w1 = alpha``,
                                                                     ``w2 = 1 − alpha``
M4      ``weighted_sum``         ``x, v``            ``z``           ``w1, w2``
======  =======================  ==================  ==============  ====================

with measurement noise ``sensor_A → y_A``, ``sensor_B → y_B`` (``noise``: white noise on the
sensors' readings, as the paper's simulator adds it) and process noise ``actuator → M0.y``,
``plant → M1.v`` (``process_noise``: the paper adds ``w_k`` to the lag's recursion and ``ξ_k``
(m/s²) to the plant's acceleration; levels converted to the table's in :func:`_process_noise`).
The ``discretisation`` of the ``twin:`` shape says how the modules step: ``euler`` (the paper
simulator's, which ``config/config.yaml`` and the generator's twin files declare) makes M1 an
``euler`` module and the lags M0, M2a, M2b ``zoh`` modules (a module's ``discretisation``,
:mod:`dtwin.twin.table`), so the table is the paper's simulator: ``x_k = x_{k−1} + dt·v_{k−1}``,
``v_k = v_{k−1} + dt·a_{k−1}`` and ``y_k = a·y_{k−1} + (1 − a)·u_{k−1}``, each module reading its
input one sample late (the plant bit for bit, the lags to rounding:
``tests/gap/test_table_euler.py``). Otherwise the modules are continuous: ``zoh`` or ``foh`` is kept
as the table's hold of the recorded inputs, ``bandlimited`` or a silent file becomes None (chosen
from data). M3's two weights are separate params of the table (a re-fit does not keep them summing
to 1). The package stays below :mod:`dtwin.params`: it takes plain sections, a mapping of mappings,
or any object with those attributes (a :class:`dtwin.params.TwinParams`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from dtwin.twin.paper_modules import EULER
from dtwin.twin.table import TwinTable, TwinTableError, table_from_mapping

__all__ = ["PAPER_NOISE_SIGNALS", "PAPER_PROCESS_NOISE_STATES", "paper_table"]

#: The ``noise`` section's sensor channels → the signal their measurement noise is added to (a
#: map of names, not a twin: the values are signals, never parameters).
PAPER_NOISE_SIGNALS: dict[str, str] = {"sensor_A": "y_A", "sensor_B": "y_B"}
#: Its process channels → the qualified state each disturbs (:func:`paper_table`).
PAPER_PROCESS_NOISE_STATES: dict[str, str] = {"actuator": "M0.y", "plant": "M1.v"}


def _get(owner: Any, name: str) -> Any:
    if isinstance(owner, Mapping):
        return owner.get(name)
    return getattr(owner, name, None)


def _value(sections: Any, section: str, field: str) -> Any:
    """``sections[section][field]``; a missing section or field refused in one line."""
    part = _get(sections, section)
    if part is None:
        raise TwinTableError("missing (the paper's chain needs every module's section)",
                             key=section, token=section)  # fmt: skip
    value = _get(part, field)
    if value is None:
        raise TwinTableError("missing", key=f"{section}.{field}", token=field)
    return value


def _paper_modules(sections: Any, steps: dict[str, str]) -> dict[str, dict[str, Any]]:
    def sensor(name: str, output: str) -> dict[str, Any]:
        params = {k: _value(sections, name, k) for k in ("tau", "bias")}
        return {"block": "lag", "inputs": ["x"], "outputs": [output], "params": params, **steps}

    alpha = _value(sections, "fusion", "alpha")
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)):
        raise TwinTableError(f"must be a number (got {alpha!r})", key="fusion.alpha",
                             token=str(alpha))  # fmt: skip
    return {
        "M0": {"block": "lag", "inputs": ["u_cmd"], "outputs": ["u_act"],
               "params": {"tau": _value(sections, "actuator", "tau")}, **steps},
        "M1": {"block": "mass_spring_damper", "inputs": ["u_act"], "outputs": ["x", "v"],
               "params": {k: _value(sections, "plant", k) for k in ("m", "c", "k")},
               **({"discretisation": "euler"} if steps else {})},
        "M2a": sensor("sensor_A", "y_A"),
        "M2b": sensor("sensor_B", "y_B"),
        "M3": {"block": "weighted_sum", "inputs": ["y_A", "y_B"], "outputs": ["y_fused"],
               "params": {"weights": [alpha, 1.0 - alpha]}},
        "M4": {"block": "weighted_sum", "inputs": ["x", "v"], "outputs": ["z"],
               "params": {"weights": [_value(sections, "kpi", k) for k in ("w1", "w2")]}},
    }  # fmt: skip


def _positive(value: Any, key: str, why: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise TwinTableError(f"must be a number > 0 (got {value!r}; {why})", key=key,
                             token=str(value))  # fmt: skip
    return float(value)


def _process_noise(sections: Any, noise: Any) -> dict[str, Any]:
    """Return the ``noise`` section's process channels as the table's ``process_noise``.

    The table's level is the standard deviation of a disturbance's integral over a sample, held
    over the sample in the state's derivative (docs/gap.md §Twin file). The paper adds ``ξ_k``
    (m/s²) to the plant's acceleration over an Euler step: held over the step, level ``ξ·dt``
    (m/s) on ``M1.v``. It adds ``w_k`` to the actuator lag's state after the lag's exact update,
    whereas a disturbance ``d`` held over a sample moves the lag by ``d·(1 − a)·τ/dt``
    (``a = exp(−dt/τ)``): level ``w·(dt/τ)/(1 − a)`` on ``M0.y``, the same per-sample increment.
    """
    levels = {c: _get(noise, c) for c in PAPER_PROCESS_NOISE_STATES if _get(noise, c) is not None}
    if not levels:
        return {}
    why = "the actuator's and the plant's noise are per sample"
    dt = _positive(_get(sections, "dt"), "dt", why)
    factors = {"plant": dt}
    if "actuator" in levels:
        steps = dt / _positive(_value(sections, "actuator", "tau"), "actuator.tau", why)
        factors["actuator"] = steps / -math.expm1(-steps)
    return {
        PAPER_PROCESS_NOISE_STATES[c]: _positive(v, f"noise.{c}", "a standard deviation")
        * factors[c]
        for c, v in levels.items()
    }


def paper_table(sections: Any) -> TwinTable:
    """Return the paper's six-module twin as a :class:`~dtwin.twin.table.TwinTable`.

    Parameters
    ----------
    sections : mapping or object
        The ``twin:`` sections (module docstring): ``actuator.tau``, ``plant.m/c/k``,
        ``sensor_A.tau/bias``, ``sensor_B.tau/bias``, ``fusion.alpha``, ``kpi.w1/w2``;
        optional ``noise`` (std devs by channel: ``actuator`` per sample, ``plant`` m/s²,
        ``sensor_A``/``sensor_B`` in the reading's units), ``dt`` (s, needed with
        ``noise.plant``) and ``discretisation`` (``euler``: the paper simulator's discrete
        modules; otherwise continuous ones, module docstring).

    Returns
    -------
    TwinTable
        Modules M0, M1, M2a, M2b, M3, M4 in that order.

    Raises
    ------
    TwinTableError
        A missing section or field, or a value the table refuses (``tau`` ≤ 0…).

    Examples
    --------
    >>> table = paper_table({"actuator": {"tau": 0.15}, "plant": {"m": 1.0, "c": 0.4, "k": 4.0},
    ...     "sensor_A": {"tau": 0.08, "bias": 0.0}, "sensor_B": {"tau": 0.25, "bias": 0.01},
    ...     "fusion": {"alpha": 0.6}, "kpi": {"w1": 1.0, "w2": 0.2}, "dt": 0.02})
    >>> [m.name for m in table.modules], table.exogenous, table.module("M3").params
    (['M0', 'M1', 'M2a', 'M2b', 'M3', 'M4'], ('u_cmd',), {'w1': 0.6, 'w2': 0.4})
    """
    noise = _get(sections, "noise")
    discretisation = _get(sections, "discretisation")
    steps = {"discretisation": "zoh"} if discretisation == EULER else {}
    mapping: dict[str, Any] = {"modules": _paper_modules(sections, steps)}
    if noise is not None:
        mapping["noise"] = {
            signal: _get(noise, channel)
            for channel, signal in PAPER_NOISE_SIGNALS.items()
            if _get(noise, channel) is not None
        }
        mapping["process_noise"] = _process_noise(sections, noise)
    if discretisation in ("zoh", "foh"):
        mapping["discretisation"] = discretisation
    return table_from_mapping(mapping, dt=_get(sections, "dt"))
