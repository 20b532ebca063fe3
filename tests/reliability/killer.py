"""Signals at chosen moments: callbacks for training steps, a runner for file writes.

``KillAt`` and ``PoisonAt`` are Lightning callbacks (``+callbacks.x._target_=killer.KillAt``).
``python -m killer PATTERN VERB ARGS...`` runs ``skelagnostic VERB ARGS...`` and sends
SIGTERM to itself when a file whose path contains ``PATTERN`` is about to be renamed into
place (the atomic writer's last step: its temporary file exists, complete), once.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any

import lightning as L
import torch


class KillAt(L.Callback):
    """Send ``signum`` to this process when ``trainer.global_step`` reaches ``step``.

    It fires in ``on_train_batch_end`` before :class:`ModelCheckpoint` (Lightning
    runs checkpoint callbacks last), so the newest checkpoint is the previous step's.

    Args:
        step: Global step (optimizer steps taken) at which to kill.
        signum: Signal number, e.g. 9 (SIGKILL) or 15 (SIGTERM).
    """

    def __init__(self, step: int, signum: int) -> None:
        self.step = step
        self.signum = signal.Signals(signum)

    def on_train_batch_end(self, trainer: L.Trainer, *args: Any) -> None:
        """Kill the process at :attr:`step`."""
        if trainer.global_step == self.step:
            os.kill(os.getpid(), self.signum)


class PoisonAt(L.Callback):
    """Fill the first parameter of the module with NaN when ``trainer.global_step`` is ``step``.

    It fires in ``on_train_batch_start``, so the training step at ``step`` computes
    a NaN loss from finite data (a diverged run, made deterministic).

    Args:
        step: Global step (optimizer steps taken) at which to poison the weights.
    """

    def __init__(self, step: int) -> None:
        self.step = step

    def on_train_batch_start(
        self, trainer: L.Trainer, pl_module: L.LightningModule, *args: Any
    ) -> None:
        """Poison the weights at :attr:`step`."""
        if trainer.global_step == self.step:
            with torch.no_grad():
                next(pl_module.parameters()).fill_(float("nan"))


def sigterm_at_replace(pattern: str) -> None:
    """Make ``os.replace`` send SIGTERM to this process before renaming onto ``*pattern*``.

    Fires once. The signal is delivered while the atomic writer's temporary file
    exists, before the rename.
    """
    real = os.replace
    fired: list[str] = []

    def replace(src: Any, dst: Any, *args: Any, **kwargs: Any) -> None:
        if not fired and pattern in os.fspath(dst):
            fired.append(os.fspath(dst))
            os.kill(os.getpid(), signal.SIGTERM)
        real(src, dst, *args, **kwargs)

    os.replace = replace


if __name__ == "__main__":
    sigterm_at_replace(sys.argv[1])
    from skelagnostic.cli import main

    sys.exit(main(sys.argv[2:]))
