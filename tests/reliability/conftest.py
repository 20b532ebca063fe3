"""Environment for CLI subprocesses: the example plugin importable, a private cache."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from skelagnostic.plugins import LOAD_PLUGINS_ENV

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"
HERE = Path(__file__).resolve().parent


@pytest.fixture
def cli_env(tmp_path: Path) -> dict[str, str]:
    """Environment of ``python -m skelagnostic.cli`` with only the example plugin installed."""
    dist = tmp_path / "site" / "skelagnostic_example_aligner-0.1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: skelagnostic-example-aligner\nVersion: 0.1.0\n")
    (dist / "entry_points.txt").write_text(
        "[skelagnostic]\nexample = skelagnostic_example.plugin\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(dist.parent), str(EXAMPLE_SRC), str(REPO / "src"), str(HERE)])
    env[LOAD_PLUGINS_ENV] = "example"
    env["SKELAGNOSTIC_CACHE"] = str(tmp_path / "cache")
    env.pop("SKELAGNOSTIC_DEBUG", None)
    return env
