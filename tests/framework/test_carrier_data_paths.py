"""Every method's data path on a file whose static root carries the trajectory.

The same procedural walk is written twice: the ordinary export (the hips are the
root) and the Bandai-Namco / MotionBuilder layout (a static ``joint_Root`` at the
origin above the hips, six channels on every joint). Read through a
:class:`~skelagnostic.data.BVHSource`, both must give the same dataset items to
each method, and a training step must run on the carrier file.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import lightning as L
import pytest
import torch

import skelagnostic as sa
from skelagnostic.data import BVHSource

#: Items may differ by the BVH text's 6 decimals (centimetres) and float32 features.
ATOL = 1e-4


@pytest.fixture(scope="module")
def walks(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Directories holding the walk as an ordinary export and with a static carrier root."""
    root = tmp_path_factory.mktemp("walks")
    layouts = {"plain": {}, "carrier": {"root_carrier": "static", "channels": "all6"}}
    dirs = {}
    for name, layout in layouts.items():
        dirs[name] = root / name
        dirs[name].mkdir()
        motion, _ = sa.procedural.generate("biped22", "walk", 4.0, fps=30, seed=3, **layout)
        sa.write_bvh(motion, dirs[name] / "walk.bvh")
    assert sa.read_bvh(dirs["carrier"] / "walk.bvh").skeleton.body_root == 1
    return dirs


def _items(dm: L.LightningDataModule, count: int = 4) -> list[dict[str, Any]]:
    dm.prepare_data()
    dm.setup("fit")
    if hasattr(dm, "train_set"):  # PC-MRL interpolation: seeded random windows
        dataset = dm.train_set
    else:
        datasets = dm.datasets["train"]
        assert len(datasets) == 1
        dataset = next(iter(datasets.values()))
    return [dataset[i] for i in range(min(count, len(dataset)))]


def _assert_same_items(
    make: Callable[[Path, Path], L.LightningDataModule], walks: dict[str, Path], tmp_path: Path
) -> L.LightningDataModule:
    """The items ``make(dir, cache)`` gives on both layouts agree; returns the carrier's module."""
    plain = _items(make(walks["plain"], tmp_path / "plain"))
    carrier_dm = make(walks["carrier"], tmp_path / "carrier")
    carrier = _items(carrier_dm)
    assert len(carrier) == len(plain) > 0
    for a, b in zip(plain, carrier, strict=True):
        assert a.keys() == b.keys()
        for key, value in a.items():
            if isinstance(value, torch.Tensor):
                assert value.shape == b[key].shape, key
                got = b[key]
                if key == "offsets":
                    # the root's OFFSET is where the file put the hips (at export for the
                    # carrier): forward kinematics takes the root's position from the
                    # motion and no point or bone starts there, so only the bones compare
                    value, got = value[..., 1:, :], got[..., 1:, :]
                torch.testing.assert_close(got, value, atol=ATOL, rtol=0, msg=key)
            else:
                assert b[key] == value, key
    return carrier_dm


def _one_step(model: L.LightningModule, dm: L.LightningDataModule, tmp_path: Path) -> None:
    trainer = L.Trainer(
        max_steps=1,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
        num_sanity_val_steps=0,
        default_root_dir=tmp_path,
    )
    trainer.fit(model, datamodule=dm)
    assert trainer.global_step == 1
    loss = trainer.callback_metrics.get("train/loss")
    assert loss is not None and torch.isfinite(loss)


def test_humot(walks: dict[str, Path], tmp_path: Path, humot_small: dict[str, int]) -> None:
    from skelagnostic_humot.aligner import HumotAligner
    from skelagnostic_humot.data import HumotDataModule

    def make(path: Path, cache: Path) -> HumotDataModule:
        return HumotDataModule(
            [BVHSource([path], units="cm")], cache_dir=cache, val_fraction=0.0, batch_size=4
        )

    dm = _assert_same_items(make, walks, tmp_path)
    skeleton = next(iter(dm.skeletons.values()))
    assert skeleton.joint_names[0] == "Hips" and 1.3 < skeleton.height() < 1.7
    _one_step(HumotAligner(**humot_small), dm, tmp_path)


def test_pcmrl_interpolation(walks: dict[str, Path], tmp_path: Path) -> None:
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule

    def make(path: Path, cache: Path) -> PcmrlInterpDataModule:
        return PcmrlInterpDataModule(
            [BVHSource([path], units="cm")],
            fps=30,
            window=32,
            stride=16,
            batch_size=2,
            samples_per_epoch=4,
            val_fraction=0.0,
            cache_dir=cache,
        )

    dm = _assert_same_items(make, walks, tmp_path)
    torch.manual_seed(0)
    model = PcmrlInterpAligner(dim=16, heads=2, layers=1, ff_mult=2, max_relative=16)
    _one_step(model, dm, tmp_path)


def test_pcmrl_point_clouds(
    walks: dict[str, Path], tmp_path: Path, pcmrl_tiny: dict[str, int]
) -> None:
    """Stage 1: source windows, and the target hierarchy given as a carrier file."""
    from skelagnostic_pcmrl.points import sample_layout, zero_length_bones
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule, load_target_skeleton

    carrier_file = str(walks["carrier"] / "walk.bvh")
    plain_target, plain_units = load_target_skeleton(str(walks["plain"] / "walk.bvh"))
    target, units = load_target_skeleton(carrier_file)
    assert units == plain_units == "cm"
    assert target.joint_names == plain_target.joint_names
    torch.testing.assert_close(target.offsets[1:], plain_target.offsets[1:])
    clouds = [
        sample_layout(sk, 256, 0.01, generator=torch.Generator().manual_seed(0))
        for sk in (plain_target, target)
    ]
    assert torch.equal(clouds[0].tails, clouds[1].tails)
    torch.testing.assert_close(
        clouds[1].local(target.offsets), clouds[0].local(plain_target.offsets)
    )
    # read as it is, the carrier's link to the hips is no bone: no point lies on it
    raw = sa.read_bvh(carrier_file).skeleton
    assert 1 in zero_length_bones(raw)
    raw_cloud = sample_layout(raw, 256, 0.01, generator=torch.Generator().manual_seed(0))
    assert not bool((raw_cloud.tails == 1).any())

    def make(path: Path, cache: Path) -> PcmrlReconDataModule:
        return PcmrlReconDataModule(
            [BVHSource([path], units="cm")],
            target=str(path / "walk.bvh"),
            window=16,
            stride=16,
            batch_size=2,
            val_fraction=0.0,
            cache_dir=cache,
        )

    dm = _assert_same_items(make, walks, tmp_path)
    _one_step(PcmrlReconAligner(target=carrier_file, **pcmrl_tiny), dm, tmp_path)


def test_vqpae(walks: dict[str, Path], tmp_path: Path) -> None:
    from skelagnostic_vqpae.aligner import VqpaeAligner
    from skelagnostic_vqpae.data import VqpaeDataModule

    def make(path: Path, cache: Path) -> VqpaeDataModule:
        return VqpaeDataModule(
            BVHSource([path], units="cm"),
            fps=30,
            stride=8,
            batch_size=4,
            val_fraction=0.0,
            cache_dir=cache,
        )

    dm = _assert_same_items(make, walks, tmp_path)
    _one_step(VqpaeAligner(num_codes=8, kernel_size=7, pose_mlp="none"), dm, tmp_path)


def test_cli_inputs_drop_the_carrier(walks: dict[str, Path]) -> None:
    """``retarget``/``interpolate``/``transfer`` read their files through the same rule."""
    from skelagnostic.cli.infer import _read

    plain = _read(walks["plain"] / "walk.bvh", {})
    carrier = _read(walks["carrier"] / "walk.bvh", {"units": "cm"})
    assert carrier.skeleton.joint_names == plain.skeleton.joint_names
    assert carrier.units == "cm" and carrier.translations is None
    torch.testing.assert_close(
        carrier.global_positions(), plain.global_positions(), atol=1e-5, rtol=0
    )
