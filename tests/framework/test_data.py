"""Data module: sources, presets, the window cache, splits by clip, multi-dataset batches."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.aligners import batch_skeleton
from skelagnostic.core.motion import reroot
from skelagnostic.data import (
    PRESETS,
    BVHSource,
    MotionDataModule,
    ProceduralSource,
    WindowCache,
    preset_source,
)
from skelagnostic.data.datamodule import _split_clips
from skelagnostic.data.sources import ClipRef
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import FirstFrameOffsetQuaternions, RootLocalVelocities


def small_source() -> ProceduralSource:
    return ProceduralSource(
        kinds=["biped22", "quadruped"], gaits=["walk"], clips_per_gait=3, seconds=2.0
    )


def test_procedural_source_is_in_metres_and_keyed_by_content() -> None:
    src = small_source()
    clips = src.clips()
    assert [c.id for c in clips][:3] == ["biped22_walk_0", "biped22_walk_1", "biped22_walk_2"]
    assert len({c.key for c in clips}) == len(clips)
    assert [c.key for c in clips] == [c.key for c in small_source().clips()]
    motion = src.load(clips[0])
    assert motion.units == "m" and 1.0 < motion.skeleton.height() < 2.5
    assert pickle.loads(pickle.dumps(src)).clips() == clips


def test_datamodule_batches_one_per_skeleton(tmp_path: Path) -> None:
    dm = MotionDataModule(small_source(), window=16, stride=8, batch_size=4, cache_dir=tmp_path)
    dm.prepare_data()
    dm.setup("fit")
    assert dm.dataset_names == ["procedural/biped22", "procedural/quadruped"]
    batch, _, _ = next(iter(dm.train_dataloader()))
    assert set(batch) == set(dm.dataset_names)
    biped = batch["procedural/biped22"]
    assert biped["features"].shape == (4, 16, 22, 3)
    assert biped["template"].shape == (4, 22, 3) and biped["height"].shape == (4,)
    assert batch["procedural/quadruped"]["features"].shape == (4, 16, 21, 3)
    rep = dm.representations["procedural/biped22"]
    assert rep.is_fitted and rep.mean.shape == (22, 3)
    assert set(dm.state_dict()) == set(dm.dataset_names)


def test_every_batch_carries_its_dataset_skeleton_and_fps(tmp_path: Path) -> None:
    """Train, validation and predict batches (workers too) carry ``skeleton`` and ``fps``."""
    dm = MotionDataModule(
        small_source(), window=16, stride=8, batch_size=4, num_workers=1, cache_dir=tmp_path
    )
    dm.prepare_data()
    dm.setup("fit")
    train, _, _ = next(iter(dm.train_dataloader()))
    val, _, _ = next(iter(dm.val_dataloader()))
    predict, _, _ = next(iter(dm.predict_dataloader()))
    for batch in (train, val, predict):
        for name, b in batch.items():
            assert batch_skeleton(b, name) == dm.skeletons[name]  # offsets too
            assert batch_skeleton(b).joint_names == dm.skeletons[name].joint_names
            assert b["fps"] == 30.0 and b["features"].shape[0] == 4
    assert set(train) == set(dm.dataset_names) and set(predict) == {dm.dataset_names[0]}
    with pytest.raises(SkelagnosticError, match="dataset 'mine' carries no 'skeleton'"):
        batch_skeleton({"features": train[dm.dataset_names[0]]["features"]}, "mine")


def test_split_is_by_clip_and_deterministic(tmp_path: Path) -> None:
    dm = MotionDataModule(
        small_source(),
        window=16,
        stride=8,
        val_fraction=0.34,
        test_fraction=0.3,
        cache_dir=tmp_path,
    )
    dm.setup()
    for name in dm.dataset_names:
        parts = [set(dm.datasets[s][name].clip_ids) for s in ("train", "val", "test")]
        assert all(parts)
        assert not (parts[0] & parts[1] or parts[0] & parts[2] or parts[1] & parts[2])
        assert sum(len(p) for p in parts) == 3
    again = MotionDataModule(
        small_source(),
        window=16,
        stride=8,
        val_fraction=0.34,
        test_fraction=0.3,
        cache_dir=tmp_path,
    )
    again.setup()
    assert (
        again.datasets["val"]["procedural/biped22"].clip_ids
        == dm.datasets["val"]["procedural/biped22"].clip_ids
    )


def test_split_rules() -> None:
    clips = [ClipRef(f"c{i}", str(i)) for i in range(10)] + [ClipRef("subject5", "x", "test")]
    split = _split_clips(clips, 0.2, 0.1, seed=0)
    assert [len(split[s]) for s in ("train", "val", "test")] == [7, 2, 2]
    assert split["test"][0].id == "subject5"
    assert {c.id for c in _split_clips(clips, 0.2, 0.1, seed=1)["val"]} != {
        c.id for c in split["val"]
    }
    single = _split_clips(clips[:1], 0.5, 0.0, seed=0)
    assert len(single["train"]) == 1 and not single["val"]


def test_cache_is_reused_and_keyed_by_preprocessing(tmp_path: Path, monkeypatch) -> None:
    src = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=2, seconds=2.0)
    MotionDataModule(src, window=16, cache_dir=tmp_path).prepare_data()
    files = sorted((tmp_path / "windows").rglob("*.npy"))
    assert len(files) == 2 and not list((tmp_path / "windows").rglob("*.tmp"))
    stamps = [f.stat().st_mtime_ns for f in files]

    def boom(self, clip):
        raise AssertionError("cached clip was loaded again")

    monkeypatch.setattr(ProceduralSource, "load", boom)
    MotionDataModule(src, window=16, cache_dir=tmp_path).prepare_data()
    assert [f.stat().st_mtime_ns for f in files] == stamps
    monkeypatch.undo()
    MotionDataModule(src, window=20, cache_dir=tmp_path).prepare_data()
    MotionDataModule(src, RootLocalVelocities(), window=16, cache_dir=tmp_path).prepare_data()
    assert len(list((tmp_path / "windows").rglob("*.npy"))) == 6


def test_cache_reads_are_memory_mapped(tmp_path: Path) -> None:
    cache = WindowCache(tmp_path)
    entry = cache.put("ab" * 32, np.ones((3, 4, 2, 1)), {"clip": "c", "starts": [0, 1, 2]})
    arr = cache.get("ab" * 32).open()
    assert isinstance(arr, np.memmap) and arr.dtype == np.float32 and entry.num_windows == 3
    assert cache.get("cd" * 32) is None


def test_window_dependent_representation(tmp_path: Path) -> None:
    src = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=2, seconds=2.0)
    dm = MotionDataModule(
        src, FirstFrameOffsetQuaternions(), window=8, stride=8, cache_dir=tmp_path, val_fraction=0.0
    )
    dm.setup()
    assert dm.dataset_names == ["procedural"]  # one topology: named after the source
    item = dm.datasets["train"]["procedural"][3]
    identity = torch.tensor([1.0, 0, 0, 0]).expand(22, 4)
    torch.testing.assert_close(item["features"][0, :, :4], identity)  # FOQ of each window


def test_datamodule_pickles_without_arrays(tmp_path: Path) -> None:
    dm = MotionDataModule(small_source(), window=16, cache_dir=tmp_path)
    dm.setup()
    ds = dm.datasets["train"]["procedural/biped22"]
    ds[0]
    windows = sum(e.array.stat().st_size for e in ds.entries)
    assert len(pickle.dumps(ds)) < windows / 2  # metadata only: windows stay in the files
    clone = pickle.loads(pickle.dumps(dm))
    torch.testing.assert_close(
        clone.datasets["train"]["procedural/biped22"][0]["features"], ds[0]["features"]
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"window": 0}, "data.window"),
        ({"batch_size": 0}, "data.batch_size"),
        ({"val_fraction": 0.6, "test_fraction": 0.5}, "data.val_fraction"),
    ],
)
def test_bad_arguments_name_the_field(kwargs, match: str) -> None:
    with pytest.raises(SkelagnosticError, match=match):
        MotionDataModule(small_source(), **kwargs)


def test_too_short_clips_are_reported(tmp_path: Path) -> None:
    src = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=1, seconds=0.5)
    with pytest.raises(SkelagnosticError, match=r"data\.window=64"):
        MotionDataModule(src, window=64, cache_dir=tmp_path).setup()


def test_bvh_source_errors(tmp_path: Path) -> None:
    with pytest.raises(SkelagnosticError, match="does not exist"):
        BVHSource([tmp_path / "missing"])
    with pytest.raises(SkelagnosticError, match="no file matches"):
        BVHSource([tmp_path])
    with pytest.raises(SkelagnosticError, match="unknown unit 'furlong'"):
        BVHSource([tmp_path], units="furlong")
    with pytest.raises(SkelagnosticError, match="unknown dataset preset"):
        preset_source("nope", tmp_path)


def test_reroot_keeps_global_motion() -> None:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30, seed=0)
    spine = motion.skeleton.joint_names[9]
    sub = reroot(motion, spine)
    assert sub.skeleton.joint_names[0] == spine and sub.skeleton.parents[0] == -1
    keep = [motion.skeleton.index(n) for n in sub.skeleton.joint_names]
    torch.testing.assert_close(sub.global_positions(), motion.global_positions()[:, keep])


@pytest.mark.data
def test_real_bvh_directories_group_by_topology(shared_data: Path, tmp_path: Path) -> None:
    src = BVHSource(
        [shared_data / "human" / "xia_cmu", shared_data / "dog" / "mann"],
        pattern="*_0*.bvh",
        units="cm",
    )
    dm = MotionDataModule(src, window=32, stride=32, fps=15, cache_dir=tmp_path)
    dm.setup()
    assert sorted(dm.dataset_names) == ["bvh/21j", "bvh/31j"]
    assert dm.skeletons["bvh/21j"].morphology == "quadruped"


@pytest.mark.data
def test_lafan1_preset_puts_subject5_in_test(shared_data: Path) -> None:
    src = preset_source("lafan1", shared_data / "human" / "lafan1")
    assert src.units == PRESETS["lafan1"].units == "cm"
    split = {c.id.rsplit("/", 1)[-1]: c.split for c in src.clips()}
    assert split["obstacles1_subject5.bvh"] == "test"
    assert split["walk4_subject1.bvh"] is None


def test_skeleton_with_only_test_clips_is_reported(tmp_path: Path) -> None:
    for seed in range(2):
        motion, _ = sa.procedural.generate("biped22", "walk", seconds=3.0, fps=30, seed=seed)
        sa.write_bvh(motion, tmp_path / f"held_out_{seed}.bvh")
    src = BVHSource([tmp_path], units="m", test_pattern="held_out")
    dm = MotionDataModule(src, window=16, stride=16, fps=30, cache_dir=tmp_path / "cache")
    with pytest.raises(SkelagnosticError, match=r"no training clip.*data\.test_pattern"):
        dm.setup()


def test_overfit_batches_repeats_the_same_training_batches(tmp_path: Path) -> None:
    """``Trainer(overfit_batches=N)`` works with the data module (the resumable loader did not)."""
    import lightning as L

    class Recorder(L.LightningModule):
        def __init__(self) -> None:
            super().__init__()
            self.weight = torch.nn.Parameter(torch.zeros(()))
            self.seen: list[torch.Tensor] = []

        def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
            features = batch["procedural/biped22"]["features"]
            self.seen.append(features.clone())
            return (self.weight - features.mean()) ** 2

        def configure_optimizers(self) -> torch.optim.Optimizer:
            return torch.optim.SGD(self.parameters(), lr=0.1)

    dm = MotionDataModule(small_source(), window=16, stride=8, batch_size=2, cache_dir=tmp_path)
    module = Recorder()
    trainer = L.Trainer(
        overfit_batches=2,
        max_epochs=3,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
    )
    trainer.fit(module, datamodule=dm)
    assert len(module.seen) == 6
    for epoch in (1, 2):
        for i in range(2):
            assert torch.equal(module.seen[2 * epoch + i], module.seen[i])
    assert not torch.equal(module.seen[0], module.seen[1])
