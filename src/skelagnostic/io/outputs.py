"""Output files of the command line: checked before any is written, written atomically.

Every file a CLI verb produces (renders, viewer pages, summaries, ``config.yaml``,
``evaluation.json``, exports, BVH results) is written by :func:`write_output` or
:func:`output_path`, on top of :mod:`skelagnostic.io.atomic`: a failure (a full
disk, a file-size limit, a read-only directory) leaves the previous file as it was
and becomes one :class:`OutputError` naming the option and the cause.

Verbs call :func:`check_output_file` / :func:`check_output_dir` on every output
location first, so that an unusable one (a directory where a file is expected, a
path under a regular file, a read-only directory, a dangling symbolic link) is
refused before anything is computed or written.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from skelagnostic.errors import SkelagnosticError
from skelagnostic.io.atomic import atomic_path, atomic_write, write_target

__all__ = [
    "OutputError",
    "check_output_dir",
    "check_output_file",
    "output_path",
    "write_output",
]


class OutputError(SkelagnosticError):
    """An output location that cannot be used, or a write that failed (target untouched)."""


def _label(key: str | None, path: str | Path) -> str:
    return f"{key}={str(path)!r}" if key else str(path)


def _failed(key: str | None, path: str | Path, exc: OSError, existed: bool) -> OutputError:
    cause = exc.strerror or str(exc) or type(exc).__name__
    kept = "the previous file is unchanged" if existed else "nothing was written"
    return OutputError(f"{_label(key, path)}: cannot write ({cause}); {kept}")


def _writable_directory(directory: Path, key: str | None, shown: str | Path) -> None:
    """Check that files can be created in ``directory`` (or in the folders it would need)."""
    here = Path(os.path.abspath(directory))  # "out=x.gif" names the working directory
    while not os.path.lexists(here) and here != here.parent:
        here = here.parent
    if os.path.islink(here) and not here.exists():
        raise OutputError(
            f"{_label(key, shown)}: {here} is a symbolic link to "
            f"{os.readlink(here)!r}, which does not exist"
        )
    if not here.is_dir():
        raise OutputError(f"{_label(key, shown)}: {here} is a file, not a directory")
    if not os.access(here, os.W_OK | os.X_OK):
        raise OutputError(f"{_label(key, shown)}: the directory {here} is not writable")


def check_output_file(path: str | Path, key: str | None = None) -> Path:
    """Check, before anything is written, that a file can be written at ``path``.

    Missing parent directories are fine (writers create them); a symbolic link is
    followed (writers replace the file it names).

    Args:
        path: The output file.
        key: The option naming it (``out``, ``html``, ...), for the message.

    Returns:
        The file that will be replaced (links followed).

    Raises:
        OutputError: ``path`` is a directory, lies under a regular file or a
            dangling link, its directory is not writable, or its links form a loop.
    """
    _writable_directory(Path(path).parent, key, path)  # as given: a dangling link is refused
    try:
        target = write_target(path)
    except OSError as exc:
        raise OutputError(f"{_label(key, path)}: {exc.strerror}") from None
    if target.is_dir():
        raise OutputError(f"{_label(key, path)}: is a directory; give a file name")
    _writable_directory(target.parent, key, path)
    return target


def check_output_dir(path: str | Path, key: str | None = None) -> Path:
    """Check, before anything is written, that ``path`` is or can become a writable directory.

    Args:
        path: The output directory (it may not exist yet).
        key: The option naming it (``out``, ``runs_dir``, ...), for the message.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``path`` is a regular file, a dangling symbolic link, lies
            under a regular file, or the directory is not writable.
    """
    directory = Path(path)
    if os.path.islink(directory) and not directory.exists():
        raise OutputError(
            f"{_label(key, path)}: a symbolic link to {os.readlink(directory)!r}, "
            "which does not exist"
        )
    if directory.exists() and not directory.is_dir():
        raise OutputError(f"{_label(key, path)}: is a file, not a directory")
    _writable_directory(directory, key, path)
    return directory


def write_output(
    path: str | Path,
    data: bytes | str | Callable[[BinaryIO], object],
    key: str | None = None,
) -> Path:
    """Write an output file atomically; a failure leaves the previous file unchanged.

    Args:
        path: The file (missing parent directories are created).
        data: The content (``str`` is written as UTF-8), or a function writing it
            to the binary file object it is given.
        key: The option naming the file (``out``, ``html``, ...), for the message.

    Returns:
        The path written (symbolic links followed).

    Raises:
        OutputError: The file cannot be written (full disk, file-size limit,
            read-only directory, ...): one line naming ``key``, the path and the cause.
    """
    content = data.encode("utf-8") if isinstance(data, str) else data
    existed = os.path.lexists(path)
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        return atomic_write(path, content)
    except OutputError:
        raise
    except OSError as exc:
        raise _failed(key, path, exc, existed) from None


@contextlib.contextmanager
def output_path(path: str | Path, key: str | None = None) -> Iterator[Path]:
    """A temporary path for a tool that writes by file name; it replaces ``path`` on success.

    Args:
        path: The output file (missing parent directories are created).
        key: The option naming the file, for the message.

    Yields:
        The temporary path to write (see :func:`~skelagnostic.io.atomic.atomic_path`).

    Raises:
        OutputError: An :class:`OSError` while writing or replacing: ``path`` is
            unchanged. Other exceptions of the body propagate (``path`` unchanged too).
    """
    existed = os.path.lexists(path)
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            yield tmp
    except OutputError:
        raise
    except OSError as exc:
        raise _failed(key, path, exc, existed) from None
