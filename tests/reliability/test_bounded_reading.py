"""Bounded memory when reading the window cache (issue 8: data bigger than RAM).

The normalisation pass of ``MotionDataModule.setup`` must allocate the same
whatever the size of the corpus, and items are read from the cache files
without memory maps. The large-scale measurement is the ``bigdata`` benchmark
suite (``docs/scaling.md``); these tests check the mechanism on small corpora.
"""

from __future__ import annotations

import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from skelagnostic.data import MotionDataModule, ProceduralSource, WindowCache
from skelagnostic.data import window_dataset as window_dataset_module
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions


def _module(cache: Path, seconds: float, clips: int = 2) -> MotionDataModule:
    source = ProceduralSource(
        kinds=["biped22"], gaits=["walk"], clips_per_gait=clips, seconds=seconds
    )
    return MotionDataModule(
        source, GlobalPositions(frame="root"), window=8, stride=8, val_fraction=0.0, cache_dir=cache
    )


def _normalisation_peak(dm: MotionDataModule, monkeypatch: pytest.MonkeyPatch) -> int:
    """Peak traced bytes (Python objects, numpy buffers) of the normalisation pass of ``setup``.

    The pass is the representation's ``fit_normalization`` consuming the
    dataset's feature chunks; the rest of ``setup`` (the procedural source
    generating its clips, reading the cache's JSON) is not counted.
    """
    dm.prepare_data()
    peaks: list[int] = []
    fit = GlobalPositions.fit_normalization

    def measured(self: GlobalPositions, features: Any, **kwargs: Any) -> None:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        fit(self, features, **kwargs)
        peaks.append(tracemalloc.get_traced_memory()[1] - base)

    monkeypatch.setattr(GlobalPositions, "fit_normalization", measured)
    tracemalloc.start()
    try:
        dm.setup("fit")
    finally:
        tracemalloc.stop()
        monkeypatch.setattr(GlobalPositions, "fit_normalization", fit)
    assert len(peaks) == 1
    return peaks[0]


def test_normalisation_pass_does_not_allocate_with_the_corpus(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a chunk of 4 windows' values, so both corpora span many chunks; the clips
    # of the second corpus are 4x longer (4x the windows), as are the per-clip
    # arrays a pass loading a clip at a time would allocate
    monkeypatch.setattr(window_dataset_module, "STATS_CHUNK_VALUES", 4 * 8 * 22 * 3)
    small = _normalisation_peak(_module(tmp_path / "a", seconds=10.0), monkeypatch)
    large = _normalisation_peak(_module(tmp_path / "b", seconds=40.0), monkeypatch)
    long_clip = (40 * 30 // 8) * 8 * 22 * 3 * 4  # bytes of one long clip's windows (float32)
    assert small < long_clip / 4, small
    assert large < 1.25 * small, (small, large)


def test_normalisation_statistics_match_a_direct_computation(tmp_path: Path) -> None:
    dm = _module(tmp_path, seconds=6.0, clips=3)
    dm.setup("fit")
    ds = dm.datasets["train"]["procedural"]
    every = np.concatenate([e.open().reshape(-1, 22, 3) for e in ds.entries]).astype(np.float64)
    std = every.std(0)
    std[std < 1e-6] = 1.0  # constant channels (the root, in root-local positions)
    rep = dm.representations["procedural"]
    assert (every.std(0) < 1e-6).any() and (std != 1.0).any()
    torch.testing.assert_close(rep.mean, torch.from_numpy(every.mean(0)).float())
    torch.testing.assert_close(rep.std, torch.from_numpy(std).float(), rtol=1e-4, atol=1e-6)


def test_feature_chunks_are_of_one_size_and_cover_every_frame(tmp_path: Path) -> None:
    dm = _module(tmp_path, seconds=3.0, clips=3)
    dm.setup("fit")
    ds = dm.datasets["train"]["procedural"]
    chunks = list(ds.feature_chunks(chunk_values=5 * 22 * 3 + 7))  # 5 frames a chunk
    assert {c.shape for c in chunks[:-1]} == {(5, 22, 3)} and 1 <= len(chunks[-1]) <= 5
    every = np.concatenate([e.open().reshape(-1, 22, 3) for e in ds.entries])
    np.testing.assert_array_equal(torch.cat(chunks).numpy(), every)
    whole = list(ds.feature_chunks(chunk_values=10**9))  # capped at the dataset's frames
    assert len(whole) == 1 and whole[0].shape == every.shape


def test_items_are_read_without_memory_maps(tmp_path: Path) -> None:
    dm = _module(tmp_path, seconds=3.0)
    dm.setup("fit")
    ds = dm.datasets["train"]["procedural"]
    items = [ds[i] for i in range(len(ds))]
    last = ds.entries[-1].open()
    np.testing.assert_array_equal(items[-1]["features"].numpy(), last[-1])
    assert items[-1]["features"].numpy().flags.writeable
    del last
    maps = Path("/proc/self/maps")
    if maps.exists():  # Linux: none of the cache files is mapped into the process
        mapped = maps.read_text()
        assert not any(str(e.array) in mapped for e in ds.entries)


def test_cache_entry_read_ranges_and_errors(tmp_path: Path) -> None:
    cache = WindowCache(tmp_path)
    data = np.arange(5 * 4 * 3 * 2, dtype=np.float32).reshape(5, 4, 3, 2)
    cache.put("ab" * 32, data, {"clip": "c", "starts": [0, 1, 2, 3, 4]})
    entry = cache.get("ab" * 32)
    assert entry is not None
    np.testing.assert_array_equal(entry.read(), data)
    np.testing.assert_array_equal(entry.read(1, 3), data[1:3])
    out = np.empty((1, 4, 3, 2), np.float32)
    assert entry.read(4, 5, out=out) is out
    np.testing.assert_array_equal(out, data[4:])
    with pytest.raises(SkelagnosticError, match="out of range"):
        entry.read(3, 6)
    with pytest.raises(SkelagnosticError, match="cannot read"):
        entry.read(0, 2, out=out)
    with entry.array.open("r+b") as fh:  # damaged after it was checked
        fh.truncate(entry.array.stat().st_size - 8)
    with pytest.raises(SkelagnosticError, match=r"ends 8 bytes early"):
        entry.read(4, 5)
