"""The VQ-PAE data module: windows around pivots, z-score with a zero-variance guard, datasets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.data import (
    CachedFrameWindows,
    FrameWindows,
    MultiSource,
    VqpaeDataModule,
    human_dog_source,
)

from skelagnostic import Motion, procedural
from skelagnostic.data import ProceduralSource
from skelagnostic.data.sources import ClipRef, ClipSource
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import RootLocalVelocities


def _dm(cache_dir: Path, **kwargs: object) -> VqpaeDataModule:
    kwargs.setdefault("pair_seconds", 0.1)  # partner windows (the default is none)
    src = ProceduralSource(
        kinds=["biped22", "quadruped"], gaits=["walk"], clips_per_gait=2, seconds=2.0
    )
    dm = VqpaeDataModule(src, fps=20, batch_size=4, cache_dir=cache_dir, **kwargs)
    dm.prepare_data()
    dm.setup()
    return dm


def test_windows_are_centred_on_their_pivot() -> None:
    feats = torch.arange(30.0).view(15, 2)
    poses = torch.arange(15.0).view(15, 1)
    ds = FrameWindows(feats, poses, [(0, 9), (9, 15)], window=5, stride=1)
    assert len(ds) == (9 - 4) + (6 - 4)
    batch = ds.__getitems__([0, 5, 6])
    assert batch["features"].shape == (3, 2, 5)
    assert batch["pivot"].tolist() == [2, 2, 3]
    assert batch["clip"].tolist() == [0, 1, 1]
    # pivot frame sits in the middle; a window never crosses a clip boundary
    assert batch["poses"][:, 2, 0].tolist() == [2.0, 11.0, 12.0]
    assert batch["poses"][1, :, 0].tolist() == [9.0, 10.0, 11.0, 12.0, 13.0]
    single = ds[5]
    assert torch.equal(single["features"], batch["features"][1])


def test_partner_windows_stay_inside_their_clip() -> None:
    feats = torch.arange(46.0).view(23, 2)
    poses = torch.arange(23.0).view(23, 1)
    # 9 frames (5 windows), 6 (2 windows), 5 (1 window), 3 (too short for a window)
    ds = FrameWindows(
        feats, poses, [(0, 9), (9, 15), (15, 20), (20, 23)], window=5, stride=1, pair_shift=2
    )
    batch = ds.__getitems__(list(range(len(ds))))
    # later partner while it fits in the clip, else the earlier one
    assert batch["shift"].tolist() == [2, 2, 2, -2, -2, 0, 0, 0]
    starts = batch["features"][:, 0, 0] / 2  # feature (f, 0) = 2 f: the first frame
    partner = batch["shifted"][:, 0, 0] / 2
    assert (partner - starts).tolist() == [2, 2, 2, -2, -2, 0, 0, 0]
    assert "shifted" not in FrameWindows(feats, poses, [(0, 9)], 5, 1).__getitems__([0])
    plain = ds.gather([0, 1])  # what embedding and evaluation read: no partner gathered
    assert "shifted" not in plain and "shift" not in plain
    assert torch.equal(plain["features"], batch["features"][:2])
    with pytest.raises(SkelagnosticError, match="pair_shift"):
        FrameWindows(feats, poses, [(0, 9)], 5, 1, pair_shift=-1)


def test_only_training_windows_carry_partners(cache_dir: Path) -> None:
    dm = _dm(cache_dir)
    assert dm.pair_shift == 2  # 0.1 s at 20 fps
    train = next(iter(dm.train_dataloader()))[0]
    assert all(b["shifted"].shape == b["features"].shape for b in train.values())
    val = next(iter(dm.val_dataloader()))[0]
    assert all("shifted" not in b for b in val.values() if b is not None)
    assert _dm(cache_dir, pair_seconds=0.0).pair_shift == 0
    with pytest.raises(SkelagnosticError, match="pair_seconds"):
        VqpaeDataModule(pair_seconds=-1.0, cache_dir=cache_dir)


def test_one_second_windows_and_channels(cache_dir: Path) -> None:
    dm = _dm(cache_dir)
    assert dm.window == 21
    assert dm.dataset_names == ["procedural/biped22", "procedural/quadruped"]
    batch = next(iter(dm.train_dataloader()))[0]
    for name, b in batch.items():
        joints = dm.skeletons[name].num_joints
        assert b["features"].shape == (4, 3 * joints, 21)
        assert b["poses"].shape == (4, 21, 3 * joints)


def test_even_window_is_rejected(cache_dir: Path) -> None:
    with pytest.raises(SkelagnosticError, match=r"data\.window must be odd"):
        VqpaeDataModule(window=20, window_seconds=None, cache_dir=cache_dir)
    with pytest.raises(SkelagnosticError, match="window_seconds"):
        VqpaeDataModule(window_seconds=0.0, cache_dir=cache_dir)


def test_features_are_z_scored_per_channel(cache_dir: Path) -> None:
    dm = _dm(cache_dir, val_fraction=0.0)
    for name, ds in dm.datasets["train"].items():
        mean, std = ds.features.mean(0), ds.features.std(0, unbiased=False)
        varying = dm.representations[name].std.reshape(-1) != 1.0
        assert torch.allclose(mean, torch.zeros_like(mean), atol=1e-4)
        assert torch.allclose(std[varying], torch.ones_like(std[varying]), atol=1e-3)


class _ConstantChannel(ClipSource):
    """Procedural clips whose root is pinned, so its root-local velocity channels are constant."""

    name = "pinned"

    def __init__(self) -> None:
        self._clips = {
            f"c{i}": procedural.generate("biped22", "walk", seconds=2.0, fps=20, seed=i)[0]
            for i in range(2)
        }

    def clips(self) -> list[ClipRef]:
        return [ClipRef(k, f"pinned-{k}") for k in self._clips]

    def load(self, clip: ClipRef):  # type: ignore[no-untyped-def]
        m = self._clips[clip.id]
        root = torch.zeros_like(m.root_positions)
        root[:, 1] = m.root_positions[:, 1].mean()
        rotations = m.rotations.clone()
        rotations[:, 0] = m.rotations[0, 0]
        return Motion(m.skeleton, rotations, root, m.fps)


def test_zero_variance_channels_give_no_nan(cache_dir: Path) -> None:
    dm = VqpaeDataModule(
        _ConstantChannel(), fps=20, batch_size=4, cache_dir=cache_dir, val_fraction=0.0
    )
    dm.prepare_data()
    dm.setup()
    (name,) = dm.dataset_names
    raw = RootLocalVelocities().encode(_ConstantChannel().load(ClipRef("c0", "")))
    assert float(raw[:, 0].abs().max()) == 0.0  # the root's own channels are exactly constant
    std = dm.representations[name].std
    assert bool((std[0] == 1.0).all())
    ds = dm.datasets["train"][name]
    assert bool(torch.isfinite(ds.features).all())
    assert bool(torch.isfinite(ds.poses).all())


def test_multisource_gives_one_dataset_per_part(cache_dir: Path) -> None:
    a = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=1, seconds=2.0, name="a")
    b = ProceduralSource(kinds=["biped22"], gaits=["run"], clips_per_gait=1, seconds=2.0, name="b")
    dm = VqpaeDataModule(MultiSource([a, b]), fps=20, cache_dir=cache_dir, val_fraction=0.0)
    dm.prepare_data()
    dm.setup()
    assert dm.dataset_names == ["a", "b"]  # same topology, still two datasets
    with pytest.raises(SkelagnosticError, match="names must differ"):
        MultiSource([a, a])


@pytest.mark.data
def test_human_dog_source_on_the_shared_clips(shared_data: Path) -> None:
    src = human_dog_source(shared_data / "human" / "lafan1", shared_data / "dog" / "mann")
    names = {c.id.split(":")[0] for c in src.clips()}
    assert names == {"human", "dog"}
    dog = next(c for c in src.clips() if c.id.endswith("D1_010_KAN01_002.bvh"))
    motion = src.load(dog)
    assert motion.skeleton.num_joints == 21
    assert 0.2 < motion.skeleton.height() < 2.0  # converted to metres


def test_nearly_constant_channels_are_floored(cache_dir: Path) -> None:
    raw = _dm(cache_dir, val_fraction=0.0, std_floor=0.0)
    dm = _dm(cache_dir, val_fraction=0.0, std_floor=0.05)
    raised = False
    for name in dm.dataset_names:
        for got, ref in (
            (dm.representations[name], raw.representations[name]),
            (dm.pose_representations[name], raw.pose_representations[name]),
        ):
            want = torch.maximum(ref.std, 0.05 * ref.std.mean())
            assert torch.allclose(got.std, want)
            raised = raised or bool((got.std > ref.std).any())
    assert raised  # the floor does bite on these clips
    with pytest.raises(SkelagnosticError, match="std_floor"):
        VqpaeDataModule(std_floor=1.5, cache_dir=cache_dir)


def test_streamed_windows_and_statistics_match_the_in_memory_ones(cache_dir: Path) -> None:
    """Windows read from the cache per batch equal those of all frames held in memory."""
    dm = _dm(cache_dir, val_fraction=0.25)
    n_in = len(dm.representation.channels)
    for name in dm.dataset_names:
        train = dm.datasets["train"][name]
        assert isinstance(train, CachedFrameWindows)
        raw = {
            part: [torch.from_numpy(np.array(e.open()[0])) for e in ds.entries]
            for part, ds in ((p, dm.datasets[p][name]) for p in ("train", "val"))
        }
        # statistics over all training frames at once (the concatenating computation)
        every = torch.cat(raw["train"]).double()
        for rep, channels in (
            (dm.representations[name], slice(None, n_in)),
            (dm.pose_representations[name], slice(n_in, None)),
        ):
            values = every[..., channels]
            std = values.std(0, unbiased=False)
            std = torch.where(std < 1e-6, torch.ones_like(std), std)
            std = torch.maximum(std, 0.01 * std.mean())
            assert torch.allclose(rep.mean.double(), values.mean(0), atol=1e-5)
            assert torch.allclose(rep.std.double(), std, rtol=1e-5, atol=1e-6)
        rep, poses = dm.representations[name], dm.pose_representations[name]
        for part, ds in (("train", train), ("val", dm.datasets["val"][name])):
            lengths = np.cumsum([0] + [len(a) for a in raw[part]])
            held = FrameWindows(
                torch.cat([rep.normalize(a[..., :n_in]).flatten(1) for a in raw[part]]),
                torch.cat([poses.normalize(a[..., n_in:]).flatten(1) for a in raw[part]]),
                list(zip(lengths[:-1].tolist(), lengths[1:].tolist(), strict=True)),
                dm.window,
                dm.stride,
                ds.pair_shift,
            )
            assert len(held) == len(ds) > 0
            everything = list(range(len(ds)))
            want, got = held.__getitems__(everything), ds.__getitems__(everything)
            assert (
                set(want)
                == set(got)
                == (
                    {"features", "poses", "clip", "pivot"}
                    | ({"shifted", "shift"} if part == "train" else set())
                )
            )
            for key in want:
                assert torch.equal(want[key], got[key]), (name, part, key)
