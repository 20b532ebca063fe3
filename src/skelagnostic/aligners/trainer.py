"""A quiet Lightning trainer for training inside code: benchmarks, protocols, tests."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import lightning as L

__all__ = ["QUIET_TRAINER_OPTIONS", "quiet_trainer"]

#: The ``lightning.Trainer`` options of :func:`quiet_trainer`: no logger, no checkpoints,
#: no progress bar, no model summary (read-only; override them through its arguments).
QUIET_TRAINER_OPTIONS: Mapping[str, Any] = MappingProxyType(
    {
        "logger": False,
        "enable_checkpointing": False,
        "enable_progress_bar": False,
        "enable_model_summary": False,
    }
)


def quiet_trainer(**overrides: Any) -> L.Trainer:
    """A ``lightning.Trainer`` that writes and prints nothing of its own.

    For training that is a step of other code (a benchmark, an evaluation
    protocol, an ablation) rather than a run of its own: no logger, no
    checkpoint callback, no progress bar and no model summary
    (:data:`QUIET_TRAINER_OPTIONS`). ``trainer.save_checkpoint(path)`` still
    writes a checkpoint when asked.

    Args:
        **overrides: Any other ``lightning.Trainer`` arguments (``max_steps``,
            ``accelerator``, ``callbacks``, ``default_root_dir``, ...); they also
            win over :data:`QUIET_TRAINER_OPTIONS` (e.g. ``logger=CSVLogger(...)``).

    Returns:
        The trainer.

    Example:
        >>> trainer = quiet_trainer(max_steps=10, accelerator="cpu", limit_val_batches=0)
        >>> trainer.logger is None and trainer.checkpoint_callback is None
        True
    """
    return L.Trainer(**{**QUIET_TRAINER_OPTIONS, **overrides})
