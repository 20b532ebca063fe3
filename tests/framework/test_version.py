"""One version source: the installed distributions' metadata."""

from __future__ import annotations

import re
import sys
from importlib import metadata
from pathlib import Path

import pytest

import skelagnostic
from skelagnostic.plugins import PluginManager
from skelagnostic.version import UNKNOWN_VERSION, distribution_version

REPO = Path(__file__).resolve().parents[2]


def test_package_version_is_the_distribution_version() -> None:
    assert "__version__" in dir(skelagnostic)
    assert skelagnostic.__version__ == metadata.version("skelagnostic")


def test_no_source_file_spells_the_version() -> None:
    pyproject = (REPO / "pyproject.toml").read_text()
    (version,) = re.findall(r'^version = "([^"]+)"', pyproject, re.M)
    spelled = [
        p
        for p in [*REPO.glob("src/**/*.py"), *REPO.glob("plugins/*/src/**/*.py")]
        if re.search(rf"__version__\s*=\s*[\"']{re.escape(version)}[\"']", p.read_text())
    ]
    assert spelled == []


@pytest.mark.parametrize(
    "package", ["skelagnostic_humot", "skelagnostic_pcmrl", "skelagnostic_vqpae"]
)
def test_builtin_plugins_report_skelagnostic_version(package: str) -> None:
    module = pytest.importorskip(package)
    assert module.__version__ == metadata.version("skelagnostic")


def test_example_plugin_reports_its_own_distribution(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(REPO / "plugins" / "example-aligner" / "src"))
    sys.modules.pop("skelagnostic_example", None)
    import skelagnostic_example

    assert skelagnostic_example.__version__ == distribution_version("skelagnostic-example-aligner")


def test_missing_distribution_has_the_documented_fallback() -> None:
    assert distribution_version("skelagnostic-no-such-dist") == UNKNOWN_VERSION == "0+unknown"


def test_plugins_listing_shows_the_builtin_version() -> None:
    info = PluginManager(load_entrypoints=False).plugins()[0]
    assert (info.name, info.version) == ("skelagnostic", metadata.version("skelagnostic"))
