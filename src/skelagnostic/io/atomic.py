"""Atomic file writes that respect the umask and write through symbolic links.

Every file skelagnostic writes in place (BVH files, window-cache entries) goes
through :func:`atomic_write`, so that all of them behave the same way:

* the content goes to a temporary file next to the target, is flushed to disk,
  and replaces the target with one :func:`os.replace`: readers see the old file
  or the new one, never a part of it, and a failed write (a full disk, say)
  leaves the target untouched and removes the temporary file;
* a new file gets the permissions :func:`open` would give it (``0o666`` minus
  the umask, so ``0o644`` under the usual umask ``022``), unlike
  :func:`tempfile.mkstemp`, which always gives ``0o600``; an existing file keeps
  its permission bits;
* a target that is a symbolic link is written through: the file it points to is
  replaced and the link stays a link (``follow_symlinks=False`` replaces the
  link itself, as checkpoint files need);
* with ``sync_directory=True`` the directory entry (the rename) is flushed to
  disk too, where the platform allows it (checkpoints ask for it; BVH files and
  rebuildable cache entries skip the extra ``fsync``).

Tools that write by file name (ffmpeg, exporters) use :func:`atomic_path`: they
write to the temporary path it gives, which replaces the target on success.

Both are one implementation. Checkpoints
(:func:`skelagnostic.callbacks.checkpoint_io.atomic_torch_save`) go through
:func:`atomic_write` with a fixed temporary name, so that a save killed
mid-write leaves one ``<name>.tmp`` that the next save of that name reuses.
Writers that only take a file name (``torch.onnx.export``, ``torch.jit.save``) write
into the temporary file :func:`atomic_path` names, with the same guarantees.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["atomic_path", "atomic_write", "fsync_directory", "write_target"]

_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)


def write_target(path: str | Path) -> Path:
    """The file a write to ``path`` replaces: ``path`` with every symbolic link followed.

    Args:
        path: The path given by the user (it need not exist; a dangling link gives
            the file it names).

    Returns:
        The absolute path of the file to replace.

    Raises:
        OSError: ``ELOOP`` if the links form a loop.
    """
    target = Path(os.path.realpath(path))
    if target.is_symlink():  # realpath stops at a link loop instead of raising
        raise OSError(errno.ELOOP, os.strerror(errno.ELOOP), str(path))
    return target


def fsync_directory(directory: str | Path) -> None:
    """Flush a directory entry (a rename) to disk, where the platform allows it.

    Args:
        directory: The directory whose entries to flush. Platforms that cannot
            open a directory (Windows) or file systems that refuse ``fsync`` on one
            are skipped silently: the rename itself is still atomic there.
    """
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(directory, flags)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def _create_temporary(target: Path, temp_suffix: str | None) -> tuple[int, Path]:
    """Create an empty file next to ``target`` with mode ``0o666`` minus the umask.

    With ``temp_suffix`` the name is fixed (``<name><suffix>``, replacing a stale
    one); otherwise a fresh random name is taken.
    """
    if temp_suffix is not None:
        tmp = target.with_name(target.name + temp_suffix)
        flags = (_FLAGS & ~os.O_EXCL) | os.O_TRUNC
        return os.open(tmp, flags, 0o666), tmp
    for _ in range(100):
        tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp, _FLAGS, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary file name", str(target.parent))


def _existing_mode(target: Path) -> int | None:
    """The permission bits of ``target`` if it is a regular file, else ``None``."""
    try:
        info = os.stat(target)
    except FileNotFoundError:
        return None
    return stat.S_IMODE(info.st_mode) if stat.S_ISREG(info.st_mode) else None


def _fsync_file(path: Path) -> None:
    """Flush the content of the file at ``path`` to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def _replacing(
    path: str | Path, *, follow_symlinks: bool, temp_suffix: str | None, sync_directory: bool
) -> Iterator[tuple[Path, Path]]:
    """The one implementation of :func:`atomic_path` and :func:`atomic_write`.

    Creates the temporary file next to the target (empty, mode ``0o666`` minus the
    umask) and yields it with the target; when the block ends without an exception
    the temporary file gets the target's mode (its own if it exists, else the new
    file's), is flushed to disk and replaces the target. On an exception the target
    is untouched and the temporary file removed.

    Yields:
        ``(temporary, target)``: the path to write and the file it replaces.
    """
    target = write_target(path) if follow_symlinks else Path(os.path.abspath(path))
    keep_mode = _existing_mode(target)
    fd, tmp = _create_temporary(target, temp_suffix)
    try:
        created = stat.S_IMODE(os.fstat(fd).st_mode)  # 0o666 minus the umask
    finally:
        os.close(fd)
    mode = keep_mode if keep_mode is not None else created
    try:
        yield tmp, target
        os.chmod(tmp, mode)
        _fsync_file(tmp)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if sync_directory:
        fsync_directory(target.parent)


@contextlib.contextmanager
def atomic_path(
    path: str | Path, *, follow_symlinks: bool = True, sync_directory: bool = False
) -> Iterator[Path]:
    """A temporary file next to ``path`` to write by name; it replaces ``path`` at the end.

    For writers that take a file name instead of a file object. The block writes the
    yielded path (an empty file, which the writer may also delete and create again);
    when the block ends without an exception the file gets the mode :func:`atomic_write`
    gives (``path``'s own, else ``0o666`` minus the umask, whatever mode the writer
    created it with), is flushed to disk and replaces ``path``. On an exception
    ``path`` is untouched and the temporary file removed.

    Args:
        path: The file to write (its directory must exist); a symbolic link is
            followed unless ``follow_symlinks=False``.
        follow_symlinks: As in :func:`atomic_write`.
        sync_directory: As in :func:`atomic_write`.

    Yields:
        The temporary path to write.

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> with atomic_path(folder / "out.txt") as tmp:
        ...     _ = tmp.write_text("done")
        >>> (folder / "out.txt").read_text(), [p.name for p in folder.iterdir()]
        ('done', ['out.txt'])
    """
    with _replacing(
        path, follow_symlinks=follow_symlinks, temp_suffix=None, sync_directory=sync_directory
    ) as (tmp, _):
        yield tmp


def atomic_write(
    path: str | Path,
    data: bytes | Callable[[BinaryIO], object],
    *,
    follow_symlinks: bool = True,
    temp_suffix: str | None = None,
    sync_directory: bool = False,
) -> Path:
    """Write a file atomically, with the permissions the umask allows.

    Args:
        path: The file to write. Its directory must exist. A symbolic link is
            followed and the file it points to is replaced.
        data: The content, or a function that writes it to the binary file object
            it is given (e.g. ``lambda fh: np.save(fh, array)``).
        follow_symlinks: Write through a symbolic link (default); ``False``
            replaces the link itself by a regular file.
        temp_suffix: Write to the fixed name ``<name><temp_suffix>`` instead of
            a random one, so that a process killed mid-write leaves at most one
            temporary file, which the next write reuses.
        sync_directory: Also flush the directory entry of the rename to disk.

    Returns:
        The path of the file written (``path``, with symbolic links followed
        unless ``follow_symlinks=False``).

    Raises:
        OSError: The directory is missing or read-only, the disk is full, the links
            form a loop, ...; the target is then untouched and no temporary file
            is left behind. Exceptions raised by ``data`` propagate the same way.
    """
    with _replacing(
        path,
        follow_symlinks=follow_symlinks,
        temp_suffix=temp_suffix,
        sync_directory=sync_directory,
    ) as (tmp, target):
        # os.fdopen, as every writer of the package: the reliability tests fill the
        # disk through it (tests/reliability/test_output_writes.py, full_disk)
        fd = os.open(tmp, os.O_WRONLY | os.O_TRUNC | getattr(os, "O_BINARY", 0))
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data)
    return target
