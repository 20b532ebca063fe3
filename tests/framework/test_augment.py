"""Augmentation of training windows (``data.augment.*``): mirror, yaw, speed change.

Each transform keeps the skeleton's bone lengths and moves the foot contacts as it
should (mirror: left and right swap; yaw: unchanged; speed: their timing scales by
the factor); a window's transform depends only on ``(seed, epoch, window index)``,
so it is the same with or without worker processes; validation windows are never
augmented; a bad ``data.augment`` value is refused naming its field.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch
from test_config_groups import SMALL
from torch.utils.data import DataLoader

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.analysis import foot_contacts
from skelagnostic.cli import app
from skelagnostic.cli.cache import info as cache_info
from skelagnostic.data import MotionDataModule, ProceduralSource
from skelagnostic.data.augment import (
    Augmentation,
    change_speed,
    plan_span,
    rotate_yaw,
)
from skelagnostic.data.loaders import ResumableSampler
from skelagnostic.errors import SkelagnosticError
from skelagnostic.plugins import get_plugin_manager
from skelagnostic.representations import GlobalPositions, RootLocalVelocities


def _walks() -> list[sa.Motion]:
    biped = procedural.generate("biped22", "walk", seconds=4.0, fps=30, seed=1)[0]
    dog = procedural.generate("quadruped", "trot", seconds=4.0, fps=30, seed=2)[0]
    return [biped.to_metres(), dog.to_metres()]


def _real(shared_data: Path) -> sa.Motion:
    motion = sa.read_bvh(shared_data / "human" / "xia_cmu" / "neutral_01_000.bvh")
    return motion.resample(30.0).to_metres()


def _bone_error(motion: sa.Motion) -> float:
    """Largest gap between a bone's length in the global positions and in the skeleton."""
    pos = motion.global_positions().double()
    sk = motion.skeleton
    parents = torch.tensor([max(p, 0) for p in sk.parents])
    lengths = (pos - pos[:, parents]).norm(dim=-1)[:, 1:]
    return float((lengths - sk.bone_lengths().double()[1:]).abs().max() / sk.height())


def _transforms(motion: sa.Motion) -> dict[str, sa.Motion]:
    return {
        "mirror": motion.mirror(),
        "yaw": rotate_yaw(motion, math.radians(130.0)),
        "faster": change_speed(motion, 1.25, int((motion.num_frames - 1) / 1.25)),
        "slower": change_speed(motion, 0.8, motion.num_frames),
    }


def test_every_transform_keeps_bone_lengths(shared_data: Path) -> None:
    for motion in [*_walks(), _real(shared_data)]:
        assert _bone_error(motion) < 1e-5
        for name, out in _transforms(motion).items():
            assert _bone_error(out) < 1e-5, name


def _swap(motion: sa.Motion, feet: list[int]) -> list[int]:
    mapping = motion.skeleton.mirror_map()
    return [feet.index(mapping[j]) for j in feet]


def test_mirror_swaps_left_and_right_contacts_frame_by_frame() -> None:
    for motion in _walks():
        contacts, feet = foot_contacts(motion)
        mirrored, mfeet = foot_contacts(motion.mirror())
        assert mfeet == feet and contacts.any() and (~contacts).any()
        swap = _swap(motion, feet)
        assert swap != list(range(len(feet)))  # left and right do swap
        assert torch.equal(mirrored, contacts[:, swap])


def test_yaw_keeps_contacts_and_turns_the_root_path() -> None:
    for motion in _walks():
        turned = rotate_yaw(motion, math.radians(90.0))
        assert torch.equal(foot_contacts(turned).contacts, foot_contacts(motion).contacts)
        up = motion.skeleton.up_index
        travel = motion.root_positions[-1] - motion.root_positions[0]
        turned_travel = turned.root_positions[-1] - turned.root_positions[0]
        assert torch.allclose(turned.root_positions[0], motion.root_positions[0])
        assert abs(float(turned_travel.norm() - travel.norm())) < 1e-4
        flat = [t.clone() for t in (travel, turned_travel)]
        for t in flat:
            t[up] = 0
        assert abs(float(torch.dot(flat[0], flat[1]))) < 1e-3 * float(flat[0].norm() ** 2)


def _transitions(contacts: torch.Tensor) -> list[tuple[int, int, bool]]:
    """``(foot, frame, now in contact)`` of every change of a foot's contact state."""
    change = contacts[1:] != contacts[:-1]
    return [(int(f), int(t) + 1, bool(contacts[t + 1, f])) for t, f in change.nonzero()]


@pytest.mark.parametrize("factor", [0.8, 1.25])
def test_speed_change_scales_the_contact_timing(factor: float, shared_data: Path) -> None:
    for motion in [*_walks(), _real(shared_data)]:
        frames = int((motion.num_frames - 1) / factor)
        fast = change_speed(motion, factor, frames)
        assert fast.num_frames == frames and fast.fps == motion.fps
        # same thresholds per source frame: the speeds scale by the factor
        source, feet = foot_contacts(motion[: math.ceil((frames - 1) * factor) + 1])
        speed = sa.analysis.CONTACT_SPEED * factor
        moved, _ = foot_contacts(fast, speed=speed, joints=feet)
        want, got = _transitions(source), _transitions(moved)
        assert len(got) >= 4 and abs(len(got) - len(want)) <= 2  # at most a flicker more
        errors = []  # output frames between a change and the source's change, scaled
        for foot, frame, state in got:
            near = [abs(frame - t / factor) for f, t, s in want if f == foot and s == state]
            errors.append(min(near))
        within = sum(e <= 1.0 for e in errors) / len(errors)
        assert within >= 0.9 and sorted(errors)[len(errors) // 2] <= 0.5, errors


def test_plan_span_fits_the_clip() -> None:
    assert plan_span(10, 100, 32, 1.0, 1) == (9, 33, 1, 1.0)
    first, count, lead, speed = plan_span(90, 100, 32, 1.25, 1)
    assert first + count <= 100 and lead == 1 and speed == 1.25 and count == 41
    assert plan_span(0, 100, 32, 1.25, 1)[:3] == (0, 40, 0)  # no frame before the clip
    first, count, lead, speed = plan_span(3, 40, 32, 1.25, 1)  # too short: slower, no lead
    assert (first, count, lead) == (0, 40, 0) and speed < 40 / 31
    motion = _walks()[0][:40]
    assert change_speed(motion, speed, 32).num_frames == 32


def _module(tmp_path: Path, augment: dict | None, **kwargs) -> MotionDataModule:
    source = ProceduralSource(
        kinds=["biped22", "quadruped"], gaits=["walk"], clips_per_gait=3, seconds=3.0
    )
    dm = MotionDataModule(
        source,
        window=16,
        stride=8,
        batch_size=4,
        cache_dir=tmp_path / "cache",
        augment=augment,
        **kwargs,
    )
    dm.prepare_data()
    dm.setup("fit")
    return dm


FULL = {"mirror": 0.5, "yaw": True, "speed": [0.8, 1.25]}


def _epoch(dm: MotionDataModule, epoch: int) -> dict[str, list[torch.Tensor]]:
    out: dict[str, list[torch.Tensor]] = {}
    for name, loader in dm.train_dataloader().iterables.items():
        loader.sampler.set_epoch(epoch)
        out[name] = [batch["features"] for batch in loader]
    return out


def test_same_augmentation_with_and_without_workers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PL_GLOBAL_SEED", "7")
    dm = _module(tmp_path, FULL)
    plain = _epoch(dm, 1)
    dm.num_workers = 2
    workers = _epoch(dm, 1)
    for name, batches in plain.items():
        assert len(batches) == len(workers[name]) > 0
        for a, b in zip(batches, workers[name], strict=True):
            assert torch.equal(a, b)
    other = _epoch(_module(tmp_path, FULL), 2)  # another epoch: other transforms
    assert any(not torch.equal(a, b) for a, b in zip(plain[name], other[name], strict=True))
    monkeypatch.setenv("PL_GLOBAL_SEED", "8")  # another seed: other transforms too
    assert any(
        not torch.equal(a, b)
        for a, b in zip(plain[name], _epoch(dm, 1)[name], strict=True)
        if a.shape == b.shape
    )


def test_a_window_gets_the_same_transform_on_every_rank(tmp_path: Path) -> None:
    dm = _module(tmp_path, FULL)
    ds = dm.datasets["train"]["procedural/biped22"]
    whole = {}
    for rank in (0, 1):
        sampler = ResumableSampler(ds, 2, rank, True, 3, keyed=True)
        sampler.set_epoch(4)
        keys = list(sampler)
        loader = DataLoader(ds, batch_size=None, sampler=keys, num_workers=rank * 2)
        for key, item in zip(keys, loader, strict=True):
            assert key[:2] == (3, 4)
            if key[2] in whole:  # padded shards repeat a window: the same transform
                assert torch.equal(whole[key[2]], item["features"])
            whole[key[2]] = item["features"]
    assert sorted(whole) == list(range(len(ds)))
    for index, features in whole.items():
        assert torch.equal(ds[(3, 4, index)]["features"], features)


def test_identity_draw_gives_the_cached_features(tmp_path: Path) -> None:
    for rep in (GlobalPositions(), RootLocalVelocities()):
        dm = _module(tmp_path, {"mirror": 1e-9}, representation=rep)
        for ds in dm.datasets["train"].values():
            augmenter = ds.augmenter
            for index in range(len(ds)):
                ds.augmenter = None
                cached = ds[index]["features"]
                ds.augmenter = augmenter
                fresh = ds[(0, 0, index)]["features"]
                assert fresh.shape == cached.shape
                scale = float(cached.abs().max())
                assert float((fresh - cached).abs().max()) <= 1e-4 * scale


def test_validation_windows_are_never_augmented(tmp_path: Path) -> None:
    dm = _module(tmp_path, FULL)
    plain = _module(tmp_path, None)
    assert all(ds.augmenter is not None for ds in dm.datasets["train"].values())
    assert all(ds.augmenter is None for ds in dm.datasets["val"].values())
    for a, b in zip(dm.val_dataloader(), plain.val_dataloader(), strict=True):
        for name in dm.dataset_names:
            if a[0][name] is not None:
                assert torch.equal(a[0][name]["features"], b[0][name]["features"])
    augmented = _epoch(dm, 0)
    assert any(
        not torch.equal(a, b)
        for name in augmented
        for a, b in zip(augmented[name], _epoch(plain, 0)[name], strict=True)
    )


def test_motion_entries_are_shared_by_representations(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a = _module(tmp_path, FULL)
    b = _module(tmp_path, FULL, representation=RootLocalVelocities())
    assert a.motion_entries and {e.array for e in a.motion_entries.values()} == {
        e.array for e in b.motion_entries.values()
    }
    assert not _module(tmp_path, None).motion_entries  # built only when augmenting
    cache_info(a.cache, verbose=True)
    listed = capsys.readouterr().out
    assert listed.count("(motion for augmentation)") == len(a.motion_entries)
    assert listed.count("windows)") == 2 * len(a.motion_entries)  # two representations


@pytest.mark.parametrize(
    ("augment", "message"),
    [
        ({"mirror": 1.5}, r"data\.augment\.mirror must be in \[0, 1\], got 1\.5"),
        ({"mirror": "often"}, r"data\.augment\.mirror must be a finite number"),
        ({"yaw": 270}, r"data\.augment\.yaw must be true, false or degrees in \[0, 180\]"),
        ({"speed": [1.25, 0.8]}, r"data\.augment\.speed=\[1\.25, 0\.8\]: need 0\.25 <= low"),
        ({"speed": [0.8]}, r"data\.augment\.speed must be \[low, high\]"),
        ({"speed": [0.8, math.nan]}, r"data\.augment\.speed must be a finite number"),
        ({"flip": 0.5}, r"data\.augment\.flip is not an augmentation option"),
    ],
)
def test_bad_augment_values_name_their_field(augment: dict, message: str) -> None:
    with pytest.raises(SkelagnosticError, match=message):
        Augmentation.parse(augment)


def test_augment_options_parse() -> None:
    assert not Augmentation.parse(None).enabled
    assert not Augmentation.parse({"mirror": 0.0, "yaw": False, "speed": None}).enabled
    assert Augmentation.parse({"yaw": True}).yaw == 180.0
    assert Augmentation.parse({"yaw": 30}).yaw == 30.0
    assert Augmentation.parse({"speed": 1.0}).speed is None
    draws = [Augmentation.parse(FULL).draw(0, 0, i) for i in range(400)]
    assert 0.4 < sum(d.mirror for d in draws) / 400 < 0.6
    assert all(0.8 <= d.speed <= 1.25 and abs(d.yaw) <= math.pi for d in draws)


def test_data_augment_from_the_config(example_plugin: Path, tmp_path: Path) -> None:
    pm = get_plugin_manager()
    base = ["model=example", "run_dir=/tmp/x", f"data.cache_dir={tmp_path}"]
    cfg = app.compose(base)
    assert dict(cfg.data.augment) == {"mirror": 0.0, "yaw": False, "speed": None}
    assert not app.build_datamodule(cfg, pm).augmentation.enabled
    cfg = app.compose([*base, "data.augment.mirror=0.5", "data.augment.speed=[0.8,1.25]"])
    assert app.build_datamodule(cfg, pm).augmentation == Augmentation(0.5, 0.0, (0.8, 1.25))
    cfg = app.compose([*base, "data.augment.yaw=200"])
    with pytest.raises(SkelagnosticError, match=r"data\.augment\.yaw must be"):
        app.build_datamodule(cfg, pm)


def test_data_modules_of_other_methods_refuse_augmentation() -> None:
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
    from skelagnostic_vqpae.data import VqpaeDataModule

    for cls, reason in ((VqpaeDataModule, "cached per-frame"), (PcmrlInterpDataModule, "rpa")):
        with pytest.raises(SkelagnosticError, match=rf"data\.augment: {cls.__name__} .*{reason}"):
            cls(augment={"mirror": 0.5})
        assert not cls(augment={"mirror": 0.0}).augmentation.enabled


def test_a_fit_trains_on_augmented_windows(example_plugin: Path, tmp_path: Path) -> None:
    cfg = app.compose(
        [
            "model=example",
            f"run_dir={tmp_path / 'run'}",
            f"data.cache_dir={tmp_path / 'cache'}",
            "threads=1",
            "callbacks=none",
            "data.augment.mirror=0.5",
            "data.augment.yaw=45",
            "data.augment.speed=[0.8,1.25]",
            *SMALL,
        ]
    )
    metrics = app.run(cfg)
    assert math.isfinite(metrics["train/loss"]) and math.isfinite(metrics["val/loss"])
    sidecars = (tmp_path / "cache" / "windows").glob("*/*.json")
    kinds = [json.loads(path.read_text()).get("kind") for path in sidecars]
    assert kinds.count("motion") >= 2  # the windows were cut from the cached motion


def test_data_modules_that_keep_the_base_datasets_augment(tmp_path: Path) -> None:
    from skelagnostic_humot.data import HumotDataModule
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule

    source = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=2, seconds=3.0)
    for cls in (HumotDataModule, PcmrlReconDataModule):
        dm = cls(source, cache_dir=tmp_path, augment=FULL)
        dm.prepare_data()
        dm.setup("fit")
        (train,) = dm.datasets["train"].values()
        assert train.augmenter is not None
        augmenter, train.augmenter = train.augmenter, None
        cached = train[0]["features"]
        train.augmenter = augmenter
        augmented = train[(0, 3, 0)]["features"]
        assert augmented.shape == cached.shape and not torch.equal(augmented, cached)
