"""``ckpt=<scheme>:<path>``: checkpoints read by a plugin's ``register_checkpoint_readers``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from skelagnostic_example.aligner import ExampleAligner

from skelagnostic.plugins import PluginError, PluginManager, hookimpl


class _Reader:
    """Registers ``ckpt=toy:<path>`` (an ExampleAligner) and ``wrong:`` (returns a string)."""

    def __init__(self) -> None:
        self.paths: list[str] = []

    @hookimpl
    def register_aligners(self, register: Any) -> None:
        register("toy", ExampleAligner)

    @hookimpl
    def register_checkpoint_readers(self, register: Any) -> None:
        def read(path: str) -> ExampleAligner:
            """A toy model."""
            self.paths.append(path)
            return ExampleAligner()

        register("toy", read, model="toy")
        register("wrong", lambda path: "not an aligner", model="toy", description="broken")


@pytest.fixture
def pm() -> tuple[PluginManager, _Reader]:
    manager = PluginManager(load_entrypoints=False)
    reader = _Reader()
    manager.register(reader, "reader")
    return manager, reader


def test_a_registered_scheme_builds_the_model(pm: tuple[PluginManager, _Reader]) -> None:
    manager, reader = pm
    assert manager.checkpoint_readers["toy"].description == "A toy model."
    assert manager.checkpoint_readers["toy"].plugin == "reader"
    aligner = manager.read_external_checkpoint("toy:some/dir")
    assert isinstance(aligner, ExampleAligner) and not aligner.training
    assert reader.paths == ["some/dir"]
    assert manager.read_external_checkpoint("toy:x", model="toy") is not None
    info = next(p for p in manager.plugins() if p.name == "reader")
    assert "checkpoint reader:toy" in info.provides  # `skelagnostic plugins` lists it


def test_plain_paths_are_not_schemes(pm: tuple[PluginManager, _Reader], tmp_path: Path) -> None:
    manager, _ = pm
    for value in ("runs/last.ckpt", "C:/runs/last.ckpt", "s3://bucket/x.ckpt", "last"):
        assert manager.checkpoint_reader_of(value) is None
    existing = tmp_path / "toy:file.ckpt"
    existing.write_text("")
    assert manager.checkpoint_reader_of(str(existing)) is None
    assert manager.read_external_checkpoint("runs/last.ckpt") is None


def test_errors_name_the_scheme(pm: tuple[PluginManager, _Reader]) -> None:
    manager, _ = pm
    with pytest.raises(PluginError, match=r"no checkpoint reader 'other'.*toy: \(toy\)"):
        manager.checkpoint_reader_of("other:dir")
    with pytest.raises(PluginError, match="give the path after 'toy:'"):
        manager.checkpoint_reader_of("toy:")
    with pytest.raises(PluginError, match=r"is read as model=toy .* not model=humot"):
        manager.read_external_checkpoint("toy:dir", model="humot")
    with pytest.raises(PluginError, match="returned str, not the ExampleAligner"):
        manager.read_external_checkpoint("wrong:dir")


def test_bad_registrations_are_refused() -> None:
    class Bad:
        @hookimpl
        def register_checkpoint_readers(self, register: Any) -> None:
            register("A", lambda path: None, model="toy")

    manager = PluginManager(load_entrypoints=False)
    manager.register(Bad(), "bad")
    with pytest.warns(UserWarning, match="lower-case word"):
        assert "A" not in manager.checkpoint_readers
