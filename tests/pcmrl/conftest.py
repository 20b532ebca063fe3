"""PC-MRL tests: the plugin package on sys.path and a plugin manager that has it registered."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

PCMRL_SRC = Path(__file__).resolve().parents[2] / "plugins" / "pcmrl" / "src"
if str(PCMRL_SRC) not in sys.path:
    sys.path.insert(0, str(PCMRL_SRC))

#: A small stage-1 network for fast tests (the paper's sizes are checked separately).
TINY = {"dim": 8, "stages": 2, "point_heads": 2, "temporal_dim": 16, "temporal_layers": 1,
        "temporal_heads": 2, "num_source_points": 64, "num_target_points": 128}


@pytest.fixture
def pcmrl_pm():
    """A PluginManager with the built-in plugin and PC-MRL (entry points not loaded)."""
    import skelagnostic_pcmrl.plugin as plugin

    from skelagnostic.plugins import PluginManager

    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, "pcmrl", version="0.1.0", source="skelagnostic-pcmrl")
    return pm
