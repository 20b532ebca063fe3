"""Window cache integrity (issue 23, item 9): checksums, stale entries, statistics, ``cache``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from skelagnostic import cli
from skelagnostic.core.motion import Motion
from skelagnostic.data import BVHSource, MotionDataModule, ProceduralSource, WindowCache
from skelagnostic.data import cache as cache_module
from skelagnostic.data.cache import CacheWarning
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import GlobalPositions

REPO = Path(__file__).resolve().parents[2]
VALID_BVH = REPO / "tests" / "badinput" / "corpus" / "valid_small.bvh"
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"


def _module(cache: Path, representation: GlobalPositions | None = None) -> MotionDataModule:
    source = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=2, seconds=2.0)
    return MotionDataModule(
        source,
        representation or GlobalPositions(frame="root"),
        window=8,
        stride=8,
        val_fraction=0.0,
        cache_dir=cache,
    )


def _arrays(cache: Path) -> list[Path]:
    return sorted((cache / "windows").glob("*/*.npy"))


@pytest.fixture
def new_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """Forget which entries this process has verified (as a new process would)."""
    monkeypatch.setattr(cache_module, "_VERIFIED", {})


def test_entry_overwritten_with_nan_bytes_is_detected_and_rebuilt(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = _module(tmp_path)
    first.setup("fit")
    stats = first.representations["procedural"].normalization_state()
    array = _arrays(tmp_path)[0]
    intact = array.read_bytes()
    offset = first.datasets["train"]["procedural"].entries[0].layout[0]
    with array.open("r+b") as fh:  # same size, valid header: only the content is wrong
        fh.seek(offset)
        fh.write(np.full((len(intact) - offset) // 4, np.nan, np.float32).tobytes())
    monkeypatch.setattr(cache_module, "_VERIFIED", {})  # the next run is a new process
    again = _module(tmp_path)
    with pytest.warns(CacheWarning, match=r"damaged cache entry .* rebuilt \(checksum "):
        again.setup("fit")
    assert array.read_bytes() == intact
    for key, value in again.representations["procedural"].normalization_state().items():
        assert torch.equal(value, stats[key])


def test_entries_are_verified_once_per_process(
    tmp_path: Path, new_process: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    reads: list[Path] = []
    checksum = cache_module.file_checksum

    def counted(path: Path, offset: int) -> str:
        reads.append(path)
        return checksum(path, offset)

    monkeypatch.setattr(cache_module, "file_checksum", counted)
    dm = _module(tmp_path)
    dm.prepare_data()
    dm.setup("fit")
    assert reads == []  # written by this process: its checksum was computed while writing
    monkeypatch.setattr(cache_module, "_VERIFIED", {})
    for _ in range(2):  # a new process: prepare_data, setup, another data module
        dm = _module(tmp_path)
        dm.prepare_data()
        dm.setup("fit")
    assert sorted(reads) == _arrays(tmp_path)  # each array read once
    for meta in (tmp_path / "windows").glob("*/*.json"):
        assert json.loads(meta.read_text())["checksum"].startswith("crc32:")


def test_entry_without_checksum_is_rebuilt(tmp_path: Path, new_process: None) -> None:
    _module(tmp_path).prepare_data()
    meta = sorted((tmp_path / "windows").glob("*/*.json"))[0]
    info = json.loads(meta.read_text())
    del info["checksum"]
    meta.write_text(json.dumps(info))
    cache_module._VERIFIED.clear()
    with pytest.warns(CacheWarning, match=r"no checksum \(written by an older version\)"):
        _module(tmp_path).prepare_data()
    assert "checksum" in json.loads(meta.read_text())


class _Holes(GlobalPositions):
    """Positions with a NaN value in every 7th frame (a representation that divides by zero)."""

    def encode(self, motion: Motion) -> torch.Tensor:
        out = super().encode(motion)
        out[::7, 3, 1] = float("nan")
        return out


def test_non_finite_statistics_fail_with_one_line(tmp_path: Path) -> None:
    dm = _module(tmp_path, _Holes(frame="root"))
    with pytest.raises(SkelagnosticError) as info:
        dm.setup("fit")
    line = str(info.value)
    assert line == (
        "dataset 'procedural': the features normalisation statistic 'mean' is not finite (1 "
        "of 66 values); a training clip holds NaN or infinite values (check the source files, "
        "or run 'skelagnostic cache clear')"
    )
    assert line in TROUBLESHOOTING.read_text(encoding="utf-8")


def test_changed_source_file_replaces_its_entry(tmp_path: Path, new_process: None) -> None:
    clip = tmp_path / "clip.bvh"
    shutil.copy(VALID_BVH, clip)
    cache = tmp_path / "cache"

    def prepare() -> list[str]:
        dm = MotionDataModule(
            BVHSource([clip], units="cm"), window=2, stride=1, val_fraction=0.0, cache_dir=cache
        )
        dm.prepare_data()
        return [p.stem for p in _arrays(cache)]

    (old,) = prepare()
    lines = clip.read_text().splitlines()
    lines[-1] = " ".join(str(float(v) + 1.0) for v in lines[-1].split())  # edit the last frame
    clip.write_text("\n".join(lines) + "\n")
    (new,) = prepare()
    assert new != old  # the old entry is gone, not left to accumulate
    assert not list((cache / "windows").glob(f"*/{old}.*"))
    assert prepare() == [new]


def test_cache_verb_info_and_clear(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dm = _module(tmp_path / "cache")
    dm.prepare_data()
    size = sum(p.stat().st_size for p in (tmp_path / "cache").rglob("*") if p.is_file())
    assert cli.main(["cache", "info", "--cache-dir", str(tmp_path / "cache"), "-v"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"cache: {tmp_path / 'cache'}"
    assert out[1].startswith("entries: 2, size: ")
    assert WindowCache(tmp_path / "cache").size() == size
    assert sorted(line.split()[-3] for line in out[2:]) == ["biped22_walk_0", "biped22_walk_1"]
    assert cli.main(["cache", "clear", "--cache-dir", str(tmp_path / "cache")]) == 0
    assert capsys.readouterr().out.startswith(f"cache: {tmp_path / 'cache'}: removed 2 entries")
    assert _arrays(tmp_path / "cache") == []
    assert cli.main(["cache", "info", "--cache-dir", str(tmp_path / "cache")]) == 0
    assert "entries: 0, size: 0 B" in capsys.readouterr().out
    (tmp_path / "file").write_text("")
    assert cli.main(["cache", "info", "--cache-dir", str(tmp_path / "file")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"skelagnostic cache: error: --cache-dir {tmp_path / 'file'} is not a directory"
    assert (
        "skelagnostic cache: error: --cache-dir <tmp>/file is not a directory"
        in TROUBLESHOOTING.read_text(encoding="utf-8")
    )
