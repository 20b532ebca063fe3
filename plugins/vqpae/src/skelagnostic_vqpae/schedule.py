r"""The WalkTheDog authors' learning-rate and weight-decay schedule: VQ-PAE's ``model.scheduler``.

Their ``train_vq.py`` trains with AdamW and ``CyclicLRWithRestarts`` (Loshchilov &
Hutter, "Decoupled weight decay regularization", policy ``cosine``). Per
optimiser step, with ``t`` the epoch position (epochs since the cycle's start
plus the fraction of the epoch done, ``i / n`` for the ``i``-th batch, where
``n`` is the batches per epoch, plus one when the dataset is not a whole number
of batches) and ``P`` the cycle length in epochs:

* $\eta = (1 + \cos(\pi t / P)) / 2$;
* learning rate $\mathrm{lr}_{\min} + (\mathrm{lr} - \mathrm{lr}_{\min})\,\eta$ with
  $\mathrm{lr}_{\min} = 10^{-7}$;
* weight decay $w\,\eta\,\sqrt{b / (N P)}$ ("normalised" weight decay: ``b`` the batch
  size, ``N`` the samples per epoch), applied as ``p <- p (1 - wd)``, not scaled by the
  learning rate (PyTorch's ``AdamW`` multiplies it by the rate, so this schedule
  sets the group's ``weight_decay`` to ``wd / lr``);
* a cycle lasts ``P`` epochs, then ``P <- ceil(P * mult)``; the first step of a
  restart epoch still belongs to the ending cycle (``t = P``: the minimum rate and no
  weight decay), as in their scheduler.

Their epoch is one pass over the smallest dataset. :func:`authors_restarts` builds it
for ``model.scheduler`` (the default); :func:`cosine_restarts` is PyTorch's cosine
annealing with warm restarts over the data module's epochs, on every group.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch.optim import Optimizer
from torch.optim.lr_scheduler import LRScheduler

from skelagnostic.errors import SkelagnosticError

__all__ = [
    "AUTHORS_MIN_LR",
    "CyclicRestarts",
    "authors_epoch",
    "authors_restarts",
    "configure_optimizers",
    "cosine_restarts",
    "cyclic_restart_factors",
]

#: The floor of the authors' learning rate (``CyclicLRWithRestarts(min_lr=1e-7)``).
AUTHORS_MIN_LR = 1e-7


def cyclic_restart_factors(
    step: int, epoch_size: int, batch_size: int, period: int, mult: float
) -> tuple[float, float]:
    """``(eta, P)`` at optimiser step ``step`` (0-based) of the authors' schedule.

    Args:
        step: Optimiser steps taken before this one.
        epoch_size: ``N``, samples per epoch (the smallest dataset's windows).
        batch_size: ``b``, samples per step (incomplete batches are dropped).
        period: Epochs of the first cycle.
        mult: Growth of the cycle length at each restart.

    Returns:
        The cosine factor ``eta`` in ``[0, 1]`` and the cycle length ``P`` (epochs)
        it was computed with (the weight decay's normalisation uses it).

    Raises:
        SkelagnosticError: ``epoch_size < batch_size`` or a non-positive argument.

    Example:
        >>> [round(cyclic_restart_factors(s, 64, 32, 1, 2)[0], 3) for s in range(6)]
        [1.0, 0.5, 0.0, 0.854, 0.5, 0.146]
    """
    if batch_size <= 0 or period <= 0 or mult <= 0 or step < 0:
        raise SkelagnosticError(
            f"cyclic restarts: batch_size, period and mult must be positive and step >= 0, "
            f"got {batch_size}, {period}, {mult}, {step}"
        )
    batches, rest = divmod(epoch_size, batch_size)
    if batches == 0:
        raise SkelagnosticError(
            f"cyclic restarts: an epoch of {epoch_size} samples has no batch of {batch_size}"
        )
    fraction_steps = batches + (1 if rest else 0)  # their linspace(0, 1, batches + 1 or + 2)
    epoch, i = divmod(step, batches)
    start, length = 0, math.ceil(period)
    while epoch >= start + length:
        start, length = start + length, math.ceil(length * mult)
    if start > 0 and epoch == start and i == 0:  # the restart epoch's first step: old cycle ends
        previous = _previous_length(period, mult, start)
        return 0.5 * (1.0 + math.cos(math.pi)), previous
    t = epoch - start + i / fraction_steps
    return 0.5 * (1.0 + math.cos(math.pi * t / length)), length


def _previous_length(period: int, mult: float, start: int) -> int:
    """Length of the cycle that ends at epoch ``start``."""
    begin, length = 0, math.ceil(period)
    while begin + length < start:
        begin, length = begin + length, math.ceil(length * mult)
    return length


class CyclicRestarts(LRScheduler):
    """The authors' schedule on the first ``groups`` parameter groups, stepped per batch.

    Other groups (the average-pose MLPs, which the authors train with their own
    constant-rate Adam) keep their rate and weight decay.

    Args:
        optimizer: A ``torch.optim.AdamW`` (decoupled weight decay ``p *= 1 - lr * wd``).
        epoch_size: Samples per epoch (the smallest dataset's training windows).
        batch_size: Samples per step and dataset.
        period: Epochs of the first cycle (``--restart_period``, 10).
        mult: Cycle growth (``--restart_mult``, 2).
        groups: How many leading parameter groups follow the schedule.
        min_lr: Floor of the rate.
    """

    def __init__(
        self,
        optimizer: Optimizer,
        epoch_size: int,
        batch_size: int,
        period: int,
        mult: float,
        groups: int = 1,
        min_lr: float = AUTHORS_MIN_LR,
    ) -> None:
        self.epoch_size, self.batch_size = int(epoch_size), int(batch_size)
        self.period, self.mult, self.groups, self.min_lr = period, mult, groups, min_lr
        cyclic_restart_factors(0, self.epoch_size, self.batch_size, period, mult)  # validates
        self.base_weight_decays = [g["weight_decay"] for g in optimizer.param_groups]
        super().__init__(optimizer)

    def factors(self) -> tuple[float, float]:
        """``(eta, P)`` of the coming optimiser step (:func:`cyclic_restart_factors`)."""
        return cyclic_restart_factors(
            self.last_epoch, self.epoch_size, self.batch_size, self.period, self.mult
        )

    def get_lr(self) -> list[float]:  # type: ignore[override]
        """Learning rates of the coming step; sets the groups' weight decay too."""
        eta, length = self.factors()
        norm = math.sqrt(self.batch_size / (self.epoch_size * length))
        rates = []
        for k, (group, base) in enumerate(
            zip(self.optimizer.param_groups, self.base_lrs, strict=True)
        ):
            if k >= self.groups:
                rates.append(group["lr"])
                continue
            lr = self.min_lr + (base - self.min_lr) * eta
            # their AdamW: p *= 1 - wd; torch's: p *= 1 - lr * wd
            group["weight_decay"] = self.base_weight_decays[k] * eta * norm / lr
            rates.append(lr)
        return rates


def authors_restarts(
    optimizer: Optimizer, trainer: Any = None, period: int = 10, mult: int = 2
) -> CyclicRestarts:
    """The authors' ``CyclicLRWithRestarts`` on the first parameter group (the VQ-PAE).

    The ``model.scheduler`` target of ``model=vqpae``; the pose MLPs' group keeps
    its constant rate (the authors train them with their own Adam).

    Args:
        optimizer: The AdamW of :func:`configure_optimizers`.
        trainer: The run's trainer (given by the run): its data sets the epoch.
        period: Epochs of the first cycle (``--restart_period``, 10).
        mult: Cycle growth (``--restart_mult``, 2).

    Returns:
        The schedule, stepped per optimizer step.
    """
    _check_period(period, mult)
    epoch_size, batch_size = authors_epoch(trainer)
    return CyclicRestarts(optimizer, epoch_size, batch_size, period, mult, groups=1)


def cosine_restarts(
    optimizer: Optimizer, steps_per_epoch: int = 1, period: int = 10, mult: int = 2
) -> torch.optim.lr_scheduler.CosineAnnealingWarmRestarts:
    """PyTorch's cosine annealing with warm restarts every ``period`` epochs, on every group.

    Args:
        optimizer: The optimizer.
        steps_per_epoch: Optimizer steps per epoch (given by the run).
        period: Epochs of the first cycle.
        mult: Growth of the cycle length at each restart.

    Returns:
        ``CosineAnnealingWarmRestarts``, stepped per optimizer step.
    """
    _check_period(period, mult)
    return torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(
        optimizer, T_0=max(1, period * steps_per_epoch), T_mult=mult
    )


def _check_period(period: int, mult: int) -> None:
    for name, value in (("period", period), ("mult", mult)):
        if not value > 0:
            raise SkelagnosticError(f"model.scheduler.{name} must be positive, got {value}")


def configure_optimizers(aligner: Any) -> Any:
    """``model.optimizer`` + ``model.scheduler`` (per step); pose MLPs in their own group.

    :meth:`VqpaeModel.configure_optimizers
    <skelagnostic_vqpae.training.VqpaeModel.configure_optimizers>`. The first group
    (the VQ-PAEs and the codebook) takes the optimizer's rate and weight decay; the
    pose MLPs' group has ``model.pose_lr`` and no weight decay.
    """
    from skelagnostic.aligners.optim import configure_optimization

    hp = aligner.hparams
    book = aligner._require_built()
    main = [p for c in aligner.characters for p in c.pae.parameters()] + [book.weight]
    groups: list[dict[str, Any]] = [{"params": main}]
    if hp.pose_mlp != "none":
        groups.append(
            {
                "params": [p for c in aligner.characters for p in c.pose.parameters()],
                "lr": hp.pose_lr,
                "weight_decay": 0.0,
            }
        )
    # the fused kernel is 3-4x faster than foreach on this model's ~60 small tensors
    # (1.0 vs 3.4 ms per step on one CPU core); it exists for CPU and CUDA only
    fused = all(p.device.type in ("cpu", "cuda") for p in main)
    speed = {"fused": True} if fused else {"foreach": True}
    trainer = aligner._trainer
    return configure_optimization(hp.optimizer, hp.scheduler, groups, trainer, prefer=speed)


def authors_epoch(trainer: Any) -> tuple[int, int]:
    """``(samples, batch size)`` of the authors' epoch: one pass over the smallest dataset.

    Per rank under DDP. Without a data module's training windows (an aligner
    trained by hand with a plain loader), the trainer's batches per epoch stand
    for the samples, with one sample per batch.
    """
    from skelagnostic.aligners import steps_per_epoch  # Lightning: only when training

    dm = getattr(trainer, "datamodule", None) if trainer is not None else None
    train = getattr(dm, "datasets", {}).get("train") if dm is not None else None
    batch = getattr(dm, "batch_size", None)
    if train and isinstance(batch, int) and batch > 0:
        ranks = max(1, int(getattr(trainer, "world_size", 1)))
        size = min(len(ds) for ds in train.values()) // ranks
        if size >= batch:
            return size, batch
    return steps_per_epoch(trainer), 1
