"""Stop a run at its first non-finite loss or gradient, with the last good checkpoint kept.

Lightning trains on through NaN and infinite losses (``detect_anomaly`` is a
debugging aid that raises deep inside autograd), saves their weights as
``last.ckpt`` and can choose ``best.ckpt`` on a NaN ``val/loss``.
:class:`StopOnNonFinite` stops the run instead, at the first of:

* a non-finite training loss, before its backward pass (the message names the
  logged ``train/...`` terms that are non-finite, e.g. ``train/rec=nan``);
* a non-finite gradient norm, before the optimiser step;
* a non-finite metric that a checkpoint callback monitors (``val/loss``), before
  the checkpoint callbacks see it, so no ``best.ckpt`` is chosen on it;
* a checkpoint about to be saved with non-finite weights (it is not written).

So every checkpoint a stopped run leaves holds finite weights, and the error
names the newest one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import lightning as L
import torch

from skelagnostic.callbacks.checkpoint import newest_checkpoint
from skelagnostic.core.finite import first_non_finite
from skelagnostic.errors import SkelagnosticError

__all__ = ["NonFiniteTrainingError", "StopOnNonFinite"]


class NonFiniteTrainingError(SkelagnosticError):
    """Training produced a non-finite loss, gradient, metric or weight.

    Attributes:
        step: The global step (optimiser steps taken before it).
        what: What was non-finite (``"train/loss=nan"``, ``"the gradient norm"``, ...).
        checkpoint: The newest checkpoint the run wrote (all weights finite), if any.
    """

    def __init__(self, message: str, step: int, what: str, checkpoint: Path | None) -> None:
        super().__init__(message)
        self.step = step
        self.what = what
        self.checkpoint = checkpoint


def _value(value: Any) -> float | None:
    if isinstance(value, torch.Tensor) and value.numel() == 1:
        return float(value.detach())
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return None


def _non_finite_metrics(metrics: Mapping[str, Any], prefix: str) -> list[str]:
    """``name=value`` of the metrics under ``prefix`` that are NaN or infinite."""
    out = []
    for name in sorted(metrics):
        value = _value(metrics[name])
        if name.startswith(prefix) and value is not None and not math.isfinite(value):
            out.append(f"{name}={value}")
    return out


class StopOnNonFinite(L.Callback):
    """Stop ``fit`` with one error at the first non-finite loss, gradient norm or metric.

    See the module docstring for where it looks. The error
    (:class:`NonFiniteTrainingError`) names the step, what was non-finite and the
    newest checkpoint written before it, whose weights are finite (a save of
    non-finite weights is refused). Runs in 16-bit mixed precision skip the
    gradient check: their gradient scaler skips such steps by design.
    ``skelagnostic fit`` adds this callback to every run.

    Args:
        check_gradients: Also check the gradient norm before each optimiser step.
    """

    def __init__(self, check_gradients: bool = True) -> None:
        self.check_gradients = check_gradients

    def _stop(self, trainer: L.Trainer, what: str) -> NonFiniteTrainingError:
        step, epoch = trainer.global_step, trainer.current_epoch
        newest = newest_checkpoint(trainer)
        checkpoint = None if newest is None else newest[0]
        kept = (
            f"the last checkpoint, with finite weights, is {checkpoint}"
            if checkpoint is not None
            else "no checkpoint was written before it"
        )
        return NonFiniteTrainingError(
            f"training diverged: {what} at step {step} (epoch {epoch}); the run is stopped and "
            f"{kept} (lower the learning rate, or look for NaN/inf in the data)",
            step,
            what,
            checkpoint,
        )

    def on_before_backward(
        self, trainer: L.Trainer, pl_module: L.LightningModule, loss: torch.Tensor
    ) -> None:
        """Stop before the backward pass of a non-finite training loss."""
        if bool(torch.isfinite(loss.detach()).all()):
            return
        terms = _non_finite_metrics(trainer.callback_metrics, "train/")
        what = ", ".join(terms) if terms else f"the training loss is {float(loss.detach())}"
        raise self._stop(trainer, what)

    def on_before_optimizer_step(
        self, trainer: L.Trainer, pl_module: L.LightningModule, optimizer: torch.optim.Optimizer
    ) -> None:
        """Stop before an optimiser step on a non-finite gradient norm."""
        if not self.check_gradients or str(trainer.precision).startswith("16"):
            return
        grads = [p.grad for p in pl_module.parameters() if p.grad is not None]
        if not grads:
            return
        norm = torch.nn.utils.get_total_norm(grads, error_if_nonfinite=False)
        if bool(torch.isfinite(norm)):
            return
        name = first_non_finite(
            (n, p.grad) for n, p in pl_module.named_parameters() if p.grad is not None
        )
        where = f" (first non-finite gradient: {name})" if name else ""
        raise self._stop(trainer, f"the gradient norm is {float(norm)}{where}")

    def _check_monitored(self, trainer: L.Trainer) -> None:
        monitored = {
            m
            for c in trainer.checkpoint_callbacks
            if isinstance(m := getattr(c, "monitor", None), str)
        }
        metrics = trainer.callback_metrics
        bad = [t for t in _non_finite_metrics(metrics, "") if t.split("=")[0] in monitored]
        if bad:
            raise self._stop(trainer, ", ".join(bad))

    def on_validation_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """Stop on a non-finite monitored metric before a checkpoint is chosen on it."""
        if not trainer.sanity_checking:
            self._check_monitored(trainer)

    def on_train_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        """The same for checkpoints saved at the end of a training epoch."""
        self._check_monitored(trainer)

    def on_save_checkpoint(
        self, trainer: L.Trainer, pl_module: L.LightningModule, checkpoint: dict[str, Any]
    ) -> None:
        """Refuse to save non-finite weights (the previous checkpoint stays the newest)."""
        name = first_non_finite(checkpoint.get("state_dict", {}).items())
        if name is not None:
            raise self._stop(trainer, f"the weight {name} is not finite")
