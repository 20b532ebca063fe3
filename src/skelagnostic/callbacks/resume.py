"""Exact resume from epoch-end checkpoints of runs that set ``max_steps``.

Lightning restarts a run whose ``trainer.max_steps`` is set ("iteration-based
training") as if its checkpoint had been written in the middle of an epoch,
even when it was written at the end of one (``on_train_epoch_end``, which is
where :class:`~lightning.pytorch.callbacks.ModelCheckpoint` saves in a run
without validation batches). The resumed run then re-enters the finished
epoch, finds no batch left, counts it as a further epoch and ends short of the
uninterrupted run. Lightning does this so that a run stopped by ``max_steps``
in the middle of a pass can continue that pass with a larger ``max_steps``.
:class:`ResumeFromEpochEnd` keeps that, and restarts a run whose checkpointed
epoch had run its last batch like Lightning restarts runs without ``max_steps``.
"""

from __future__ import annotations

import lightning as L
from lightning.pytorch.loops.fit_loop import _FitLoop
from lightning.pytorch.loops.loop import _Loop

__all__ = ["ResumeFromEpochEnd"]


class _EpochEndAwareFitLoop(_FitLoop):
    """Lightning's fit loop, not restarting an epoch that ran its last batch."""

    @_FitLoop.restarting.setter
    def restarting(self, restarting: bool) -> None:
        current = self.epoch_progress.current
        finished = current.ready == current.started == current.processed
        if restarting and finished and self.epoch_loop.batch_progress.is_last_batch:
            _Loop.restarting.fset(self, False)  # what _FitLoop does without max_steps
        else:
            _FitLoop.restarting.fset(self, restarting)


class ResumeFromEpochEnd(L.Callback):
    """Resume a ``max_steps`` run from an epoch-end checkpoint with the next epoch.

    At ``setup`` of a ``fit``, Lightning's fit loop gets a restart rule that
    treats a checkpoint written after the last batch of an epoch as the end of
    that epoch (as Lightning does when ``max_steps`` is not set), so the
    resumed run ends with the steps and weights of an uninterrupted one.
    Checkpoints written during an epoch, and runs stopped by ``max_steps``
    before the end of a pass, restart as in Lightning. Trainers with a custom
    fit loop are left alone. ``skelagnostic fit`` adds this callback to every run.
    """

    def setup(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        """Give the trainer's fit loop the epoch-end restart rule (before the checkpoint loads)."""
        if stage == "fit" and type(trainer.fit_loop) is _FitLoop:
            trainer.fit_loop.__class__ = _EpochEndAwareFitLoop
