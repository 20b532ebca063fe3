"""Fixtures of the bad-input corpus: the example plugin as an installed distribution."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from skelagnostic.plugins import LOAD_PLUGINS_ENV, get_plugin_manager

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"


def write_dist(site: Path, name: str, entry_points: dict[str, str]) -> None:
    """A minimal ``.dist-info`` that importlib.metadata finds when ``site`` is on sys.path."""
    dist = site / f"{name.replace('-', '_')}-0.1.0.dist-info"
    dist.mkdir(parents=True, exist_ok=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    lines = ["[skelagnostic]", *(f"{k} = {v}" for k, v in entry_points.items())]
    (dist / "entry_points.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture
def site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A fake site directory holding the example plugin; only it is loaded."""
    site = tmp_path / "site"
    write_dist(site, "skelagnostic-example-aligner", {"example": "skelagnostic_example.plugin"})
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(EXAMPLE_SRC))
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example")
    monkeypatch.delenv("SKELAGNOSTIC_DEBUG", raising=False)
    get_plugin_manager.cache_clear()
    yield site
    get_plugin_manager.cache_clear()
    sys.modules.pop("broken_plugin", None)


@pytest.fixture
def broken_plugin(site: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A plugin distribution ``broken`` whose module raises on import, next to the example."""
    (site / "broken_plugin.py").write_text("raise RuntimeError('boom')\n")
    write_dist(site, "skelagnostic-broken", {"broken": "broken_plugin"})
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example,broken")
    return site


@pytest.fixture
def add_plugin(site: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., None]]:
    """``add_plugin(name, source, dist=None)``: a one-module plugin next to the example.

    The module ``fake_plugin_<name>`` holds ``source``; the distribution
    (``skelagnostic-<name>`` unless ``dist`` is given) declares the entry point
    ``name``, which is added to ``SKELAGNOSTIC_LOAD_PLUGINS``.
    """
    loaded = ["example"]
    modules: list[str] = []

    def add(name: str, source: str, dist: str | None = None) -> None:
        module = f"fake_plugin_{(dist or name).replace('-', '_')}"
        (site / f"{module}.py").write_text(source)
        write_dist(site, dist or f"skelagnostic-{name}", {name: module})
        sys.modules.pop(module, None)
        modules.append(module)
        loaded.append(name)
        monkeypatch.setenv(LOAD_PLUGINS_ENV, ",".join(loaded))
        get_plugin_manager.cache_clear()

    yield add
    for module in modules:
        sys.modules.pop(module, None)
