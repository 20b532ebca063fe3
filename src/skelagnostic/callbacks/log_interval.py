"""Short runs log their training metrics: the logging interval fitted to the run's length."""

from __future__ import annotations

import lightning as L

__all__ = ["AdaptiveLogInterval"]


class AdaptiveLogInterval(L.Callback):
    """Logs ``train/*`` at least every few steps on short runs.

    At the start of training, ``trainer.log_every_n_steps`` becomes at most
    the number of batches per epoch and at most a twentieth of ``max_steps``
    (never below 1), so a 40-step run logs its loss instead of nothing.
    """

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Shorten the interval to the run's length."""
        interval = int(trainer.log_every_n_steps)
        if interval <= 0:
            return
        batches = trainer.num_training_batches
        if isinstance(batches, int) or (isinstance(batches, float) and batches != float("inf")):
            interval = min(interval, max(1, int(batches)))
        if trainer.max_steps and trainer.max_steps > 0:
            interval = min(interval, max(1, trainer.max_steps // 20))
        trainer.log_every_n_steps = interval
