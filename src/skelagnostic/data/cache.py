"""On-disk cache of preprocessed windows (``.npy`` arrays and JSON descriptions).

One entry per (clip content, preprocessing config): ``<key>.npy`` holds the
``[num_windows, window, N, C]`` float32 features, ``<key>.json`` the clip's
skeleton and window starts. Training reads windows with plain positioned reads
(:meth:`CacheEntry.read`), not memory maps, so a process holds only the
windows it is working on: its resident memory does not grow with the corpus
(mapped pages would count in its RSS until unmapped). Both files are written
to a temporary file and moved in place with :func:`os.replace`, the JSON last
(:func:`~skelagnostic.io.atomic.atomic_write`, so they get the permissions the
umask allows), so readers (other DDP ranks, concurrent runs) see a complete
entry or none.
An entry that is nevertheless damaged (unparsable JSON, an array whose
header, shape or size disagrees with it, or whose bytes do not match the
CRC-32 checksum stored in the JSON, e.g. after a disk error or a manual edit)
is reported with a :class:`CacheWarning` and treated as missing, so it is
rebuilt. The checksum is verified the first time a process opens an entry
(one sequential read of the array) and not again while the file is unchanged,
so it costs one read of the corpus per process, not per epoch.

Clips read from a file keep one entry per (file path, preprocessing)
(:meth:`WindowCache.track`): when the file changes, its old entry is deleted
once the new one is in place, so stale entries do not accumulate.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.atomic import atomic_write

#: Bump when the cached layout or the window extraction changes. 2: clips whose unit is
#: guessed from :meth:`~skelagnostic.Skeleton.height` are converted with the height of the
#: template built from the rest geometry (issue #26, item 8).
CACHE_VERSION = 2
#: Environment variable overriding the default cache directory.
CACHE_ENV = "SKELAGNOSTIC_CACHE"


def default_cache_dir() -> Path:
    """``$SKELAGNOSTIC_CACHE`` or ``~/.cache/skelagnostic``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env).expanduser() if env else Path.home() / ".cache" / "skelagnostic"


def cache_key(clip_key: str, preprocessing: dict[str, Any]) -> str:
    """SHA-256 of the clip's content key and the preprocessing config (JSON-serialisable)."""
    blob = json.dumps(
        {"clip": clip_key, "pre": preprocessing, "version": CACHE_VERSION}, sort_keys=True
    )
    return hashlib.sha256(blob.encode()).hexdigest()


def slot_key(source_id: str, preprocessing: dict[str, Any]) -> str:
    """SHA-256 of where a clip comes from (e.g. its file path) and the preprocessing.

    Unlike :func:`cache_key` it does not depend on the clip's content, so a file
    that changes keeps its slot (:meth:`WindowCache.track`).
    """
    blob = json.dumps(
        {"source": source_id, "pre": preprocessing, "version": CACHE_VERSION}, sort_keys=True
    )
    return hashlib.sha256(blob.encode()).hexdigest()


class CacheWarning(UserWarning):
    """A damaged cache entry was found; it is rebuilt."""


#: Arrays verified by this process: path -> (inode, size, mtime) when they matched.
_VERIFIED: dict[Path, tuple[int, int, int]] = {}
#: Bytes per read when computing a checksum.
_CHECKSUM_BLOCK = 1 << 20


def _signature(path: Path) -> tuple[int, int, int]:
    st = path.stat()
    return st.st_ino, st.st_size, st.st_mtime_ns


def checksum(data: np.ndarray) -> str:
    """``"crc32:<hex>"`` of the bytes of the C-contiguous array ``data``."""
    return f"crc32:{zlib.crc32(data.reshape(-1).view(np.uint8)) if data.size else 0:08x}"


def file_checksum(path: Path, offset: int) -> str:
    """``"crc32:<hex>"`` of the bytes of ``path`` from ``offset`` on, read in blocks."""
    crc = 0
    with path.open("rb") as fh:
        fh.seek(offset)
        for block in iter(lambda: fh.read(_CHECKSUM_BLOCK), b""):
            crc = zlib.crc32(block, crc)
    return f"crc32:{crc:08x}"


def _atomic_write(path: Path, write: Any) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, write)
    except OSError as exc:
        raise SkelagnosticError(
            f"data.cache_dir: cannot write the window cache in {str(path.parent)!r} "
            f"({exc.strerror or exc}); set data.cache_dir or $SKELAGNOSTIC_CACHE to a "
            "writable directory"
        ) from exc


@dataclass(frozen=True)
class CacheEntry:
    """A cached clip: where its windows are and what they describe.

    Attributes:
        array: Path of the ``.npy`` file of ``[num_windows, window, N, C]`` features.
        meta: Clip id, skeleton (``Skeleton.to_dict()``), window starts, fps.
    """

    array: Path
    meta: dict[str, Any]

    @property
    def num_windows(self) -> int:
        """Number of windows of the clip."""
        return len(self.meta["starts"])

    def open(self) -> np.ndarray:
        """The features as a read-only memory map."""
        with self._opened(-1):  # one line if the entry was deleted
            return np.load(self.array, mmap_mode="r")

    @cached_property
    def layout(self) -> tuple[int, tuple[int, ...]]:
        """Byte offset of the data in the ``.npy`` file and the array's shape."""
        with self._opened(-1) as fh:
            offset, shape, _ = _read_npy_header(fh)
        return offset, shape

    def _opened(self, buffering: int) -> BinaryIO:
        """The array file open for reading; its removal since it was cached is one line."""
        try:
            return self.array.open("rb", buffering=buffering)
        except FileNotFoundError:  # e.g. 'skelagnostic cache clear' while training reads it
            raise SkelagnosticError(
                f"cache entry {self.array} was deleted while in use (by 'skelagnostic "
                "cache clear'?); run the command again to rebuild it"
            ) from None

    def read(
        self, start: int = 0, stop: int | None = None, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Windows ``start:stop`` read from the file into memory (no memory map).

        Args:
            start: First window.
            stop: One past the last window (default: all windows).
            out: A C-contiguous float32 array of ``[stop - start, window, N, C]``
                values to read into (default: a new array).

        Returns:
            The windows, ``[stop - start, window, N, C]`` float32 (``out`` if given).

        Raises:
            SkelagnosticError: The range is out of bounds, ``out`` does not fit, or the
                file is shorter than its header says (names the file).
        """
        offset, shape = self.layout
        stop = shape[0] if stop is None else stop
        if not 0 <= start <= stop <= shape[0]:
            raise SkelagnosticError(
                f"cache entry {self.array}: windows {start}:{stop} out of range [0, {shape[0]}]"
            )
        size = (stop - start, *shape[1:])
        if out is None:
            out = np.empty(size, np.float32)
        elif out.shape != size or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise SkelagnosticError(
                f"cache entry {self.array}: cannot read {size} float32 windows into an array "
                f"of {out.shape} {out.dtype}"
            )
        with self._opened(0) as fh:
            fh.seek(offset + start * 4 * math.prod(shape[1:]))
            read_exactly(fh, out, self.array)
        return out

    def read_frames(self, start: int, stop: int) -> np.ndarray:
        """Frames ``start:stop`` of an entry holding one ``[1, T, ...]`` array (a whole clip).

        A positioned read of those frames only (no memory map), as :meth:`read` does
        for windows.

        Returns:
            ``[stop - start, ...]`` float32.

        Raises:
            SkelagnosticError: The entry holds several windows, or the range is out of
                bounds (names the file).
        """
        offset, shape = self.layout
        if len(shape) < 2 or shape[0] != 1 or not 0 <= start <= stop <= shape[1]:
            raise SkelagnosticError(
                f"cache entry {self.array}: cannot read frames {start}:{stop} of an array of "
                f"{shape} (one clip of [1, T, ...] frames expected)"
            )
        out = np.empty((stop - start, *shape[2:]), np.float32)
        with self._opened(0) as fh:
            fh.seek(offset + start * 4 * math.prod(shape[2:]))
            read_exactly(fh, out, self.array)
        return out


def _read_npy_header(fh: Any) -> tuple[int, tuple[int, ...], np.dtype]:
    """``(data offset, shape, dtype)`` of the ``.npy`` file open at its start."""
    fmt = np.lib.format
    version = fmt.read_magic(fh)
    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
    shape, fortran_order, dtype = read_header(fh)
    if fortran_order:
        raise ValueError("array is stored in Fortran order")
    return fh.tell(), tuple(int(n) for n in shape), dtype


def read_exactly(fh: Any, out: np.ndarray, path: Path) -> None:
    """Fill the C-contiguous ``out`` from the current position of the binary file ``fh``.

    Raises:
        SkelagnosticError: The file ends first (names ``path``).
    """
    view = memoryview(out).cast("B")
    done = 0
    while done < len(view):
        got = fh.readinto(view[done:])
        if not got:
            raise SkelagnosticError(
                f"cache entry {path}: file ends {len(view) - done} bytes early; delete it to "
                "rebuild it"
            )
        done += got


class WindowCache:
    """A directory of cached window arrays.

    Args:
        root: The cache directory (created on first write).
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).expanduser()

    def _paths(self, key: str) -> tuple[Path, Path]:
        base = self.root / "windows" / key[:2]
        return base / f"{key}.npy", base / f"{key}.json"

    def get(self, key: str) -> CacheEntry | None:
        """The entry of ``key``, or ``None`` if it is not (completely) written."""
        array, meta = self._paths(key)
        if not meta.is_file() or not array.is_file():
            return None
        try:
            info = json.loads(meta.read_text())
            with array.open("rb") as fh:
                data_start, shape, dtype = _read_npy_header(fh)
            expected = data_start + int(np.prod(shape)) * dtype.itemsize
            if dtype != np.float32 or shape[:1] != (len(info["starts"]),):
                raise ValueError(f"array {shape} {dtype} does not match its metadata")
            if array.stat().st_size != expected:
                raise ValueError(
                    f"array file has {array.stat().st_size} bytes, expected {expected}"
                )
            self._verify(array, data_start, info)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            warnings.warn(
                f"damaged cache entry {array} rebuilt ({exc})", CacheWarning, stacklevel=2
            )
            return None
        entry = CacheEntry(array, info)
        entry.__dict__["layout"] = (data_start, shape)  # known: spare a second header read
        return entry

    @staticmethod
    def _verify(array: Path, data_start: int, info: dict[str, Any]) -> None:
        """Check the array's bytes against the checksum of its metadata, once per process.

        Raises:
            ValueError: No checksum (an entry of an older version) or a mismatch.
        """
        signature = _signature(array)
        if _VERIFIED.get(array) == signature:
            return
        want = info.get("checksum")
        if not want:
            raise ValueError("no checksum (written by an older version)")
        got = file_checksum(array, data_start)
        if got != want:
            raise ValueError(f"checksum {got} of the array bytes, expected {want}")
        _VERIFIED[array] = signature

    def put(self, key: str, windows: np.ndarray, meta: dict[str, Any]) -> CacheEntry:
        """Store ``windows`` (cast to float32) and ``meta`` atomically under ``key``.

        The metadata gets the ``checksum`` of the array's bytes (:func:`checksum`).
        """
        array, meta_path = self._paths(key)
        data = np.ascontiguousarray(windows, dtype=np.float32)
        meta = {**meta, "checksum": checksum(data)}
        _atomic_write(array, lambda fh: np.save(fh, data))
        _atomic_write(meta_path, lambda fh: fh.write(json.dumps(meta).encode()))
        _VERIFIED[array] = _signature(array)  # its checksum was just computed
        return CacheEntry(array, meta)

    # ------------------------------------------------------------- maintenance
    def _slot_path(self, slot: str) -> Path:
        return self.root / "slots" / slot[:2] / slot

    def track(self, slot: str, key: str) -> None:
        """Record that ``slot`` (e.g. a source file and preprocessing) is cached under ``key``.

        If the slot named another entry (the file has changed since), that
        entry is deleted: a source file keeps one entry per preprocessing.

        Args:
            slot: Hex digest identifying the file and preprocessing, not the content.
            key: The entry's key (content and preprocessing).
        """
        path = self._slot_path(slot)
        try:
            old = path.read_text().strip()
        except OSError:
            old = ""
        if old == key:
            return
        if old:
            self.remove(old)
        _atomic_write(path, lambda fh: fh.write(key.encode()))

    def remove(self, key: str) -> int:
        """Delete the entry ``key`` (if present); returns the bytes freed."""
        freed = 0
        for path in self._paths(key):
            try:
                freed += path.stat().st_size
                path.unlink()
            except FileNotFoundError:
                pass
        return freed

    def entries(self) -> Iterator[tuple[str, Path, dict[str, Any] | None]]:
        """Every entry's ``(key, array path, metadata or None if unreadable)``, sorted by key."""
        for array in sorted((self.root / "windows").glob("*/*.npy")):
            try:
                meta = json.loads(array.with_suffix(".json").read_text())
            except (OSError, ValueError):
                meta = None
            yield array.stem, array, meta

    def size(self) -> int:
        """Bytes of all files of the cache (entries, slots, temporary files)."""
        return sum(
            p.stat().st_size
            for sub in ("windows", "slots")
            for p in (self.root / sub).rglob("*")
            if p.is_file()
        )

    def clear(self) -> ClearReport:
        """Delete every file the cache wrote; leave anything else where it is.

        A file is deleted only if its place, name and first bytes are those the
        cache gives its files (:func:`cache_file_kind`): ``windows/<kk>/<key>.npy``
        starting with the ``.npy`` magic, ``windows/<kk>/<key>.json`` starting with
        ``{``, ``slots/<kk>/<slot>`` holding a key, and the temporary files of
        their atomic writes. Other files, symbolic links and folders are left
        alone and listed in the report; the cache's folders are removed when
        they end up empty.

        Returns:
            What was deleted and what was left alone.

        Raises:
            SkelagnosticError: A file of the cache cannot be deleted (names it).
        """
        entries, freed, kept = 0, 0, []
        for sub in ("windows", "slots"):
            top = self.root / sub
            if top.is_symlink() or not top.is_dir():
                if top.is_symlink() or top.exists():
                    kept.append(top)
                continue
            for folder in sorted(top.iterdir()):
                if folder.is_symlink() or not folder.is_dir() or not _SHARD.fullmatch(folder.name):
                    kept.append(folder)
                    continue
                for path in sorted(folder.iterdir()):
                    kind = cache_file_kind(path, sub)
                    if kind is None:
                        kept.append(path)
                        continue
                    try:
                        size = path.stat().st_size
                        path.unlink()
                    except FileNotFoundError:  # removed meanwhile (another clear, a rebuild)
                        continue
                    except OSError as exc:
                        raise SkelagnosticError(
                            f"cache: cannot delete {path} ({exc.strerror or exc})"
                        ) from exc
                    freed += size
                    entries += kind == "array"
                _remove_if_empty(folder)
            _remove_if_empty(top)
        _VERIFIED.clear()
        return ClearReport(entries, freed, tuple(kept))


@dataclass(frozen=True)
class ClearReport:
    """What :meth:`WindowCache.clear` did.

    Attributes:
        entries: Entries deleted (their ``.npy`` arrays).
        freed: Bytes of all files deleted (entries, slots, temporary files).
        kept: Files, links and folders inside the cache's folders that the cache
            did not write, left alone.
    """

    entries: int
    freed: int
    kept: tuple[Path, ...]


#: A cache key or slot: 64 lowercase hex digits (a SHA-256).
_KEY = re.compile(r"[0-9a-f]{64}")
#: A shard folder of ``windows/`` or ``slots/``: the first two hex digits of the key.
_SHARD = re.compile(r"[0-9a-f]{2}")
#: What :func:`~skelagnostic.io.atomic.atomic_write` names its temporary files.
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.[0-9a-f]{8}\.tmp")
#: ``(folder, suffix)`` of each kind of file.
_KINDS = {("windows", ".npy"): "array", ("windows", ".json"): "meta", ("slots", ""): "slot"}
#: The first bytes of the entries' files: the ``.npy`` magic, a JSON object.
_HEADERS = {"array": b"\x93NUMPY", "meta": b"{"}
#: Hex digits (the start of a slot's key).
_HEX = re.compile(r"[0-9a-f]*")


def cache_file_kind(path: Path, sub: str) -> str | None:
    """The kind of cache file ``path`` (in ``<root>/<sub>/<kk>/``) is; ``None``: not the cache's.

    Args:
        path: A path in a shard folder (``<kk>``) of ``windows`` or ``slots``.
        sub: ``"windows"`` or ``"slots"``.

    Returns:
        ``"array"``, ``"meta"``, ``"slot"`` or ``"temporary"`` when the name
        matches the folder (``<kk>`` are the first two digits of the 64-digit
        key) and the file starts as that kind of file does (a temporary file may
        be empty or cut short: it is checked against the start of its kind's
        header); ``None`` for anything else, a symbolic link or a folder.
    """
    if path.is_symlink() or not path.is_file():
        return None
    temporary = _TEMPORARY.fullmatch(path.name)
    name = temporary.group("name") if temporary else path.name
    key, dot, suffix = name.partition(".")
    if not (_KEY.fullmatch(key) and key[:2] == path.parent.name):
        return None
    kind = _KINDS.get((sub, dot + suffix))
    if kind is None:
        return None
    try:
        with path.open("rb") as fh:
            head = fh.read(65 if kind == "slot" else len(_HEADERS[kind]))
    except OSError:
        return None
    if kind == "slot":  # a key (a temporary file: the start of one)
        text = head.decode("ascii", "replace")
        ok = bool(_KEY.fullmatch(text)) or (temporary is not None and _HEX.fullmatch(text))
    else:  # the header (a temporary file: its start, or nothing yet)
        ok = head == _HEADERS[kind] or (temporary is not None and _HEADERS[kind].startswith(head))
    if not ok:
        return None
    return "temporary" if temporary else kind


def _remove_if_empty(folder: Path) -> None:
    """Remove ``folder`` if it is empty (else leave it)."""
    try:
        folder.rmdir()
    except OSError:
        pass
