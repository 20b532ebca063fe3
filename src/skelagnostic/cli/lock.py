"""The lock file of a directory one command writes (a run directory, ``demo``'s ``out=``).

Standard library only, so that verbs without training (``demo``) take the lock
without importing Lightning or Hydra.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["LOCK_FILE", "RunDirectoryLock", "RunDirectoryRefused"]

#: The lock file a command holds in its run directory while it runs (deleted at its end).
LOCK_FILE = ".skelagnostic.lock"


class RunDirectoryRefused(BaseException):
    """A command may not use the run directory it was given; the message says why.

    A ``BaseException`` on purpose: it is raised by :class:`RunDirectoryGuard`, a
    Hydra callback, and Hydra turns a callback's ``Exception`` into a warning and
    goes on to create the directory. The CLI prints it as one error line.
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def _pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine (``True`` when that cannot be told)."""
    if pid <= 0:
        return False
    if os.name != "posix":
        return True  # os.kill(pid, 0) would terminate it on Windows
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, owned by someone else
        return True
    return True


class RunDirectoryLock:
    """The lock file ``<run_dir>/.skelagnostic.lock`` of the command writing a run directory.

    The file holds the process id of its holder. On POSIX the holder also keeps an
    ``fcntl.flock`` on it, which the kernel drops when the process ends, however it
    ends: a lock file left by a killed process (a stale lock, its PID dead) is taken
    over. Elsewhere, a lock file whose PID is not running is taken over.
    :meth:`release` deletes the file.

    Args:
        run_dir: The run directory (created if missing).
        key: The option naming it, for the message (``demo`` locks its ``out``).

    Example:
        >>> import tempfile
        >>> lock = RunDirectoryLock(Path(tempfile.mkdtemp()) / "run")
        >>> lock.acquire()
        >>> (lock.path.parent / LOCK_FILE).is_file()
        True
        >>> lock.release()
        >>> lock.path.exists()
        False
    """

    def __init__(self, run_dir: str | Path, key: str = "hydra.run.dir") -> None:
        self.path = Path(run_dir) / LOCK_FILE
        self.key = key
        self._fd: int | None = None

    def _busy(self, pid: int | None) -> RunDirectoryRefused:
        holder = f"process {pid}" if pid else "another process"
        advice = (
            "a run directory belongs to one run: name another directory, or leave "
            "hydra.run.dir out (each run then gets a new one)"
            if self.key == "hydra.run.dir"
            else f"name another {self.key}= or wait until it ends"
        )
        return RunDirectoryRefused(
            f"{self.key}={str(self.path.parent)!r} is in use by another command "
            f"({holder} holds {self.path.name}); {advice}"
        )

    @staticmethod
    def _read_pid(fd: int) -> int | None:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 64).decode("ascii", "replace").strip()
        return int(text) if text.isdigit() else None

    def acquire(self) -> None:
        """Take the lock (creating the directory and the file).

        Raises:
            RunDirectoryRefused: A running process holds it.
            OSError: The directory or the file cannot be created.
        """
        created = not self.path.parent.exists()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        existed = os.path.lexists(self.path)
        try:
            self._acquire()
        except OSError:  # e.g. a full disk: leave no lock file, nor the folder made for it
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None
            with contextlib.suppress(OSError):
                if not existed:
                    self.path.unlink()
                if created:
                    self.path.parent.rmdir()
            raise

    def _acquire(self) -> None:
        try:
            import fcntl
        except ImportError:  # not POSIX: the PID in the file decides
            self._acquire_by_pid()
            return
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = self._read_pid(fd)
                os.close(fd)
                raise self._busy(pid) from None
            except OSError:  # a file system without flock (some NFS): the PID decides
                os.close(fd)
                self._acquire_by_pid()
                return
            try:  # the holder may have deleted the file between our open and flock
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        self._fd = fd
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, f"{os.getpid()}\n".encode())

    def _acquire_by_pid(self) -> None:
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                with open(self.path, "rb") as fh:
                    text = fh.read(64).decode("ascii", "replace").strip()
                pid = int(text) if text.isdigit() else None
                if pid is not None and _pid_alive(pid):
                    raise self._busy(pid) from None
                with contextlib.suppress(FileNotFoundError):
                    self.path.unlink()  # a stale lock: its process is gone
                continue
            self._fd = fd
            os.write(fd, f"{os.getpid()}\n".encode())
            return
        raise self._busy(None)

    def release(self) -> None:
        """Delete the lock file and drop the lock (nothing happens when it is not held)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):  # the run directory may have been discarded
            self.path.unlink()
        os.close(self._fd)  # also drops the flock
        self._fd = None
