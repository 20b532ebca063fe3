"""On-disk cache of preprocessed windows, read back through numpy memory maps.

One entry per (clip content, preprocessing config): ``<key>.npy`` holds the
``[num_windows, window, N, C]`` float32 features, ``<key>.json`` the clip's
skeleton and window starts. Both are written to a temporary file and moved in
place with :func:`os.replace`, the JSON last, so readers (other DDP ranks,
concurrent runs) see a complete entry or none. An entry that is nevertheless
damaged (unparsable JSON, an array whose header, shape or size disagrees with
it, e.g. after a disk error or a manual edit) is reported with a
:class:`CacheWarning` and treated as missing, so it is rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skelagnostic.errors import SkelagnosticError

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
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise SkelagnosticError(
            f"data.cache_dir: cannot write the window cache in {str(path.parent)!r} "
            f"({exc.strerror or exc}); set data.cache_dir or $SKELAGNOSTIC_CACHE to a "
            "writable directory"
        ) from exc
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
                fmt = np.lib.format
                version = fmt.read_magic(fh)
                read_header = fmt.read_array_header_1_0 if version == (1, 0) else \
                    fmt.read_array_header_2_0
                shape, _, dtype = read_header(fh)
                data_start = fh.tell()
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
        return CacheEntry(array, info)

    def put(self, key: str, windows: np.ndarray, meta: dict[str, Any]) -> CacheEntry:
        """Store ``windows`` (cast to float32) and ``meta`` atomically under ``key``."""
        array, meta_path = self._paths(key)
        data = np.ascontiguousarray(windows, dtype=np.float32)
        _atomic_write(array, lambda fh: np.save(fh, data))
        _atomic_write(meta_path, lambda fh: fh.write(json.dumps(meta).encode()))
        return CacheEntry(array, meta)
