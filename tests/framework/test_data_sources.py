"""Shared sources (MultiSource, MetresSource), the data-module hooks and **kwargs forwarding."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic.cli import app
from skelagnostic.data import (
    ClipRef,
    ClipSource,
    MetresSource,
    MotionDataModule,
    MultiSource,
    ProceduralSource,
    datamodule_options,
    flatten_sources,
)
from skelagnostic.errors import SkelagnosticError


class _Fixed(ClipSource):
    """One stick figure of a given height, in a given (maybe unknown) unit."""

    def __init__(self, height: float, units: str | None, name: str = "fixed") -> None:
        self.height, self.units, self.name = height, units, name

    def clips(self) -> list[ClipRef]:
        return [ClipRef("stick", f"{self.height}-{self.units}")]

    def load(self, clip: ClipRef) -> sa.Motion:
        sk = sa.Skeleton(
            ["hips", "spine", "head"],
            [-1, 0, 1],
            [[0, 0, 0], [0, self.height / 2, 0], [0, self.height / 2, 0]],
        )
        rot = torch.tensor([[1.0, 0, 0, 0]]).expand(4, 3, 4)
        return sa.Motion(sk, rot, torch.zeros(4, 3), 30, units=self.units)


def _procedural(name: str, kind: str) -> ProceduralSource:
    return ProceduralSource(kinds=[kind], gaits=["walk"], clips_per_gait=2, seconds=2.0, name=name)


@pytest.mark.parametrize(
    ("height", "units", "fallback", "metres"),
    [
        (175.0, "cm", "mm", 1.75),  # the clip's unit wins over the fallback
        (69.0, None, "inch", 69 * 0.0254),  # the fallback, not a guess (cm)
        (1750.0, None, None, 1.75),  # the guess: mm
    ],
)
def test_metres_source_converts_every_clip(height, units, fallback, metres) -> None:
    source = MetresSource(_Fixed(height, units), fallback)
    motion = source.load(source.clips()[0])
    assert motion.units == "m"
    assert motion.skeleton.height() == pytest.approx(metres)
    assert source.name == "fixed"
    assert source.loading()["fallback_units"] == fallback


def test_multi_source_prefixes_ids_and_loads_from_its_parts() -> None:
    multi = MultiSource([_Fixed(170.0, "cm", "human"), _Fixed(60.0, "cm", "dog")])
    ids = [c.id for c in multi.clips()]
    assert ids == ["human:stick", "dog:stick"]
    assert multi.load(multi.clips()[1]).skeleton.height() == pytest.approx(60.0)
    assert set(multi.loading()) == {"human", "dog"}
    with pytest.raises(SkelagnosticError, match="names no part"):
        multi.load(ClipRef("cat:stick", "k"))
    with pytest.raises(SkelagnosticError, match="must differ"):
        MultiSource([_Fixed(1.0, "m"), _Fixed(2.0, "m")])
    with pytest.raises(SkelagnosticError, match="at least one"):
        MultiSource([])


def test_any_data_module_makes_one_dataset_per_multi_source_part(tmp_path: Path) -> None:
    multi = MultiSource([_procedural("human", "biped22"), _procedural("dog", "quadruped")])
    assert [s.name for s in flatten_sources([multi, _procedural("x", "biped17")])] == [
        "human",
        "dog",
        "x",
    ]
    dm = MotionDataModule(
        multi, window=16, stride=16, val_fraction=0.0, cache_dir=tmp_path / "cache"
    )
    dm.setup("fit")
    assert dm.dataset_names == ["human", "dog"]
    assert dm.skeletons["dog"].morphology == "quadruped"


def test_hooks_are_public_and_overridable(tmp_path: Path) -> None:
    seen: list[str] = []

    class OnlyHumans(MotionDataModule):
        def add_dataset(self, name, members):
            seen.append(name)
            if name == "human":
                super().add_dataset(name, members)

    dm = OnlyHumans(
        [_procedural("human", "biped22"), _procedural("dog", "quadruped")],
        window=16,
        stride=16,
        val_fraction=0.5,
        cache_dir=tmp_path / "cache",
    )
    dm.setup("fit")
    assert seen == ["human", "dog"] and dm.dataset_names == ["human"]
    entry = dm.cache_entry(dm.sources[0], dm.sources[0].clips()[0])
    assert entry.num_windows > 0
    assert set(dm.loaders("val", shuffle=False)) == {"human"}


def test_plugin_data_modules_forward_the_base_options(tmp_path: Path) -> None:
    from skelagnostic_humot.data import HumotDataModule
    from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
    from skelagnostic_pcmrl.recon.data import PcmrlReconDataModule
    from skelagnostic_vqpae.data import VqpaeDataModule

    for cls in (HumotDataModule, VqpaeDataModule, PcmrlReconDataModule, PcmrlInterpDataModule):
        options = datamodule_options(cls)
        assert {"fps", "num_workers", "cache_dir", "split_seed", "test_fraction"} <= set(options)
        assert options["fps"] in (cls, MotionDataModule)
    assert datamodule_options(HumotDataModule)["window"] is HumotDataModule
    dm = HumotDataModule(num_workers=0, split_seed=7, cache_dir=tmp_path, batch_size=3)
    assert (dm.window, dm.stride, dm.split_seed, dm.batch_size) == (30, 6, 7, 3)
    with pytest.raises(TypeError, match="bogus"):
        HumotDataModule(bogus=1)
    with pytest.raises(SkelagnosticError, match="always per element"):
        VqpaeDataModule(per_element_stats=False)
    with pytest.raises(SkelagnosticError, match=r"data\.fps must be > 0"):
        PcmrlInterpDataModule(fps=0)


def test_cli_routes_base_options_through_kwargs(tmp_path: Path) -> None:
    pm = sa.plugins.get_plugin_manager()
    cfg = app.compose(
        [
            "model=humot",
            "run_dir=/tmp/x",
            "data.split_seed=5",
            "data.test_fraction=0.25",
            f"data.cache_dir={tmp_path}",
        ]
    )
    dm = app.build_datamodule(cfg, pm)
    assert (dm.split_seed, dm.test_fraction, dm.window) == (5, 0.25, 30)
    cfg = app.compose(["model=humot", "run_dir=/tmp/x", "data.test_fraction=abc"])
    with pytest.raises(app.ConfigError, match=r"data\.test_fraction='abc' has the wrong type"):
        app.build_datamodule(cfg, pm)


def test_procedural_test_clips_leave_the_other_clips_and_their_split_alone() -> None:
    # issue 48, item 6: the default data (data=procedural) gets a real test split
    options = {"kinds": ["biped22", "quadruped"], "clips_per_gait": 2, "seconds": 1.0}
    plain = ProceduralSource(**options).clips()
    source = ProceduralSource(**options, test_clips_per_gait=1)
    clips = source.clips()
    assert [c for c in clips if c.split is None] == plain  # same ids and content keys
    tested = [c for c in clips if c.split == "test"]
    assert len(tested) == 5  # one per kind and gait: biped walk/run, quadruped walk/trot/gallop
    assert not {c.id for c in tested} & {c.id for c in plain}
    assert not {c.key for c in tested} & {c.key for c in plain}  # other motions (seeds)
    before = MotionDataModule(val_fraction=0.2, test_fraction=0.0).split_clips(plain)
    after = MotionDataModule(val_fraction=0.2, test_fraction=0.0).split_clips(clips)
    assert after["train"] == before["train"] and after["val"] == before["val"]
    assert after["test"] == tested and source.load(tested[0]).num_frames > 0
    with pytest.raises(SkelagnosticError, match=r"data\.test_clips_per_gait=-1"):
        ProceduralSource(test_clips_per_gait=-1)
    cfg = app.compose(["model=vqpae", "run_dir=/tmp/x", "data=procedural"])
    assert cfg.data.test_clips_per_gait == 1 and cfg.data.test_fraction == 0.0
