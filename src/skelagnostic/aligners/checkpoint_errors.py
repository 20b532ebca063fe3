"""The errors of checkpoint loading, shared by the checkpoint and weights readers."""

from __future__ import annotations

from pathlib import Path

from skelagnostic.errors import SkelagnosticError

__all__ = ["CheckpointError", "CheckpointNotFoundError"]


class CheckpointError(SkelagnosticError):
    """A checkpoint that cannot be loaded, with the file and the cause in one line.

    Attributes:
        path: The checkpoint file.
        option: The option or argument that named it (``ckpt_path``, ``ckpt``, ...).
        reason: The cause, without the location prefix.
    """

    def __init__(self, path: str | Path, reason: str, option: str = "checkpoint") -> None:
        self.path = Path(path)
        self.option = option
        self.reason = reason
        super().__init__(f"{option}: {reason}")


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """The checkpoint file does not exist (also a :class:`FileNotFoundError`)."""
