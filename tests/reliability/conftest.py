"""Environment for CLI subprocesses: the example plugin importable, a private cache."""

from __future__ import annotations

from pathlib import Path

import pytest
from reliability_env import EXAMPLE_SRC, plugin_env


@pytest.fixture
def cli_env(tmp_path: Path) -> dict[str, str]:
    """Environment of ``python -m skelagnostic.cli`` with only the example plugin installed."""
    return plugin_env(tmp_path, "example", "skelagnostic_example.plugin", EXAMPLE_SRC)
