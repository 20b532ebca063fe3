"""Lightning's Rich progress bar, with the epoch line right for runs without an epoch limit."""

from __future__ import annotations

from lightning.pytorch.callbacks import RichProgressBar

__all__ = ["RichProgress"]


class RichProgress(RichProgressBar):
    """:class:`~lightning.pytorch.callbacks.RichProgressBar` for step-limited runs.

    Lightning 2.6 writes ``Epoch 51/-2`` when ``max_epochs=-1`` (no epoch limit,
    what ``trainer.max_steps=N`` sets in ``skelagnostic fit``): Lightning issue
    #21925, fixed upstream after 2.6.6. This bar writes ``Epoch 51`` followed by
    the step limit (``Epoch 51 · max 5000 steps``) in that case and is
    Lightning's bar otherwise. The configuration ``callbacks=default`` uses it.
    """

    def _get_train_description(self, current_epoch: int) -> str:
        trainer = self.trainer
        if trainer.max_epochs is None or trainer.max_epochs >= 0:
            return super()._get_train_description(current_epoch)
        description = f"Epoch {current_epoch}"
        if trainer.max_steps is not None and trainer.max_steps >= 0:
            description += f" · max {trainer.max_steps} steps"
        return f"{description:{len(self.validation_description)}}"
