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
import warnings
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["deprecated_aliases", "lazy_exports"]


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


def deprecated_aliases(module: str, aliases: Mapping[str, str]) -> Callable[[str], Any]:
    """Build a module-level ``__getattr__`` that still serves the old names of renamed objects.

    Each access to an old name returns the renamed object and issues a
    :class:`DeprecationWarning` that names the new one, so code written against
    the old name keeps working while it is being updated.

    Args:
        module: The module's ``__name__``.
        aliases: Old name -> the current name of the object in ``module``.

    Returns:
        The module's ``__getattr__``.

    Examples:
        >>> import types, sys, warnings
        >>> mod = sys.modules["demo_mod"] = types.ModuleType("demo_mod")
        >>> mod.New = 42
        >>> mod.__getattr__ = deprecated_aliases("demo_mod", {"Old": "New"})
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     value = mod.Old
        >>> value, str(caught[0].message)
        (42, 'demo_mod.Old is deprecated; use demo_mod.New')
        >>> del sys.modules["demo_mod"]
    """
    table = dict(aliases)

    def __getattr__(name: str) -> Any:
        if name not in table:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(
            f"{module}.{name} is deprecated; use {module}.{table[name]}",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(sys.modules[module], table[name])

    return __getattr__
