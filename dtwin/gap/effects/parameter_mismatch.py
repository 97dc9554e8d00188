"""``parameter_mismatch`` (every module): no new term, the module's own parameters are off.

Specification: docs/gap.md §Candidate effects, §Generator.

:data:`EFFECT` re-fits the module's linear parameters; :data:`CASE` is how the benchmark draws
it: one nominal parameter of the module offset or scaled in the asset.
"""

from __future__ import annotations

from typing import Any

from dtwin.gap.effects._base import PARAMETER_MISMATCH, Effect
from dtwin.gap.effects._case import CaseEffect, log_between
from dtwin.twin.paper_modules import CONTRACTS
from dtwin.twin.wiring import SENSOR, role_of

__all__ = ["EFFECT", "CASE"]


EFFECT = Effect(
    PARAMETER_MISMATCH,
    ("M0", "M1", "M2a", "M2b", "M3", "M4"),
    (),
    (),
    "linear",
    "the module's own linear parameters re-fitted (no new term)",
    lambda s: [],
    lambda s: [[]],
    lambda s: [],
    linear_form=True,
)


#: Per module: its twin section and the parameter(s) a ``parameter_mismatch`` may change (a
#: single name is taken without a random draw).
_MISMATCH_PARAMS = {
    name: (c.section, c.params[0] if len(c.params) == 1 else c.params)
    for name, c in CONTRACTS.items()
}


def _draw_mismatch(module, level, rng, scale) -> dict[str, Any]:
    """Return a ``parameter_mismatch``: one nominal parameter of ``module`` offset or scaled."""
    section, names = _MISMATCH_PARAMS[module]
    name = names if isinstance(names, str) else str(rng.choice(names))
    sign = 1 if rng.uniform() < 0.5 else -1
    if name == "bias":
        delta = sign * log_between(1.5, 10.0, level) * scale["sigma"]
        return {"form": "offset", "section": section, "param": name, "delta": delta}
    if name == "alpha":
        delta = sign * log_between(0.06, 0.35, level)
        return {"form": "offset", "section": section, "param": name, "delta": delta}
    low, high = (0.4, 2.0) if name == "tau" and role_of(module) == SENSOR else (0.15, 0.6)
    factor = (1 + log_between(low, high, level)) ** sign
    return {"form": "factor", "section": section, "param": name, "factor": factor}


def _apply_mismatch(asset: dict, nominal, true_effect: dict) -> None:
    """Change the asset's parameter named in a ``parameter_mismatch`` draw (in place).

    Also records the parameter's new ``value`` and its ``nominal`` one in ``true_effect``.
    """
    section, name = true_effect["section"], true_effect["param"]
    before = asset[section][name]
    if "factor" in true_effect:
        asset[section][name] = before * true_effect["factor"]
    else:
        asset[section][name] = before + true_effect["delta"]
        if name == "alpha":
            asset[section][name] = min(max(asset[section][name], 0.0), 1.0)
    true_effect["value"] = asset[section][name]
    true_effect["nominal"] = nominal[section][name]


def _mismatch_truth(spec, key, dt):
    """Return the changed parameter, its true value and its nominal one."""
    return spec["param"], spec["value"], spec["nominal"]


CASE = CaseEffect(PARAMETER_MISMATCH, _draw_mismatch, asset=_apply_mismatch, truth=_mismatch_truth)
