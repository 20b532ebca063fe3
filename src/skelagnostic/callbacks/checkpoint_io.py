"""Atomic checkpoint files: a kill during a save never destroys the previous checkpoint.

Lightning's :class:`~lightning.fabric.plugins.io.TorchCheckpointIO` saves through
an fsspec transaction: the checkpoint goes to a temporary file in ``$TMPDIR``,
then is moved onto its path, which is a copy whenever ``$TMPDIR`` is on another
file system. A process killed during that copy leaves a truncated (often empty)
``last.ckpt``, the previous good one already overwritten, and the temporary file
(as large as the checkpoint) in ``$TMPDIR``. :class:`AtomicCheckpointIO` writes
next to the checkpoint instead and renames.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from lightning.fabric.plugins.io import TorchCheckpointIO
from lightning.fabric.utilities.types import _PATH

from skelagnostic.io.atomic import atomic_write

__all__ = ["TEMP_SUFFIX", "AtomicCheckpointIO", "atomic_torch_save"]

#: Suffix of the file a checkpoint is written to before it is renamed onto its path.
TEMP_SUFFIX = ".tmp"


def atomic_torch_save(obj: Any, path: str | os.PathLike[str]) -> None:
    """``torch.save(obj, path)`` so that ``path`` holds either its old or its new content.

    The object goes through :func:`skelagnostic.io.atomic.atomic_write`: it is
    written to ``<path>.tmp`` in the same directory (replacing a stale one a
    killed save left behind), flushed to disk with ``fsync``, renamed onto
    ``path`` with :func:`os.replace` (atomic on POSIX and Windows), and the
    directory is flushed too. If ``path`` is a symbolic link, the link is
    replaced, not the file it points to. A new file gets the permissions of a
    newly created file (``0o666`` less the process umask); an existing one
    keeps its permission bits.
    On an error the temporary file is removed and the error raised; a
    ``SIGKILL`` can leave the temporary file, never a damaged ``path``.

    Args:
        obj: What to save (anything :func:`torch.save` accepts).
        path: Destination file; its directory is created if needed.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(
        target,
        lambda fh: torch.save(obj, fh),
        follow_symlinks=False,
        temp_suffix=TEMP_SUFFIX,
        sync_directory=True,
    )


class AtomicCheckpointIO(TorchCheckpointIO):
    """Lightning checkpoint I/O whose saves are atomic and leave no temporary file.

    Each local checkpoint is written by :func:`atomic_torch_save`: to
    ``<name>.tmp`` in its own directory, ``fsync``-ed, then renamed onto
    ``<name>``. Until the rename the previous file of that name is intact, so a
    process killed at any moment leaves a loadable checkpoint (the previous
    one, or none if it had never been written); nothing goes to ``$TMPDIR``; a
    ``<name>.tmp`` left by a kill is overwritten by the next save of that name.
    Files are created with the process umask (like any other file the run
    writes, not ``0600``). Loading and :meth:`remove_checkpoint` are
    :class:`~lightning.fabric.plugins.io.TorchCheckpointIO`'s; remote paths
    (``s3://...``) are saved by it too.

    Give it to the trainer as a plugin; ``skelagnostic fit`` does for every
    run. Lightning's strategies call it on global rank 0 only, so under DDP one
    process writes. It works with :class:`~lightning.pytorch.callbacks.ModelCheckpoint`
    (``save_last=True`` writes ``last.ckpt`` through it; with ``save_last="link"``
    Lightning points ``last.ckpt`` at the newest checkpoint, written atomically).

    Example:
        >>> import lightning as L
        >>> from skelagnostic.callbacks import AtomicCheckpointIO
        >>> trainer = L.Trainer(plugins=[AtomicCheckpointIO()], logger=False)
        >>> type(trainer.strategy.checkpoint_io).__name__
        'AtomicCheckpointIO'
    """

    def save_checkpoint(
        self, checkpoint: dict[str, Any], path: _PATH, storage_options: Any | None = None
    ) -> None:
        """Write ``checkpoint`` to ``path`` atomically (local paths; others as Lightning does).

        Args:
            checkpoint: The trainer's checkpoint dict.
            path: Destination file.
            storage_options: Not supported (as in ``TorchCheckpointIO``).

        Raises:
            TypeError: ``storage_options`` is given.
        """
        if storage_options is not None:
            raise TypeError(
                "`Trainer.save_checkpoint(..., storage_options=...)` is not supported by "
                f"{type(self).__name__}"
            )
        text = os.fspath(path)
        if "://" in text and not text.startswith("file://"):
            super().save_checkpoint(checkpoint, path)
            return
        atomic_torch_save(checkpoint, text.removeprefix("file://"))
