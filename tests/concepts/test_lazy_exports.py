"""The packages' lazy re-exports (PEP 562, ``dtwin._lazy``): every name resolves, others fail."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import dtwin
import dtwin.gap
import dtwin.gapbench

PACKAGES = (dtwin, dtwin.gap, dtwin.gapbench)


def _fresh(code: str) -> str:
    """Run ``code`` in a fresh interpreter; return its stdout."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return done.stdout.strip()


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_every_re_export_is_its_modules_object(package):
    for name, module in package._EXPORTS.items():
        assert getattr(package, name) is getattr(importlib.import_module(module), name)
    assert set(package._EXPORTS) <= set(dir(package))
    assert package.__all__ == sorted(package._EXPORTS)


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_an_unknown_name_is_an_attribute_error_naming_the_package(package):
    with pytest.raises(AttributeError, match=f"module '{package.__name__}' has no attribute"):
        package.no_such_name  # noqa: B018


def test_the_gap_packages_diagnose_stays_the_function_once_its_module_is_imported():
    # importing dtwin.gap.diagnose binds the module on the package; the export must win
    out = _fresh(
        "import importlib, types, dtwin.gap\n"
        "module = importlib.import_module('dtwin.gap.diagnose')\n"
        "from dtwin.gap import diagnose\n"
        "print(type(diagnose).__name__, diagnose is module.diagnose, "
        "isinstance(dtwin.gap.diagnose, types.ModuleType))"
    )
    assert out == "function True False"


def test_the_table_diagnoser_and_the_parser_load_neither_the_paper_diagnoser_nor_scipy_signal():
    out = _fresh(
        "import sys, dtwin.gap.table_diagnose, dtwin.gap.table_report\n"
        "from dtwin.cli import build_parser\n"
        "build_parser()\n"
        "heavy = ('dtwin.gap.diagnose', 'dtwin.gap.which', 'scipy.signal', 'dtwin.gapbench')\n"
        "print([name for name in heavy if name in sys.modules])"
    )
    assert out == "[]"
