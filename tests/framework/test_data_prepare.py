"""``skelagnostic data prepare|get``: checksum, safe extraction, parse check, window cache.

Every archive is a small zip built here from procedural clips written with
:func:`~skelagnostic.write_bvh`; nothing is downloaded (``get`` reads ``file://``
URLs or an injected opener).
"""

from __future__ import annotations

import hashlib
import io
import os
import zipfile
from pathlib import Path

import pytest

from skelagnostic import cli, procedural, write_bvh
from skelagnostic.cli import data as data_cli
from skelagnostic.data import PRESETS, MotionDataModule, WindowCache, preset_source
from skelagnostic.data.prepare import (
    DataPrepareError,
    check_bvh_files,
    download,
    extract_archive,
    safe_member_path,
)

#: Two MANN dog names: one of the fixed test clips, one training clip.
DOG_NAMES = ("D1_004_KAN01_001", "D1_047_KAN01_001")


def bvh_bytes(tmp_path: Path, kind: str = "quadruped", seed: int = 0) -> bytes:
    """A 1-second procedural clip as BVH text."""
    motion, _ = procedural.generate(kind, "walk", seconds=1.5, seed=seed)
    path = tmp_path / f"clip-{kind}-{seed}.bvh"
    write_bvh(motion, path)
    data = path.read_bytes()
    path.unlink()
    return data


def make_zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def prepare_argv(archive: Path, dest: Path, cache: Path) -> list[str]:
    """``skelagnostic data prepare mann_dog`` of ``archive`` with its checksum."""
    return [
        "data",
        "prepare",
        "mann_dog",
        "--zip",
        str(archive),
        "--dest",
        str(dest),
        "--sha256",
        sha256(archive),
        "--cache-dir",
        str(cache),
    ]


@pytest.fixture
def dog_zip(tmp_path: Path) -> Path:
    """A zip of two dog clips in ``MotionCapture/``: the MANN names of a test and a train clip."""
    members = {
        f"MotionCapture/{name}.bvh": bvh_bytes(tmp_path, seed=i) for i, name in enumerate(DOG_NAMES)
    }
    return make_zip(tmp_path / "dog.zip", members)


def test_prepare_verifies_extracts_and_caches(
    dog_zip: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dest, cache = tmp_path / "data", tmp_path / "cache"
    result = data_cli.prepare("mann_dog", dog_zip, dest, sha256=sha256(dog_zip), cache_dir=cache)
    root = dest / "mann_dog"
    assert result.root == root
    assert [p.name for p in result.files] == [f"{n}.bvh" for n in sorted(DOG_NAMES)]
    for name in DOG_NAMES:
        assert (root / "MotionCapture" / f"{name}.bvh").is_file()
    assert [p.name for p in result.test_files] == ["D1_004_KAN01_001.bvh"]
    assert (result.members, result.extracted) == (2, 2)
    # the cache holds what MotionDataModule's defaults read: building it adds nothing
    entries = list(WindowCache(cache).entries())
    assert len(entries) == 2 and result.cached_windows > 0
    assert result.cached_windows == sum(len(meta["starts"]) for _, _, meta in entries)
    dm = MotionDataModule(sources=[preset_source("mann_dog", root)], cache_dir=cache)
    dm.prepare_data()
    assert len(list(WindowCache(cache).entries())) == 2
    text = data_cli.report(result, dest)
    assert f"data=mann_dog data.root={root}" in text
    assert f"SKELAGNOSTIC_DATA={dest}" in text
    assert "test split: 1 file(s): D1_004_KAN01_001.bvh" in text


def test_prepare_bvh_puts_any_archive_in_a_folder_of_its_own(tmp_path: Path) -> None:
    archive = make_zip(tmp_path / "mine.zip", {"takes/a.bvh": bvh_bytes(tmp_path, "biped22")})
    dest = tmp_path / "data"
    result = data_cli.prepare("bvh", archive, dest, sha256=sha256(archive).upper(), cache=False)
    assert result.files == (dest / "bvh" / "takes" / "a.bvh",)
    assert result.test_files == () and result.cache_dir is None
    text = data_cli.report(result, dest)
    assert f"data=bvh data.paths=[{dest / 'bvh'}]" in text and "SKELAGNOSTIC_DATA" not in text


def test_prepare_is_idempotent(dog_zip: Path, tmp_path: Path) -> None:
    dest = tmp_path / "data"
    first = data_cli.prepare("mann_dog", dog_zip, dest, sha256=sha256(dog_zip), cache=False)
    stamps = {p: p.stat().st_mtime_ns for p in first.files}
    second = data_cli.prepare("mann_dog", dog_zip, dest, sha256=sha256(dog_zip), cache=False)
    assert second.extracted == 0 and second.files == first.files
    assert {p: p.stat().st_mtime_ns for p in second.files} == stamps
    # a damaged file in place is written again
    first.files[0].write_bytes(b"HIERARCHY\n")
    third = data_cli.prepare("mann_dog", dog_zip, dest, sha256=sha256(dog_zip), cache=False)
    assert third.extracted == 1


def test_checksum_mismatch_names_the_file_and_both_digests(dog_zip: Path, tmp_path: Path) -> None:
    wrong = "0" * 64
    with pytest.raises(DataPrepareError) as info:
        data_cli.prepare("mann_dog", dog_zip, tmp_path / "data", sha256=wrong, cache=False)
    message = str(info.value)
    assert str(dog_zip) in message and wrong in message and sha256(dog_zip) in message
    assert not (tmp_path / "data").exists()  # nothing extracted


def test_the_stored_checksum_is_checked(dog_zip: Path, tmp_path: Path) -> None:
    stored = PRESETS["lafan1"].archive
    assert stored is not None
    with pytest.raises(DataPrepareError, match=f"expected {stored.sha256}, got {sha256(dog_zip)}"):
        data_cli.prepare("lafan1", dog_zip, tmp_path / "data", cache=False)


def test_a_preset_without_a_stored_checksum_needs_one(dog_zip: Path, tmp_path: Path) -> None:
    assert PRESETS["mann_dog"].archive is None
    with pytest.raises(DataPrepareError, match=r"no checksum is stored for 'bvh'.*--sha256"):
        data_cli.prepare("bvh", dog_zip, tmp_path / "data", cache=False)


def test_every_corrupt_bvh_is_named_with_its_line(tmp_path: Path) -> None:
    good = bvh_bytes(tmp_path)
    lines = good.decode().splitlines(keepends=True)
    bad_offset = "".join(lines[:3]) + "  OFFSET 0.0 abc 0.0\n" + "".join(lines[4:])
    archive = make_zip(
        tmp_path / "bad.zip",
        {
            "take/good.bvh": good,
            "take/bad_offset.bvh": bad_offset.encode(),
            "take/not_bvh.bvh": b"hello\n",
        },
    )
    dest = tmp_path / "data"
    with pytest.raises(DataPrepareError) as info:
        data_cli.prepare("bvh", archive, dest, sha256=sha256(archive), cache=False)
    message = str(info.value)
    assert "2 of 3 BVH file(s) do not parse" in message
    assert "take/bad_offset.bvh:4: " in message and "'abc' is not a number" in message
    assert "take/not_bvh.bvh:1: " in message and "HIERARCHY" in message
    assert "good.bvh" not in message


@pytest.mark.parametrize(
    "member",
    [
        "../evil.bvh",
        "a/../../evil.bvh",
        "/etc/evil.bvh",
        "..\\evil.bvh",
        "C:evil.bvh",
        "C:/evil.bvh",
    ],
)
def test_unsafe_members_are_refused_before_anything_is_written(member: str, tmp_path: Path) -> None:
    archive = make_zip(tmp_path / "slip.zip", {"ok.bvh": bvh_bytes(tmp_path), member: b"x"})
    dest = tmp_path / "deep" / "data"
    with pytest.raises(DataPrepareError, match=f"archive member {member!r}".replace("\\", "\\\\")):
        data_cli.prepare("bvh", archive, dest, sha256=sha256(archive), cache=False)
    assert not dest.exists()
    assert [p.name for p in tmp_path.rglob("evil.bvh")] == []


def test_safe_member_paths_stay_relative() -> None:
    assert str(safe_member_path("./a//b/c.bvh")) == "a/b/c.bvh"
    assert str(safe_member_path("a\\b.bvh")) == "a/b.bvh"
    with pytest.raises(DataPrepareError, match="empty path"):
        safe_member_path("./")


def test_an_unwritable_dest_is_named(dog_zip: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(DataPrepareError, match=f"--dest {blocker / 'mann_dog'}: not a writable"):
        data_cli.prepare("mann_dog", dog_zip, blocker, sha256=sha256(dog_zip), cache=False)


def test_extract_reports_a_file_that_is_no_zip(tmp_path: Path) -> None:
    fake = tmp_path / "fake.zip"
    fake.write_bytes(b"not a zip")
    with pytest.raises(DataPrepareError, match="not a readable zip file"):
        extract_archive(fake, tmp_path / "out")


def test_check_bvh_files_passes_good_files(tmp_path: Path) -> None:
    path = tmp_path / "a.bvh"
    path.write_bytes(bvh_bytes(tmp_path, "biped22"))
    steps: list[int] = []
    check_bvh_files([path], tmp_path, steps.append)
    assert steps == [1]


def test_cli_prepare(dog_zip: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dest = tmp_path / "data"
    argv = prepare_argv(dog_zip, dest, tmp_path / "cache")
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert f"data=mann_dog data.root={dest / 'mann_dog'}" in out
    assert "2 archive file(s) written" in out and "window cache:" in out
    assert cli.main([*argv[:-4], "--sha256", "f" * 64]) == 1
    err = capsys.readouterr().err
    assert err.startswith("skelagnostic data prepare: error: ") and "SHA-256 mismatch" in err


def test_cli_overrides_pick_an_aligners_data_module(
    example_plugin: Path, dog_zip: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cache = tmp_path / "cache"
    argv = prepare_argv(dog_zip, tmp_path / "d", cache)
    assert cli.main([*argv, "data.window=16"]) == 1
    assert "add model=NAME" in capsys.readouterr().err
    assert cli.main([*argv, "model=example", "data.window=16", "data.stride=4"]) == 0
    metas = [meta for _, _, meta in WindowCache(cache).entries()]
    assert len(metas) == 2 and all(m["starts"][:3] == [0, 4, 8] for m in metas)


def test_cli_help_describes_the_verb(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main([]) == 0
    assert "  data " in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["data", "prepare", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for option in ("--zip FILE", "--dest DIR", "--sha256 HEX", "--no-cache", "lafan1"):
        assert option in out


def test_get_downloads_from_a_file_url_once(dog_zip: Path, tmp_path: Path) -> None:
    dest = tmp_path / "data"
    url = dog_zip.as_uri()
    result = data_cli.get("mann_dog", dest, url=url, sha256=sha256(dog_zip), cache=False)
    assert (dest / "dog.zip").read_bytes() == dog_zip.read_bytes()
    assert result.extracted == 2

    def no_network(address: str) -> io.BytesIO:
        raise AssertionError(f"downloaded {address} again")

    again = data_cli.get(
        "mann_dog", dest, url=url, sha256=sha256(dog_zip), cache=False, opener=no_network
    )
    assert again.extracted == 0


def test_get_uses_the_stored_url_and_checksum(dog_zip: Path, tmp_path: Path) -> None:
    stored = PRESETS["lafan1"].archive
    assert stored is not None and stored.url.endswith("/lafan1/lafan1.zip")
    asked: list[str] = []

    def opener(address: str) -> io.BytesIO:
        asked.append(address)
        return io.BytesIO(dog_zip.read_bytes())

    with pytest.raises(DataPrepareError, match=f"expected {stored.sha256}"):
        data_cli.get("lafan1", tmp_path / "data", cache=False, opener=opener)
    assert asked == [stored.url]
    assert (tmp_path / "data" / "lafan1.zip").is_file()


def test_get_without_a_known_archive_says_what_to_do(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for preset in ("mann_dog", "cmu", "bandai"):
        assert PRESETS[preset].archive is None
        assert cli.main(["data", "get", preset, "--dest", str(tmp_path)]) == 1
        err = capsys.readouterr().err
        assert (
            f"no public archive with a fixed layout and a published checksum is known for "
            f"{preset!r}" in err
        )
        assert f"skelagnostic data prepare {preset} --zip FILE --sha256 HEX" in err
        assert "data.root=" in err
    assert not any(tmp_path.iterdir())


def test_cli_get_with_an_injected_opener(
    dog_zip: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def opener(address: str) -> io.BytesIO:
        assert address == "https://mirror.invalid/dog.zip"
        return io.BytesIO(dog_zip.read_bytes())

    argv = [
        "get",
        "mann_dog",
        "--dest",
        str(tmp_path / "d"),
        "--url",
        "https://mirror.invalid/dog.zip",
        "--sha256",
        sha256(dog_zip),
        "--no-cache",
    ]
    assert data_cli.main(argv, opener=opener) == 0
    assert "data=mann_dog" in capsys.readouterr().out


def test_a_failed_download_leaves_no_partial_file(tmp_path: Path) -> None:
    missing = (tmp_path / "missing.zip").as_uri()
    target = tmp_path / "out" / "x.zip"
    with pytest.raises(DataPrepareError, match=f"download of {missing} to {target} failed"):
        download(missing, target)
    assert not target.exists() and not target.with_name("x.zip.part").exists()


def test_download_reports_progress(dog_zip: Path, tmp_path: Path) -> None:
    done: list[int] = []
    target = download(dog_zip.as_uri(), tmp_path / "copy.zip", step=done.append)
    assert sum(done) == os.path.getsize(dog_zip) == target.stat().st_size
