"""The motor family's twin as one module: the expression module and the test FMU's.

The motor benchmark family (:data:`dtwin.gapbench.family_assets.MOTOR`) writes its twin as two
expression modules, ``electrical`` (state ``i``) and ``mechanical`` (state ``w``), joined by
``i`` and ``w``. :func:`expression_twin` merges them into one module ``motor`` with the same
equations and params; :func:`fmu_twin` puts the test FMU (tests/twin/fmu/motor.c, the same
equations) in its place with the same params; :func:`write_fmu_case` writes a case's folder
for ``dtwin diagnose``. tests/twin/test_fmu.py and the ``fmu`` benchmark section
(benchmarks/fmu_case.py) diagnose generated cases against both.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from dtwin.gapbench.generator import GeneratedCase

__all__ = ["MODULE", "expression_twin", "fmu_twin", "write_fmu_case"]

#: The merged module's name.
MODULE = "motor"


def _merged(modules: Mapping[str, Mapping[str, Any]], recorded: tuple[str, ...]) -> dict:
    """Return the expression modules as one: inputs from outside, ``recorded`` outputs.

    Every module's outputs must be its states (as the motor's are); params keep their names
    (unique across the family's modules).
    """
    produced = [s for m in modules.values() for s in m["outputs"]]
    for name, module in modules.items():
        if "derivatives" not in module or set(module["outputs"]) - set(module["states"]):
            raise ValueError(f"module '{name}' must be an expression module whose outputs are "
                             f"states (got keys {', '.join(module)})")  # fmt: skip
    inputs = [s for m in modules.values() for s in m["inputs"] if s not in produced]
    return {
        "inputs": list(dict.fromkeys(inputs)),
        "outputs": [s for s in produced if s in recorded],
        "states": [s for m in modules.values() for s in m["states"]],
        "params": {k: v for m in modules.values() for k, v in m["params"].items()},
        "derivatives": {k: v for m in modules.values() for k, v in m["derivatives"].items()},
    }


def _recorded(case: GeneratedCase) -> tuple[str, ...]:
    """The case's recorded outputs: its columns after ``t`` and the input."""
    return tuple(case.key["columns"][2:])


def expression_twin(case: GeneratedCase) -> dict[str, Any]:
    """Return a motor case's twin file with its modules merged into one module ``motor``.

    Parameters
    ----------
    case : GeneratedCase
        A motor case (:func:`dtwin.gapbench.families.generate_family_case`); its twin file's
        ``dt`` and ``noise`` are kept; the module's outputs are the recorded ones (``w``, or
        ``i, w`` with the internal signal).
    """
    return {**case.twin, "modules": {MODULE: _merged(case.twin["modules"], _recorded(case))}}


def fmu_twin(
    case: GeneratedCase, fmu: str | Path, interface: str = "model_exchange"
) -> dict[str, Any]:
    """Return a motor case's twin file with the test FMU as its one module ``motor``.

    Parameters
    ----------
    case : GeneratedCase
        As :func:`expression_twin`.
    fmu : str or Path
        The FMU's path (relative to the twin file when written to one).
    interface : {"model_exchange", "co_simulation"}
        The FMU's interface to use.

    The FMU's variables carry the twin's names, so each mapping is signal → the same name.
    """
    merged = _merged(case.twin["modules"], _recorded(case))
    module = {
        "fmu": str(fmu),
        "interface": interface,
        "inputs": {s: s for s in merged["inputs"]},
        "outputs": {s: s for s in merged["outputs"]},
        "params": merged["params"],
    }
    return {**case.twin, "modules": {MODULE: module}}


def write_fmu_case(
    case: GeneratedCase, fmu: str | Path, folder: str | Path, interface: str = "model_exchange"
) -> Path:
    """Write a motor case for ``dtwin diagnose``; return the twin file's path.

    ``folder`` gets ``recording.csv`` (``t`` s, ``V`` V, the recorded outputs), ``twin.yaml``
    (:func:`fmu_twin`, the FMU's path relative to it) and ``models/motor.fmu`` (a copy of
    ``fmu``).
    """
    folder = Path(folder)
    (folder / "models").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(fmu, folder / "models" / "motor.fmu")
    case.recording.to_csv(folder / "recording.csv", index=False)
    twin = fmu_twin(case, "models/motor.fmu", interface)
    (folder / "twin.yaml").write_text(yaml.safe_dump(twin, sort_keys=False))
    return folder / "twin.yaml"
