"""Fixtures of the framework tests: fake plugin distributions on sys.path, fresh plugin managers."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

from skelagnostic.plugins import LOAD_PLUGINS_ENV, get_plugin_manager

REPO = Path(__file__).resolve().parents[2]
EXAMPLE_SRC = REPO / "plugins" / "example-aligner" / "src"
# Test modules import the example aligner's classes (the third-party plugin of the
# repository, not installed by the test command): importable before collection, so
# that does not depend on which test module another one put it on the path.
if str(EXAMPLE_SRC) not in sys.path:
    sys.path.append(str(EXAMPLE_SRC))


def write_dist(site: Path, name: str, version: str, entry_points: dict[str, str]) -> Path:
    """A minimal ``.dist-info`` that importlib.metadata finds when ``site`` is on sys.path."""
    dist = site / f"{name.replace('-', '_')}-{version}.dist-info"
    dist.mkdir(parents=True, exist_ok=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    lines = ["[skelagnostic]", *(f"{k} = {v}" for k, v in entry_points.items())]
    (dist / "entry_points.txt").write_text("\n".join(lines) + "\n")
    return dist


@pytest.fixture
def fake_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """An empty directory prepended to sys.path; the plugin manager is reset around the test."""
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delenv(LOAD_PLUGINS_ENV, raising=False)
    get_plugin_manager.cache_clear()
    yield site
    get_plugin_manager.cache_clear()


@pytest.fixture
def example_plugin(fake_site: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The example aligner installed as a (fake) distribution; only it is loaded."""
    monkeypatch.syspath_prepend(str(EXAMPLE_SRC))
    write_dist(
        fake_site,
        "skelagnostic-example-aligner",
        "0.1.0",
        {"example": "skelagnostic_example.plugin"},
    )
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "example")
    return fake_site


@pytest.fixture
def dist_writer() -> Callable[[Path, str, str, dict[str, str]], Path]:
    """:func:`write_dist`, for test modules (``from conftest import`` is ambiguous across dirs)."""
    return write_dist


@pytest.fixture
def add_plugin(fake_site: Path) -> Callable[[str, str], None]:
    """``add_plugin(name, source)``: a one-module plugin distribution named ``name``."""

    def add(name: str, source: str) -> None:
        module = f"fake_plugin_{name}"
        (fake_site / f"{module}.py").write_text(source)
        write_dist(fake_site, f"fake-{name}", "1.2.3", {name: module})
        sys.modules.pop(module, None)

    return add


@pytest.fixture
def subprocess_env(tmp_path: Path) -> dict[str, str]:
    """Environment for CLI subprocesses: the example plugin importable, a private cache."""
    site = tmp_path / "subsite"
    write_dist(
        site, "skelagnostic-example-aligner", "0.1.0", {"example": "skelagnostic_example.plugin"}
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(EXAMPLE_SRC), str(REPO / "src")])
    env[LOAD_PLUGINS_ENV] = "example"
    env["SKELAGNOSTIC_CACHE"] = str(tmp_path / "cache")
    env["OMP_NUM_THREADS"] = "1"
    env.pop("SKELAGNOSTIC_DEBUG", None)
    return env


@pytest.fixture(scope="session")
def fit_example() -> Callable[..., Path]:
    """``fit_example(root, overrides, task="fit")``: the example aligner in-process; its run dir.

    Trains it (``task="fit"``, into ``root/run``), or runs another verb such as
    ``task="evaluate"`` with ``ckpt_path=`` in ``overrides`` (into ``root/<task>``).
    The plugin comes from its sources through a private plugin manager, so it
    need not be installed; the run and its window cache live below ``root``.
    """

    def fit(root: Path, overrides: Sequence[str], task: str = "fit") -> Path:
        from skelagnostic.cli import app
        from skelagnostic.plugins import PluginManager

        sys.path.insert(0, str(EXAMPLE_SRC))
        try:
            import skelagnostic_example.plugin as plugin

            pm = PluginManager(load_entrypoints=False)
            pm.register(plugin, "example")
            run_dir = root / ("run" if task == "fit" else task)
            app.run(
                app.compose(
                    [
                        "model=example",
                        f"data.cache_dir={root / 'cache'}",
                        *overrides,
                        f"run_dir={run_dir}",
                    ],
                    task=task,
                    plugin_manager=pm,
                ),
                plugin_manager=pm,
            )
        finally:
            sys.path.remove(str(EXAMPLE_SRC))
        return run_dir

    return fit
