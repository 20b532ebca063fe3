"""Installing a dataset from its archive: checksum, safe extraction, parse check, window cache.

What ``skelagnostic data prepare`` and ``skelagnostic data get`` do, as plain
functions (the CLI adds Rich progress bars through the ``step`` callbacks):

1. :func:`verify_archive`: the archive's SHA-256 against the checksum stored
   for its preset (:attr:`DatasetPreset.archive <skelagnostic.data.DatasetPreset.archive>`)
   or given by the user;
2. :func:`extract_archive`: every member of the zip below the dataset folder,
   refusing absolute paths and ``..`` (no "zip slip"); a file already there
   with the member's size and CRC-32 is kept, so a second run writes nothing;
3. :func:`check_bvh_files`: every BVH file is read with
   :func:`~skelagnostic.read_bvh`; all failures are collected and reported
   together, each with its file, line and the reader's message;
4. :func:`write_window_cache`: the window cache of a data module over the
   extracted files (by default :class:`~skelagnostic.data.MotionDataModule`'s
   defaults, so the first ``fit`` starts without preprocessing).

Nothing is converted: the files stay as the archive has them.
"""

from __future__ import annotations

import os
import shutil
import urllib.request
import zipfile
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any, BinaryIO

from skelagnostic.data.sources import PRESETS, Archive, BVHSource, file_sha256, preset_source
from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.atomic import atomic_write

__all__ = [
    "DataPrepareError",
    "PreparedDataset",
    "check_bvh_files",
    "check_writable",
    "dataset_folder",
    "default_datamodule",
    "download",
    "extract_archive",
    "file_sha256",
    "held_out_files",
    "known_archive",
    "safe_member_path",
    "verify_archive",
    "write_window_cache",
]

#: Bytes per read when hashing, copying or downloading.
_BLOCK = 1 << 20
#: Called with a number of bytes or files done since the last call.
Step = Callable[[int], None]
#: Opens a URL for reading: ``opener(url)`` returns a binary file object with an
#: optional ``headers`` mapping (``urllib.request.urlopen`` by default).
Opener = Callable[[str], Any]


class DataPrepareError(SkelagnosticError):
    """An archive or dataset folder that cannot be installed (the message names the file)."""


@dataclass(frozen=True)
class PreparedDataset:
    """What ``skelagnostic data prepare`` installed (:func:`skelagnostic.cli.data.prepare`).

    Attributes:
        preset: The preset (``lafan1``, ..., or ``bvh``).
        root: The dataset folder (``data.root=``).
        files: The BVH files, sorted.
        test_files: Those of the preset's fixed test split.
        members: Files of the archive.
        extracted: Those written by this call (0 when all were already in place).
        cached_windows: Windows written to or found in the window cache (0: no cache written).
        cache_dir: The window cache directory, if a cache was written.
    """

    preset: str
    root: Path
    files: tuple[Path, ...]
    test_files: tuple[Path, ...]
    members: int
    extracted: int
    cached_windows: int = 0
    cache_dir: Path | None = None


def verify_archive(path: Path, expected: str, step: Step | None = None) -> str:
    """Check the SHA-256 of ``path`` against ``expected``.

    Returns:
        The digest.

    Raises:
        DataPrepareError: The file is missing or its digest differs (the message
            names the file and both digests).
    """
    if not path.is_file():
        raise DataPrepareError(f"{path}: no such archive file")
    got = file_sha256(path, step)
    if got != expected.lower():
        raise DataPrepareError(
            f"{path}: SHA-256 mismatch: expected {expected.lower()}, got {got} (a partial "
            "download or another version of the archive; download it again)"
        )
    return got


def safe_member_path(name: str) -> PurePosixPath:
    r"""The relative path a zip member may be extracted to.

    Backslashes count as separators (archives made on Windows), so ``..\x``
    is caught too.

    Raises:
        DataPrepareError: The name is absolute (``/x``, ``C:x``), contains ``..``
            or is empty (the message names the member).
    """
    parts = name.replace("\\", "/").split("/")
    if name.startswith(("/", "\\")) or (len(name) > 1 and name[1] == ":"):
        raise DataPrepareError(f"archive member {name!r}: absolute path refused")
    if ".." in parts:
        raise DataPrepareError(f"archive member {name!r}: '..' in the path refused (zip slip)")
    kept = [p for p in parts if p not in ("", ".")]
    if not kept:
        raise DataPrepareError(f"archive member {name!r}: empty path refused")
    return PurePosixPath(*kept)


def _crc32(path: Path) -> int:
    crc = 0
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(_BLOCK), b""):
            crc = zlib.crc32(block, crc)
    return crc


def _same_file(target: Path, info: zipfile.ZipInfo) -> bool:
    """``target`` exists with the member's size and CRC-32."""
    try:
        return target.stat().st_size == info.file_size and _crc32(target) == info.CRC
    except OSError:
        return False


def check_writable(dest: Path) -> None:
    """Create ``dest`` if needed and check that files can be written in it.

    Raises:
        DataPrepareError: It cannot be created or written (names ``dest`` and the reason).
    """
    try:
        dest.mkdir(parents=True, exist_ok=True)
        probe = dest / f".skelagnostic-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise DataPrepareError(
            f"--dest {dest}: not a writable directory ({exc.strerror or exc})"
        ) from exc


def extract_archive(
    archive: Path, dest: Path, step: Step | None = None, total: Step | None = None
) -> tuple[list[Path], int]:
    """Extract every member of the zip ``archive`` below ``dest``, safely and idempotently.

    Every member name is checked first (:func:`safe_member_path`), so a bad
    archive writes nothing. A file already at its place with the member's size
    and CRC-32 is left alone; others are written atomically.

    Args:
        archive: The zip file.
        dest: Folder to extract into (created).
        step: Called with the bytes of each member done.
        total: Called once with the bytes of all members, before the first ``step``.

    Returns:
        The files of the archive below ``dest`` (in archive order) and how many
        were written by this call.

    Raises:
        DataPrepareError: Not a zip file, an unsafe member, ``dest`` not writable,
            not enough free disk, or a member whose data is damaged.
    """
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise DataPrepareError(f"{archive}: not a readable zip file ({exc})") from exc
    with zf:
        members = [(info, safe_member_path(info.filename)) for info in zf.infolist()]
        check_writable(dest)
        files = [(info, dest.joinpath(*rel.parts)) for info, rel in members if not info.is_dir()]
        todo = {i for i, (info, target) in enumerate(files) if not _same_file(target, info)}
        needed = sum(files[i][0].file_size for i in todo)
        free = shutil.disk_usage(dest).free
        if needed > free:
            raise DataPrepareError(
                f"--dest {dest}: the archive needs {needed} bytes, only {free} are free"
            )
        if total is not None:
            total(sum(info.file_size for info, _ in files))
        for i, (info, target) in enumerate(files):
            if i in todo:
                _extract_member(zf, info, target, archive)
            if step is not None:
                step(info.file_size)
    return [target for _, target in files], len(todo)


def _extract_member(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, archive: Path
) -> None:
    def write(out: BinaryIO) -> None:
        with zf.open(info) as src:
            shutil.copyfileobj(src, out, _BLOCK)

    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(target, write)
    except zipfile.BadZipFile as exc:
        raise DataPrepareError(f"{archive}: member {info.filename!r} is damaged ({exc})") from exc
    except OSError as exc:
        raise DataPrepareError(
            f"{target}: cannot write member {info.filename!r} ({exc.strerror or exc})"
        ) from exc


def check_bvh_files(files: Sequence[Path], root: Path, step: Step | None = None) -> None:
    """Read every BVH file; report all that fail together.

    Args:
        files: The BVH files.
        root: Their dataset folder (the message names files relative to it).
        step: Called with 1 after each file.

    Raises:
        DataPrepareError: One line per failing file: its path relative to
            ``root``, the line at fault and the reader's message.
    """
    from skelagnostic.io.bvh import read_bvh

    failures = []
    for path in files:
        try:
            read_bvh(path)
        except (SkelagnosticError, OSError, UnicodeDecodeError) as exc:
            name = path.relative_to(root).as_posix() if path.is_relative_to(root) else str(path)
            line = getattr(exc, "line", None)
            reason = getattr(exc, "reason", None) or str(exc)
            failures.append(f"  {name}{f':{line}' if line else ''}: {reason}")
        if step is not None:
            step(1)
    if failures:
        raise DataPrepareError(
            f"{root}: {len(failures)} of {len(files)} BVH file(s) do not parse:\n"
            + "\n".join(failures)
        )


def _source(preset: str, root: Path) -> BVHSource:
    return BVHSource([root], name="bvh") if preset == "bvh" else preset_source(preset, root)


def held_out_files(preset: str, root: Path) -> list[Path]:
    """The files of the preset's fixed test split below ``root`` (none for ``bvh``)."""
    if preset == "bvh":
        return []
    return sorted(Path(c.id) for c in _source(preset, root).clips() if c.split == "test")


def write_window_cache(datamodule: Any, step: Step | None = None, total: Step | None = None) -> int:
    """Write the window cache of every clip of ``datamodule``'s sources.

    Args:
        datamodule: A :class:`~skelagnostic.data.MotionDataModule` (or subclass):
            its :meth:`~skelagnostic.data.MotionDataModule.cache_entry` decides what
            is cached (representation, fps, window, stride).
        step: Called with 1 after each clip.
        total: Called once with the number of clips, before the first ``step``.

    Returns:
        The number of cached windows.
    """
    clips = [(source, clip) for source in datamodule.sources for clip in source.clips()]
    if total is not None:
        total(len(clips))
    windows = 0
    for source, clip in clips:
        windows += datamodule.cache_entry(source, clip).num_windows
        if step is not None:
            step(1)
    return windows


def download(
    url: str,
    target: Path,
    opener: Opener | None = None,
    step: Step | None = None,
    total: Callable[[int], None] | None = None,
) -> Path:
    """Stream ``url`` to ``target`` (through ``target.part``, renamed when complete).

    Args:
        url: Address of the file (``https://``, ``file://``, ...).
        target: Where to write it.
        opener: Opens the URL (default :func:`urllib.request.urlopen`); tests pass
            their own.
        step: Called with the bytes of each block received.
        total: Called once with the ``Content-Length``, when the server sends one.

    Returns:
        ``target``.

    Raises:
        DataPrepareError: The URL cannot be read or ``target`` cannot be written
            (names both).
    """
    open_url = opener or urllib.request.urlopen
    part = target.with_name(target.name + ".part")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with open_url(url) as response, part.open("wb") as out:
            length = getattr(response, "headers", {}).get("Content-Length")
            if total is not None and length:
                total(int(length))
            for block in iter(lambda: response.read(_BLOCK), b""):
                out.write(block)
                if step is not None:
                    step(len(block))
        os.replace(part, target)
    except (OSError, ValueError) as exc:  # URLError is an OSError; bad URLs raise ValueError
        part.unlink(missing_ok=True)
        raise DataPrepareError(f"download of {url} to {target} failed ({exc})") from exc
    return target


def known_archive(preset: str) -> Archive | None:
    """The stored public archive of ``preset`` (``None``: none is known, or ``bvh``).

    Raises:
        DataPrepareError: Unknown preset.
    """
    if preset == "bvh":
        return None
    if preset not in PRESETS:
        raise DataPrepareError(
            f"unknown dataset preset {preset!r}; known: {', '.join(PRESETS)}, bvh"
        )
    return PRESETS[preset].archive


def dataset_folder(preset: str, dest: Path) -> Path:
    """Where ``preset``'s files go below ``dest``: ``dest/<folder>``.

    So ``SKELAGNOSTIC_DATA=dest`` finds them.
    """
    known_archive(preset)  # checks the name
    return dest / (PRESETS[preset].folder if preset in PRESETS else preset)


def default_datamodule(preset: str, root: Path, cache_dir: Path | None = None) -> Any:
    """A :class:`~skelagnostic.data.MotionDataModule` with its defaults over the preset's files.

    Its cache is what ``fit`` with ``data=<preset>`` and the default data options
    (``fps=30``, ``window=32``, ``stride=16``, world joint positions) reads.
    """
    from skelagnostic.data.datamodule import MotionDataModule

    return MotionDataModule(sources=[_source(preset, root)], cache_dir=cache_dir)
