"""Lazy package attributes (PEP 562), so that importing a package stays fast.

A method plugin's ``__init__`` names its public classes without importing the
torch-heavy modules that define them; the first access imports the module::

    from skelagnostic.lazy import lazy_exports

    __all__ = ["MyAligner", "MyDataModule"]
    __getattr__, __dir__ = lazy_exports(__name__, {
        "MyAligner": "my_plugin.aligner",
        "MyDataModule": "my_plugin.data",
    })

This module imports only the standard library.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, names: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Build a package's module-level ``__getattr__`` and ``__dir__`` for lazy names.

    Args:
        package: The package's ``__name__``.
        names: Public name -> the module that defines it under the same name.

    Returns:
        ``(__getattr__, __dir__)``: the first imports ``names[name]`` on first access
        and keeps the value in the package namespace (later accesses cost nothing);
        the second lists the lazy names beside the loaded ones.

    Examples:
        >>> import types, sys
        >>> pkg = sys.modules["demo_pkg"] = types.ModuleType("demo_pkg")
        >>> pkg.__getattr__, pkg.__dir__ = lazy_exports("demo_pkg", {"dumps": "json"})
        >>> pkg.dumps([1])
        '[1]'
        >>> "dumps" in vars(pkg)
        True
        >>> del sys.modules["demo_pkg"]
    """
    table = dict(names)

    def __getattr__(name: str) -> Any:
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(table[name]), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *table})

    return __getattr__, __dir__
