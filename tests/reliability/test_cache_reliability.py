"""Window cache, issue 47: names per path (item 3)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

import skelagnostic as sa
from skelagnostic.data import BVHSource, MotionDataModule


def _module(paths: list[Path], cache: Path) -> MotionDataModule:
    return MotionDataModule(BVHSource(paths), window=8, stride=8, val_fraction=0.0, cache_dir=cache)


def _folder(folder: Path, biped: str) -> Path:
    """A folder of two skeletons: ``<biped>.bvh`` (22 joints) and ``dog.bvh``."""
    folder.mkdir()
    for kind, gait, name in (("biped22", "walk", biped), ("quadruped", "trot", "dog")):
        motion, _ = sa.procedural.generate(kind, gait, seconds=1.0, fps=30, seed=0)
        sa.write_bvh(motion, folder / f"{name}.bvh")
    return folder


def test_same_bytes_under_another_name_are_named_after_their_own_file(tmp_path: Path) -> None:
    a = _folder(tmp_path / "A", "alpha")
    b = tmp_path / "B"
    b.mkdir()
    shutil.copyfile(a / "alpha.bvh", b / "beta.bvh")  # the same bytes, another name
    shutil.copyfile(a / "dog.bvh", b / "dog.bvh")
    cache = tmp_path / "cache"
    first = _module([a], cache)
    first.setup()
    assert sorted(first.dataset_names) == ["bvh/alpha", "bvh/dog"]
    second = _module([b], cache)
    second.setup()
    # named after its own file, not after the cached one (was: bvh/alpha)
    assert sorted(second.dataset_names) == ["bvh/beta", "bvh/dog"]
    assert second.skeletons["bvh/beta"].name == "beta"
    assert second.datasets["train"]["bvh/beta"].clip_ids == [str((b / "beta.bvh").resolve())]
    assert second.datasets["train"]["bvh/dog"].clip_ids == [str((b / "dog.bvh").resolve())]
    # the windows are still shared: one entry per content
    assert len(list((cache / "windows").glob("*/*.npy"))) == 2
    np.testing.assert_array_equal(
        second.datasets["train"]["bvh/beta"][0]["features"].numpy(),
        first.datasets["train"]["bvh/alpha"][0]["features"].numpy(),
    )
    # and the first folder is still named after its files
    again = _module([a], cache)
    again.setup()
    assert sorted(again.dataset_names) == ["bvh/alpha", "bvh/dog"]
