"""Checkpoints of runs without validation data, and of runs that stop inside an epoch.

Lightning's :class:`~lightning.pytorch.callbacks.ModelCheckpoint` writes
``last.ckpt`` only after it saved a top-k checkpoint in the same step. When it
monitors a validation metric (the default callbacks monitor ``val/loss``) and
the run has no validation batches (``data.val_fraction=0``,
``trainer.limit_val_batches=0``), the metric never appears: it warns every
epoch and writes nothing until training ends, so a killed run loses all its
epochs. :class:`LatestWithoutValidation` turns such callbacks into "keep the
latest epoch" at the start of training.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
from lightning.pytorch.utilities import rank_zero_info

__all__ = [
    "FinalStepCheckpoint",
    "FinalStepValidation",
    "LatestWithoutValidation",
    "newest_checkpoint",
]


def newest_checkpoint(trainer: L.Trainer) -> tuple[Path, int] | None:
    """The newest checkpoint file the trainer's checkpoint callbacks wrote, with its step.

    For each callback, its ``last.ckpt`` (else its best checkpoint) if the file exists;
    of those, the one saved at the latest global step.

    Args:
        trainer: The trainer of the run.

    Returns:
        ``(path, global step)``, or ``None`` when no checkpoint file exists yet.
    """
    found: list[tuple[int, Path]] = []
    for callback in trainer.checkpoint_callbacks:
        step = int(getattr(callback, "_last_global_step_saved", -1))
        for attr in ("last_model_path", "best_model_path"):
            path = getattr(callback, attr, "")
            if path and Path(path).is_file():
                found.append((step, Path(path)))
                break
    if not found:
        return None
    step, path = max(found, key=lambda item: item[0])
    return path, step


class LatestWithoutValidation(L.Callback):
    """Without validation batches, checkpoints that monitor ``val/...`` keep the latest epoch.

    At ``on_train_start`` (after Lightning has loaded and counted the validation
    batches), every checkpoint callback whose ``monitor`` starts with ``prefix``
    gets ``monitor=None`` when the run has no validation batch
    (``limit_val_batches=0``, or loaded validation data without a batch): its top-k file then
    holds the latest epoch, and ``last.ckpt`` is written every epoch as usual.
    Runs with validation data, or whose validation data is not loaded before
    the first validation epoch (``check_val_every_n_epoch > 1``), are left
    alone. ``skelagnostic fit`` adds this callback to every run.

    Args:
        prefix: Monitored metric names this applies to.
    """

    def __init__(self, prefix: str = "val/") -> None:
        self.prefix = prefix

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Switch the monitoring checkpoints off when there is no validation batch."""
        if trainer.limit_val_batches != 0:
            if trainer.val_dataloaders is None:
                return  # not loaded yet (e.g. check_val_every_n_epoch > 1): unknown, keep
            batches = trainer.num_val_batches
            if sum(batches) if isinstance(batches, list) else batches:
                return
        for callback in trainer.checkpoint_callbacks:
            monitor = getattr(callback, "monitor", None)
            if isinstance(monitor, str) and monitor.startswith(self.prefix):
                rank_zero_info(
                    f"no validation batches: the checkpoint callback monitoring {monitor!r} "
                    f"keeps the latest epoch instead (files in {callback.dirpath})"
                )
                callback.monitor = None


class FinalStepCheckpoint(L.Callback):
    """``last.ckpt`` holds the final step also when training stops mid-epoch.

    A run sized in steps (``trainer.max_steps``, ``max_time``) usually stops
    inside an epoch. Lightning's ``ModelCheckpoint`` writes ``last.ckpt`` at
    epoch ends and validations, so the steps since then were in no checkpoint.
    At ``on_train_end`` every ``save_last`` checkpoint callback whose latest
    save is older than the final step saves ``last.ckpt`` again (through the
    callback itself, so its naming and link options apply). ``skelagnostic
    fit`` adds this callback to every run.
    """

    def on_train_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Save ``last.ckpt`` of the final step where it is missing."""
        for callback in trainer.checkpoint_callbacks:
            saved = getattr(callback, "_last_global_step_saved", None)
            save = getattr(callback, "_save_last_checkpoint", None)
            if (
                getattr(callback, "save_last", False)
                and save is not None
                and saved is not None
                and saved < trainer.global_step
            ):
                save(trainer, callback._monitor_candidates(trainer))


class FinalStepValidation(L.Callback):
    """Validate the final step of a run that ``max_steps`` stops inside an epoch.

    Lightning validates at the end of each epoch (or every ``val_check_interval``
    batches); a run sized in steps that ends between two validations then has no
    validation figure of its trained weights, and ``best.ckpt`` can only be an
    earlier state. At the batch that reaches ``trainer.max_steps`` this callback
    asks the trainer to stop (``trainer.should_stop``), which Lightning answers
    with one more validation, as after early stopping; its checkpoint callbacks
    then compare the final weights too. Runs that end at an epoch's last batch,
    epochs without validation (``check_val_every_n_epoch``) and runs without
    validation data are left alone. ``skelagnostic fit`` adds this callback to
    every run.
    """

    def on_train_batch_end(
        self,
        trainer: L.Trainer,
        pl_module: L.LightningModule,
        outputs: object,
        batch: object,
        batch_idx: int,
    ) -> None:
        """Request the stop (and so the validation) at the batch that reaches ``max_steps``."""
        limit = trainer.max_steps
        if limit is None or limit < 0 or trainer.global_step < limit or trainer.should_stop:
            return
        if trainer.fit_loop.epoch_loop.batch_progress.is_last_batch:
            return  # the epoch ends here: Lightning validates anyway
        trainer.should_stop = True
