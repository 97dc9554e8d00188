"""The packages' lazy re-exports (PEP 562, ``dtwin._lazy``): every name resolves, others fail."""

from __future__ import annotations

import importlib

import pytest

import dtwin
import dtwin.gapbench

PACKAGES = (dtwin, dtwin.gapbench)


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
