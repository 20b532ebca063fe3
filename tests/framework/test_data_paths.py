"""Path options as users write them: ``~``, ``$VARS``, one entry per character with its units."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest

from skelagnostic import cli
from skelagnostic.cli import app
from skelagnostic.core.paths import expand_home_in_override, expand_path
from skelagnostic.data.sources import bvh_sources
from skelagnostic.errors import SkelagnosticError
from skelagnostic.plugins import get_plugin_manager


@pytest.fixture
def home(tmp_path: Path, shared_data: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A home directory with ``mocap/human`` (two LaFAN1 clips, cm) and ``mocap/dog`` (cm)."""
    home = tmp_path / "home"
    human, dog = home / "mocap" / "human", home / "mocap" / "dog"
    human.mkdir(parents=True)
    dog.mkdir(parents=True)
    for clip in sorted((shared_data / "human" / "lafan1").glob("*.bvh"))[:2]:
        shutil.copy(clip, human / clip.name)
    for clip in sorted((shared_data / "dog").rglob("*.bvh"))[:2]:
        shutil.copy(clip, dog / clip.name)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("MOCAP", str(home / "mocap"))
    return home


def test_override_rewriting_only_touches_paths() -> None:
    h = str(Path.home())
    assert expand_home_in_override("data.paths=[~/a, ~/b]") == f"data.paths=[{h}/a, {h}/b]"
    assert expand_home_in_override("data.root=~") == f"data.root={h}"
    assert expand_home_in_override("data.paths=[{path: ~/d, units: cm}]") == (
        f"data.paths=[{{path: {h}/d, units: cm}}]"
    )
    for untouched in (
        "~trainer.max_time",
        "~data.cache_dir=null",
        "x='~/quoted'",
        "name=a~b",
        "data.paths=[/x/~y]",
    ):
        assert expand_home_in_override(untouched) == untouched


def test_expand_path_reads_home_and_variables(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("SA_TEST_ROOT", str(tmp_path))
    assert expand_path("${SA_TEST_ROOT}/x") == tmp_path / "x"
    assert expand_path("~/x") == Path.home() / "x"
    assert expand_path("$SA_TEST_UNSET_VARIABLE/x") == Path("$SA_TEST_UNSET_VARIABLE/x")


def test_documented_paths_forms_compose_and_load(
    example_plugin: Path, home: Path, tmp_path: Path
) -> None:
    pm = get_plugin_manager()
    for paths in (
        "data.paths=[~/mocap/human]",
        "data.paths=[$MOCAP/human]",
        "data.paths=['~/mocap/human']",
    ):
        cfg = app.compose(
            [
                "model=example",
                "data=bvh",
                paths,
                "data.units=cm",
                f"data.cache_dir={tmp_path / 'cache'}",
                f"run_dir={tmp_path}",
            ]
        )
        dm = app.build_datamodule(cfg, pm)
        files = [Path(c.id) for s in dm.sources for c in s.clips()]
        assert len(files) == 2 and all(f.parent == home / "mocap" / "human" for f in files)


def test_one_entry_per_character_with_its_units(
    example_plugin: Path, home: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    pm = get_plugin_manager()
    cfg = app.compose(
        [
            "model=example",
            "data=bvh",
            "data.window=8",
            "data.stride=8",
            "data.paths=[{path: ~/mocap/human, units: cm, name: human},"
            " {path: $MOCAP/dog, units: mm, name: dog}]",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"run_dir={tmp_path}",
        ]
    )
    dm = app.build_datamodule(cfg, pm)
    assert [s.name for s in dm.sources] == ["human", "dog"]
    with caplog.at_level(logging.INFO):
        dm.setup("fit")
    assert set(dm.dataset_names) == {"human", "dog"}
    human = dm.skeletons["human"].height()
    dog = dm.skeletons["dog"].height()
    assert 1.2 < human < 2.2  # cm -> m
    assert 0.03 < dog < 0.1  # the dog's cm read as mm: a 7 cm dog, and the log says so
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("data: ")]
    assert any(
        "'human': 2 clip(s)" in line and f"height {human:.2f} m" in line for line in lines
    ), lines
    assert any(
        line.startswith("data: dataset 'dog'") and f"height {dog:.2f} m" in line for line in lines
    ), lines


def test_unconverted_files_log_their_unit_guess(
    example_plugin: Path, home: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    cfg = app.compose(
        [
            "model=example",
            "data=bvh",
            "data.paths=[~/mocap/human]",
            "data.window=8",
            "data.stride=8",
            f"data.cache_dir={tmp_path / 'cache'}",
            f"run_dir={tmp_path}",
        ]
    )
    dm = app.build_datamodule(cfg, get_plugin_manager())
    with caplog.at_level(logging.INFO):
        dm.setup("fit")
    line = next(r.getMessage() for r in caplog.records if "dataset 'bvh'" in r.getMessage())
    assert "in the files' unit (not converted" in line and "suggests cm" in line


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"units": "cm"}, "data.paths[0]: give the entry a 'path' (or 'paths')"),
        ({"path": "/x", "unit": "cm"}, "data.paths[0].unit is not an option of a path entry"),
        (
            {"path": "/nonexistent/sa", "units": "cm"},
            "data.paths[0]: data.paths: '/nonexistent/sa' does not exist",
        ),
    ],
)
def test_bad_entries_name_the_entry(entry: dict, message: str) -> None:
    with pytest.raises(SkelagnosticError, match=None) as info:
        bvh_sources([entry])
    assert str(info.value).startswith(message)


def test_cli_fit_with_a_home_path(
    example_plugin: Path, home: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli.main(
        [
            "fit",
            "model=example",
            "experiment=smoke",
            "data=bvh",
            "data.paths=[~/mocap/human]",
            "data.units=cm",
            "data.window=8",
            "data.stride=8",
            "trainer.max_epochs=1",
            f"runs_dir={tmp_path / 'runs'}",
            f"data.cache_dir={tmp_path / 'cache'}",
        ]
    )
    assert code == 0, capsys.readouterr().err


def test_file_verbs_expand_paths(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from skelagnostic.cli.render import parse_arguments

    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("SA_CLIPS", "/clips")
    words, options = parse_arguments(
        ["~/a.bvh", "$SA_CLIPS/b.bvh", "out=~/o.bvh", "ckpt=$SA_CLIPS/x.ckpt", "labels=~a,b"]
    )
    assert words == [f"{tmp_path}/a.bvh", "/clips/b.bvh"]
    assert options == {"out": f"{tmp_path}/o.bvh", "ckpt": "/clips/x.ckpt", "labels": "~a,b"}


def test_other_units_never_reuse_cached_windows(home: Path, tmp_path: Path) -> None:
    from skelagnostic.data import MotionDataModule

    heights = []
    for units in ("cm", "mm"):
        sources = bvh_sources([{"path": home / "mocap" / "human", "units": units}])
        dm = MotionDataModule(sources, window=8, stride=8, cache_dir=tmp_path / "cache")
        dm.setup("fit")
        heights.append(next(iter(dm.skeletons.values())).height())
    assert heights[1] == pytest.approx(heights[0] / 10, rel=1e-5)
