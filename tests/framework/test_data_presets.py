"""Dataset presets: roots from ``data.root`` or ``$SKELAGNOSTIC_DATA``, and their fixed test splits.

The files are written to ``tmp_path`` under the names the presets know (the
corpora in ``../shared/datasets`` are not read here).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from skelagnostic import procedural, write_bvh
from skelagnostic.data import (
    DATA_ROOT_ENV,
    MANN_DOG_TEST,
    PRESETS,
    Archive,
    DatasetPreset,
    dataset_root,
    preset_source,
)
from skelagnostic.errors import SkelagnosticError


def touch(root: Path, *names: str) -> None:
    """Empty files (listing and splitting clips reads no BVH)."""
    for name in names:
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(name.encode())


def split_of(source_root: Path, preset: str) -> dict[str, str | None]:
    src = preset_source(preset, source_root)
    return {Path(c.id).relative_to(source_root.resolve()).as_posix(): c.split for c in src.clips()}


def test_the_root_defaults_to_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    touch(tmp_path / "lafan1", "walk1_subject1.bvh")
    monkeypatch.setenv(DATA_ROOT_ENV, str(tmp_path))
    assert dataset_root("lafan1") == tmp_path / "lafan1"
    assert dataset_root("mann_dog", None) == tmp_path / "mann_dog"
    assert dataset_root("lafan1", "???") == tmp_path / "lafan1"  # an unset Hydra value
    assert dataset_root("lafan1", tmp_path / "mine") == tmp_path / "mine"  # data.root wins
    assert preset_source("lafan1").paths == [tmp_path / "lafan1"]
    monkeypatch.setenv("SA_TEST_DATA", str(tmp_path))
    monkeypatch.setenv(DATA_ROOT_ENV, "$SA_TEST_DATA")
    assert dataset_root("cmu") == tmp_path / "cmu"


def test_a_missing_root_says_how_to_set_one(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ROOT_ENV, raising=False)
    with pytest.raises(SkelagnosticError) as info:
        preset_source("mann_dog")
    message = str(info.value)
    assert "data.root=DIR" in message and f"{DATA_ROOT_ENV}=DIR" in message
    assert "mann_dog/" in message


def test_the_root_folder_must_exist(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DATA_ROOT_ENV, str(tmp_path))
    with pytest.raises(SkelagnosticError, match=re.escape(f"{tmp_path / 'bandai'}' does not")):
        preset_source("bandai")


def test_mann_dog_holds_out_its_five_clips_by_file_name(tmp_path: Path) -> None:
    near_misses = [
        "D1_004_KAN01_0011.bvh",  # a longer take number
        "xD1_004_KAN01_001.bvh",  # a prefix
        "D1_047_KAN01_001.bvh",  # a training clip
    ]
    touch(
        tmp_path,
        *(f"{name}.bvh" for name in MANN_DOG_TEST[1:]),
        *near_misses,
        f"MotionCapture/{MANN_DOG_TEST[0]}.bvh",
    )
    split = split_of(tmp_path, "mann_dog")
    assert split == {
        **{f"{name}.bvh": "test" for name in MANN_DOG_TEST[1:]},
        f"MotionCapture/{MANN_DOG_TEST[0]}.bvh": "test",  # in a subfolder too
        **dict.fromkeys(near_misses),
    }


def test_lafan1_holds_out_subject_5_by_file_name(tmp_path: Path) -> None:
    touch(
        tmp_path,
        "walk1_subject5.bvh",
        "aiming2_subject5.bvh",
        "walk1_subject1.bvh",
        "subject5/run1_subject2.bvh",
    )
    assert split_of(tmp_path, "lafan1") == {
        "walk1_subject5.bvh": "test",
        "aiming2_subject5.bvh": "test",
        "walk1_subject1.bvh": None,
        "subject5/run1_subject2.bvh": None,  # a folder name is no subject
    }


def test_split_pattern_joins_the_pattern_and_the_clip_list() -> None:
    assert DatasetPreset("x", "", "cm").split_pattern is None
    both = DatasetPreset("x", "", "cm", test_pattern=r"_holdout\.bvh$", test_clips=("a.b",))
    pattern = re.compile(both.split_pattern or "")
    assert pattern.search("/d/walk_holdout.bvh") and pattern.search("/d/a.b.bvh")
    assert pattern.search("C:\\d\\a.b.bvh")  # either separator
    assert not pattern.search("/d/axb.bvh")  # the dot is literal
    assert not pattern.search("/d/xa.b.bvh")
    only_clips = DatasetPreset("x", "", "cm", test_clips=("c1", "c2"))
    assert re.search(only_clips.split_pattern or "", "c2.bvh")


def test_archives_carry_a_well_formed_checksum() -> None:
    with pytest.raises(SkelagnosticError, match="64 lowercase hex digits"):
        Archive("https://example.invalid/a.zip", "ABC")
    lafan1 = PRESETS["lafan1"].archive
    assert lafan1 is not None and lafan1.size == 144051503
    assert {name for name, p in PRESETS.items() if p.archive} == {"lafan1"}


def test_a_mann_dog_run_records_the_fixed_test_clips(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fit_example
) -> None:
    names = [*MANN_DOG_TEST, "D1_047_KAN01_001", "D1_053_KAN01_001", "D1_ex01_KAN01_001"]
    (tmp_path / "data" / "mann_dog").mkdir(parents=True)
    for seed, name in enumerate(names):
        motion, _ = procedural.generate("quadruped", "trot", seconds=1.5, seed=seed)
        write_bvh(motion, tmp_path / "data" / "mann_dog" / f"{name}.bvh")
    monkeypatch.setenv(DATA_ROOT_ENV, str(tmp_path / "data"))  # data.root stays null
    run = fit_example(
        tmp_path,
        [
            "data=mann_dog",
            "experiment=smoke",
            "model.hidden=8",
            "model.latent=4",
            "data.window=16",
            "data.stride=8",
            "trainer.max_epochs=1",
            "threads=1",
        ],
    )
    clips = json.loads((run / "split.json").read_text())["clips"]
    by_name = {Path(clip).stem: part for clip, part in clips.items()}
    assert set(by_name) == set(names)
    assert sorted(n for n, part in by_name.items() if part == "test") == sorted(MANN_DOG_TEST)
    assert {by_name[n] for n in names[5:]} <= {"train", "val"}
    assert "train" in {by_name[n] for n in names[5:]}
