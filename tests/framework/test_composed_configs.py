"""The configs ``skelagnostic fit`` composes for the shipped aligners do not change by accident.

``tests/fixtures/composed_configs/composed.json`` holds, for every built-in aligner and the
example plugin's, for each experiment and data preset the plugins ship, the config composed
before aligners registered their configs from one file (issue 49, item 5); its script
(``make.py`` beside it) writes it again when a config is meant to change.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from omegaconf import OmegaConf

from skelagnostic.cli import app
from skelagnostic.plugins import PluginManager

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "composed_configs"
EXPECTED: dict[str, Any] = json.loads((FIXTURE / "composed.json").read_text())


def _make_module() -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location("composed_configs_make", FIXTURE / "make.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MAKE = _make_module()


@pytest.fixture(scope="module")
def pm() -> PluginManager:
    """The built-in plugins and the example plugin, from the sources (as ``make.py`` builds it)."""
    return MAKE.plugin_manager()


def _flat(node: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted key, leaf value)`` pairs of a nested config."""
    if isinstance(node, dict) and node:
        for key, value in node.items():
            yield from _flat(value, f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix, node


def test_the_fixture_covers_every_aligner_and_shipped_preset(pm: PluginManager) -> None:
    assert sorted(MAKE.command_lines(pm)) == sorted(EXPECTED)


@pytest.mark.parametrize("key", sorted(EXPECTED))
def test_the_composed_config_is_unchanged(pm: PluginManager, key: str) -> None:
    overrides = MAKE.command_lines(pm)[key]
    cfg = app.compose([*overrides, f"run_dir={MAKE.RUN_DIR}"], plugin_manager=pm)
    got = dict(_flat(OmegaConf.to_container(cfg, resolve=True)))
    want = dict(_flat(EXPECTED[key]))
    changed = {
        k: (want.get(k, "<absent>"), got.get(k, "<absent>")) for k in want.keys() | got.keys()
    }
    assert {k: v for k, v in changed.items() if v[0] != v[1]} == {}
