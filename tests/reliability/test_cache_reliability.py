"""Window cache, issue 47: names per path (item 3), ``cache clear`` (item 5), progress (item 8)."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

import skelagnostic as sa
from skelagnostic import cli
from skelagnostic.data import BVHSource, MotionDataModule, ProceduralSource

REPO = Path(__file__).resolve().parents[2]
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"


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


def _procedural(cache: Path, clips: int = 2) -> MotionDataModule:
    source = ProceduralSource(kinds=["biped22"], gaits=["walk"], clips_per_gait=clips, seconds=1.0)
    return MotionDataModule(source, window=8, stride=8, val_fraction=0.0, cache_dir=cache)


def test_cache_clear_deletes_only_what_the_cache_wrote(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cache = tmp_path / "cache"
    _procedural(cache).prepare_data()
    arrays = sorted((cache / "windows").glob("*/*.npy"))
    assert len(arrays) == 2
    shard = arrays[0].parent
    key = arrays[0].stem
    # the user's files among the cache's: a note, a look-alike without the header,
    # a link to a file elsewhere, a folder, and a file in a folder of their own
    notes = shard / "notes.txt"
    notes.write_text("mine")
    fake = shard / f"{key[:2]}{'0' * 62}.npy"
    fake.write_bytes(b"not an array")
    outside = tmp_path / "precious.npy"
    np.save(outside, np.zeros(3))
    link = shard / f"{key[:2]}{'1' * 62}.npy"
    link.symlink_to(outside)
    (shard / "keep").mkdir()
    (cache / "windows" / "mine").mkdir()
    (cache / "windows" / "mine" / "data.npy").write_bytes(outside.read_bytes())
    # what the cache writes and leaves on a killed write: a temporary file
    temporary = shard / f".{key}.npy.0123abcd.tmp"
    temporary.write_bytes(b"\x93NUM")
    assert cli.main(["cache", "clear", "--cache-dir", str(cache)]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"cache: {cache}: removed 2 entries")
    left = [notes, fake, link, shard / "keep", cache / "windows" / "mine"]
    assert err.strip() == (
        f"skelagnostic cache: left alone {len(left)} path(s) the cache did not write: "
        + ", ".join(str(p) for p in sorted(left[:4]) + left[4:])
    )
    for path in left:
        assert path.exists() or path.is_symlink(), path
    assert notes.read_text() == "mine" and outside.exists()
    assert not temporary.exists()
    assert list((cache / "windows").glob("*/*.json")) == []
    assert not (cache / "slots").exists()  # only cache files there: removed, folders too
    assert sorted(p.name for p in (cache / "windows").iterdir()) == [shard.name, "mine"]
    assert (
        "skelagnostic cache: left alone 1 path(s) the cache did not write: "
        "<cache>/windows/ab/notes.txt" in TROUBLESHOOTING.read_text(encoding="utf-8")
    )
    # a second clear removes nothing and names the same files
    assert cli.main(["cache", "clear", "--cache-dir", str(cache)]) == 0
    out, err = capsys.readouterr()
    assert "removed 0 entries" in out and str(notes) in err


def test_cache_clear_names_a_file_it_cannot_delete(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "cache"
    _procedural(cache, clips=1).prepare_data()
    assert len(list((cache / "windows").glob("*/*.npy"))) == 1

    def refuse(self: Path, missing_ok: bool = False) -> None:
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "unlink", refuse)
    assert cli.main(["cache", "clear", "--cache-dir", str(cache)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("skelagnostic cache: error: cache: cannot delete ")
    assert err.endswith("(Permission denied)") and "\n" not in err


@pytest.fixture
def terminal(monkeypatch: pytest.MonkeyPatch) -> io.StringIO:
    """Progress bars drawn at once on a forced terminal writing to a buffer."""
    from skelagnostic.data import progress as progress_module

    buffer = io.StringIO()
    console = Console(file=buffer, force_terminal=True, width=120)
    monkeypatch.setattr(progress_module, "progress_console", lambda: console)
    monkeypatch.setattr(progress_module, "DELAY_S", 0.0)
    return buffer


def test_a_cache_build_over_many_clips_shows_progress(
    tmp_path: Path, terminal: io.StringIO
) -> None:
    dm = _procedural(tmp_path / "cache", clips=12)
    dm.prepare_data()
    shown = terminal.getvalue()
    assert "data: caching windows" in shown
    assert "12/12" in shown  # every clip counted
    terminal.truncate(0)
    dm.setup()  # reading the cache back is a pass of its own
    assert "data: reading the window cache" in terminal.getvalue()


def test_progress_stays_quiet_off_a_terminal_and_for_short_passes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from skelagnostic.data import progress as progress_module

    buffer = io.StringIO()
    consoles = {
        "pipe": Console(file=buffer, force_terminal=False),
        "terminal": Console(file=buffer, force_terminal=True, width=120),
    }
    monkeypatch.setattr(progress_module, "progress_console", lambda: consoles["pipe"])
    monkeypatch.setattr(progress_module, "DELAY_S", 0.0)
    _procedural(tmp_path / "pipe", clips=3).prepare_data()
    assert buffer.getvalue() == ""  # not a terminal
    monkeypatch.setattr(progress_module, "progress_console", lambda: consoles["terminal"])
    monkeypatch.setattr(progress_module, "DELAY_S", 3600.0)
    _procedural(tmp_path / "short", clips=3).prepare_data()
    assert buffer.getvalue() == ""  # a pass shorter than the delay
    assert list(progress_module.track_clips([1, 2, 3], "x", show=False)) == [1, 2, 3]


def test_progress_inside_another_bar_draws_no_second_one(terminal: io.StringIO) -> None:
    from rich.progress import Progress

    from skelagnostic.data import progress as progress_module

    with Progress(console=progress_module.progress_console()):  # e.g. a verb's own bar
        assert list(progress_module.track_clips(range(4), "inner")) == [0, 1, 2, 3]
    assert "inner" not in terminal.getvalue()


def test_an_entry_deleted_while_in_use_is_one_line(tmp_path: Path) -> None:
    """``cache clear`` while a fit reads its windows: one line naming the entry, no OSError."""
    cache = sa.data.WindowCache(tmp_path / "cache")
    entry = cache.put(
        "0123456789abcdef" * 4, np.zeros((2, 4, 3, 3), np.float32), {"starts": [0, 4]}
    )
    assert entry.read(0, 1).shape == (1, 4, 3, 3)
    cli.main(["cache", "clear", "--cache-dir", str(tmp_path / "cache")])
    with pytest.raises(sa.SkelagnosticError) as info:
        entry.read(1, 2)
    line = str(info.value)
    assert line == (
        f"cache entry {entry.array} was deleted while in use (by 'skelagnostic cache clear'?); "
        "run the command again to rebuild it"
    )
    text = line.replace(str(tmp_path), "<tmp>")
    assert text.split(" was ")[1] in TROUBLESHOOTING.read_text(encoding="utf-8")
