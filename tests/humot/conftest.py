"""HuMoT tests: the plugin package on sys.path and a plugin manager that has it registered."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

HUMOT_SRC = Path(__file__).resolve().parents[2] / "plugins" / "humot" / "src"
if str(HUMOT_SRC) not in sys.path:
    sys.path.insert(0, str(HUMOT_SRC))

#: A small network for fast tests (the paper's sizes are checked separately).
SMALL = {"dim": 32, "latent": 16, "blocks": 1, "heads": 4, "kernel_size": 3}


@pytest.fixture
def humot_pm():
    """A PluginManager with the built-in plugin and HuMoT (entry points not loaded)."""
    import skelagnostic_humot.plugin as plugin

    from skelagnostic.plugins import PluginManager

    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, "humot", version="0.1.0", source="skelagnostic-humot")
    return pm
