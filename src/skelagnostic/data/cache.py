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
header, shape or size disagrees with it, e.g. after a disk error or a manual
edit) is reported with a :class:`CacheWarning` and treated as missing, so it
is rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.atomic import atomic_write

#: Bump when the cached layout or the window extraction changes.
CACHE_VERSION = 1
#: Environment variable overriding the default cache directory.
CACHE_ENV = "SKELAGNOSTIC_CACHE"


def default_cache_dir() -> Path:
    """``$SKELAGNOSTIC_CACHE`` or ``~/.cache/skelagnostic``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env).expanduser() if env else Path.home() / ".cache" / "skelagnostic"


def cache_key(clip_key: str, preprocessing: dict[str, Any]) -> str:
    """SHA-256 of the clip's content key and the preprocessing config (JSON-serialisable)."""
    blob = json.dumps({"clip": clip_key, "pre": preprocessing, "version": CACHE_VERSION},
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


class CacheWarning(UserWarning):
    """A damaged cache entry was found; it is rebuilt."""


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
        return np.load(self.array, mmap_mode="r")

    @cached_property
    def layout(self) -> tuple[int, tuple[int, ...]]:
        """Byte offset of the data in the ``.npy`` file and the array's shape."""
        with self.array.open("rb") as fh:
            offset, shape, _ = _read_npy_header(fh)
        return offset, shape

    def read(self, start: int = 0, stop: int | None = None,
             out: np.ndarray | None = None) -> np.ndarray:
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
        with self.array.open("rb", buffering=0) as fh:
            fh.seek(offset + start * 4 * math.prod(shape[1:]))
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
                raise ValueError(f"array file has {array.stat().st_size} bytes, expected "
                                 f"{expected}")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            warnings.warn(f"damaged cache entry {array} rebuilt ({exc})", CacheWarning,
                          stacklevel=2)
            return None
        entry = CacheEntry(array, info)
        entry.__dict__["layout"] = (data_start, shape)  # known: spare a second header read
        return entry

    def put(self, key: str, windows: np.ndarray, meta: dict[str, Any]) -> CacheEntry:
        """Store ``windows`` (cast to float32) and ``meta`` atomically under ``key``."""
        array, meta_path = self._paths(key)
        data = np.ascontiguousarray(windows, dtype=np.float32)
        _atomic_write(array, lambda fh: np.save(fh, data))
        _atomic_write(meta_path, lambda fh: fh.write(json.dumps(meta).encode()))
        return CacheEntry(array, meta)
