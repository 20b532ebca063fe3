"""Why a fit ended: the trainer limit it reached, early stopping, or an interruption.

:func:`stop_reason` reads it from a trainer after (or during) ``trainer.fit``;
:class:`StopReason` keeps it for the end-of-run summary (``skelagnostic fit`` adds one
to every run: its reason is the ``stopped`` row of the summary table and a line of
``summary.md``).
"""

from __future__ import annotations

import datetime

import lightning.pytorch as pl
from lightning.pytorch.callbacks import EarlyStopping, Timer

__all__ = ["StopReason", "stop_reason"]


def _step(trainer: pl.Trainer) -> str:
    """``step N of M`` (``M``: ``max_steps``) or ``step N (epoch E of M)``."""
    step = trainer.global_step
    if trainer.max_steps is not None and trainer.max_steps > 0:
        return f"step {step} of {trainer.max_steps}"
    if trainer.max_epochs is not None and trainer.max_epochs > 0:
        return f"step {step} (epoch {trainer.current_epoch + 1} of {trainer.max_epochs})"
    return f"step {step}"


def _timer_limit(trainer: pl.Trainer) -> datetime.timedelta | None:
    """The ``max_time`` a Timer callback ran out of, if one did."""
    for callback in trainer.callbacks:  # type: ignore[attr-defined]
        if not isinstance(callback, Timer):
            continue
        remaining = callback.time_remaining()
        if remaining is not None and remaining <= 0:
            total = callback.time_elapsed() + remaining
            return datetime.timedelta(seconds=round(total))
    return None


def _early_stopping(trainer: pl.Trainer) -> str | None:
    """What an EarlyStopping callback that stopped the run said, if one did."""
    for callback in trainer.callbacks:  # type: ignore[attr-defined]
        if not isinstance(callback, EarlyStopping):
            continue
        message = getattr(callback, "stopping_reason_message", None)
        reason = getattr(callback, "stopping_reason", None)
        stopped = getattr(reason, "name", "") not in ("", "NOT_STOPPED") or callback.stopped_epoch
        if stopped:
            why = message or f"{callback.monitor} did not improve for {callback.patience} checks"
            return f"early stopping ({' '.join(why.split())}) at {_step(trainer)}"
    return None


def stop_reason(trainer: pl.Trainer) -> str | None:
    """Why ``trainer.fit`` ended, in one line.

    In order: an interruption (Ctrl-C), ``max_steps`` reached, ``max_time`` reached,
    early stopping, ``max_epochs`` reached, another callback setting
    ``trainer.should_stop``, no training batches.

    Args:
        trainer: The trainer, after ``fit`` (or when it ends).

    Returns:
        For example ``"max_time 0:04:30 reached at step 4 of 20"`` or
        ``"max_steps 20 reached"``; ``None`` when none of those applies.

    Example:
        >>> import lightning as L
        >>> stop_reason(L.Trainer(max_epochs=1, logger=False)) is None
        True
    """
    if trainer.interrupted:
        return f"interrupted at {_step(trainer)}"
    max_steps = trainer.max_steps
    if max_steps is not None and max_steps > 0 and trainer.global_step >= max_steps:
        return f"max_steps {max_steps} reached"
    limit = _timer_limit(trainer)
    if limit is not None:
        return f"max_time {limit} reached at {_step(trainer)}"
    early = _early_stopping(trainer)
    if early is not None:
        return early
    max_epochs = trainer.max_epochs
    if max_epochs is not None and max_epochs > 0 and trainer.current_epoch >= max_epochs:
        return f"max_epochs {max_epochs} reached at step {trainer.global_step}"
    if trainer.should_stop:
        return f"stopped by a callback (trainer.should_stop) at {_step(trainer)}"
    if trainer.num_training_batches == 0:
        return "no training batches"
    return None


class StopReason(pl.Callback):
    """Keeps :func:`stop_reason` of the fit it watched in :attr:`reason`.

    An interrupted fit (Ctrl-C) does not reach ``on_fit_end``; the reason is then
    recorded from ``on_exception`` (the CLI's :class:`~skelagnostic.callbacks.ResumeHint`
    prints the line for it).
    """

    def __init__(self) -> None:
        #: Why the last fit ended (None: not ended, or no reason found).
        self.reason: str | None = None

    def on_fit_end(self, trainer: pl.Trainer, pl_module: pl.LightningModule) -> None:
        """Record why the fit ended."""
        self.reason = stop_reason(trainer)

    def on_exception(
        self, trainer: pl.Trainer, pl_module: pl.LightningModule, exception: BaseException
    ) -> None:
        """Record an interruption by Ctrl-C."""
        if isinstance(exception, KeyboardInterrupt):
            self.reason = f"interrupted (Ctrl-C) at {_step(trainer)}"
