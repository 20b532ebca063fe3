"""skelagnostic.lazy: PEP 562 exports that import their module on first use."""

from __future__ import annotations

import sys
import types

import pytest

from skelagnostic.lazy import lazy_exports


@pytest.fixture
def package(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    module = types.ModuleType("lazy_demo")
    monkeypatch.setitem(sys.modules, "lazy_demo", module)
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    module.__getattr__, module.__dir__ = lazy_exports(  # type: ignore[method-assign]
        "lazy_demo", {"rgb_to_hsv": "colorsys", "missing": "colorsys"}
    )
    return module


def test_names_import_their_module_on_first_use_only(package):
    assert "colorsys" not in sys.modules
    assert "rgb_to_hsv" in dir(package) and "missing" in dir(package)
    assert package.rgb_to_hsv(1.0, 0.0, 0.0) == (0.0, 1.0, 1.0)
    assert "colorsys" in sys.modules
    assert vars(package)["rgb_to_hsv"] is sys.modules["colorsys"].rgb_to_hsv


def test_unknown_names_are_attribute_errors(package):
    with pytest.raises(AttributeError, match="module 'lazy_demo' has no attribute 'nope'"):
        _ = package.nope
    with pytest.raises(AttributeError, match="colorsys"):
        _ = package.missing  # listed, but the module does not define it
    assert not hasattr(package, "nope")
