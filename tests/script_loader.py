"""Import a repository script (benchmarks/, scripts/, docs/hooks/) as a module in tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

#: The repository root.
REPO = Path(__file__).resolve().parents[1]


def load_script(relative: str, name: str) -> ModuleType:
    """The module of the script at ``REPO / relative``, registered as ``name``.

    Registering it in :data:`sys.modules` lets dataclasses and pickling inside the
    script find their module.
    """
    spec = importlib.util.spec_from_file_location(name, REPO / relative)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
