"""Training-length helpers for learning-rate schedules defined in epochs."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["steps_per_epoch"]


def steps_per_epoch(trainer: Any) -> int:
    """Optimiser steps per training epoch, for schedules whose period is given in epochs.

    Reads ``trainer.estimated_stepping_batches`` (which also sets up the
    training data), then the number of training batches per epoch it found,
    divided by ``accumulate_grad_batches``; ``limit_train_batches`` and the DDP
    sharding are taken into account by the trainer. With ``max_epochs=-1``
    (training bounded by ``max_steps``) the trainer does not count the batches:
    the longest loader of the data module's ``train_dataloader()`` (a
    ``CombinedLoader`` in ``max_size_cycle`` mode, one loader per dataset) is
    counted instead. 1 when nothing has a length. Call it from
    ``configure_optimizers``.

    Args:
        trainer: The Lightning trainer (``None``: 1).

    Returns:
        At least 1.
    """
    if trainer is None:
        return 1
    total = trainer.estimated_stepping_batches
    accumulate = max(1, int(trainer.accumulate_grad_batches))
    batches = trainer.num_training_batches
    if isinstance(batches, (int, float)) and math.isfinite(batches) and batches >= 1:
        return max(1, math.ceil(batches / accumulate))
    epochs = trainer.max_epochs
    if epochs is not None and epochs >= 1 and math.isfinite(total):
        return max(1, int(total // epochs))
    datamodule = getattr(trainer, "datamodule", None)
    if datamodule is None:
        return 1
    loader = datamodule.train_dataloader()
    iterables = getattr(loader, "iterables", loader)
    loaders = iterables.values() if isinstance(iterables, dict) else [iterables]
    try:
        longest = max(len(x) for x in loaders)
    except (TypeError, ValueError):  # a loader without a length, or none
        return 1
    return max(1, math.ceil(longest / accumulate))
