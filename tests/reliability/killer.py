"""A callback that kills its own process after a given training step (resume tests)."""

from __future__ import annotations

import os
import signal
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
