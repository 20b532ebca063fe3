"""The LaFAN1 in-betweening benchmark metrics: L2P, L2Q and NPSS."""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor
from torchmetrics import Metric

from skelagnostic.metrics._checks import check_choice, fail
from skelagnostic.metrics.functional._utils import _mean_compute
from skelagnostic.metrics.functional.lafan import (
    NPSS_POWERS,
    _l2p_update,
    _l2q_update,
    _npss_update,
)
from skelagnostic.metrics.positions import _SumCountMetric

__all__ = ["L2P", "L2Q", "NPSS"]


class L2P(_SumCountMetric):
    """Normalised global-position error of the LaFAN1 benchmark.

    See [`l2p`][skelagnostic.metrics.functional.l2p]. The normalisation
    statistics come from the *training* windows and are fixed at construction
    (non-persistent buffers: they follow ``.to(device)`` but are not saved in
    checkpoints). Every counted frame has the same weight.

    Args:
        mean: Per-channel mean of the training global positions, ``J*3`` values
            (``[J*3]``, ``[J, 3]`` or LaFAN1's ``[1, J*3, 1]``), or a scalar.
        std: Per-channel standard deviation, same layout, all ``> 0``.
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = L2P(mean=torch.zeros(3), std=torch.ones(3))
        >>> target = torch.zeros(2, 4, 1, 3)                 # [B, T, J, 3]
        >>> preds = target + torch.tensor([0.0, 0.0, 1.0])
        >>> transition = torch.tensor([[False, True, True, False]] * 2)
        >>> metric.update(preds, target, mask=transition)
        >>> metric.compute()
        tensor(1.)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0
    mean: Tensor
    std: Tensor

    def __init__(self, mean: Tensor | float, std: Tensor | float, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        mean_t = torch.as_tensor(mean, dtype=torch.get_default_dtype()).reshape(-1)
        std_t = torch.as_tensor(std, dtype=torch.get_default_dtype()).reshape(-1)
        if not bool(torch.isfinite(mean_t).all()) or not bool(torch.isfinite(std_t).all()):
            raise fail("L2P", "mean and std must be finite")
        if bool((std_t <= 0).any()):
            raise fail("L2P", "std must be > 0 in every channel")
        self.register_buffer("mean", mean_t, persistent=False)
        self.register_buffer("std", std_t, persistent=False)

    def update(self, preds: Tensor, target: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate global positions ``[B, T, J, 3]``; ``mask`` ``[B, T]`` picks the frames."""
        self._accumulate(*_l2p_update(preds, target, self.mean, self.std, mask))


class L2Q(_SumCountMetric):
    """Global-quaternion error of the LaFAN1 benchmark.

    See [`l2q`][skelagnostic.metrics.functional.l2q] (including the removal of
    quaternion sign flips along time). Every counted frame has the same weight.

    Args:
        continuity: Remove sign flips along time before comparing (default ``True``).
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = L2Q()
        >>> target = torch.tensor([1.0, 0.0, 0.0, 0.0]).expand(1, 4, 2, 4)
        >>> preds = target.clone()
        >>> preds[0, 1:3, 0] = torch.tensor([0.0, 0.0, 0.0, 1.0])
        >>> metric.update(preds, target, mask=torch.tensor([[False, True, True, False]]))
        >>> metric.compute()
        tensor(1.4142)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(self, *, continuity: bool = True, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.continuity = continuity

    def update(self, preds: Tensor, target: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate global quaternions ``[B, T, J, 4]``; ``mask`` ``[B, T]`` picks the frames."""
        self._accumulate(*_l2q_update(preds, target, mask, self.continuity))


class NPSS(Metric):
    """Normalised power spectrum similarity of the LaFAN1 benchmark.

    See [`npss`][skelagnostic.metrics.functional.npss]. The state is the
    power-weighted EMD sum and the ground-truth power sum (both
    ``dist_reduce_fx="sum"``), so the weighted average over all sequences and
    channels is exact across batches and DDP ranks, identical to one
    ``fast_npss`` call on the concatenated data.

    Args:
        power: ``"real"`` (benchmark code: squared real part of the FFT, default)
            or ``"abs"`` (squared magnitude, as in CITL / PC-MRL).
        continuity: Remove quaternion sign flips along time first (default ``True``).
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = NPSS()
        >>> target = torch.nn.functional.normalize(torch.randn(3, 16, 2, 4), dim=-1)
        >>> metric.update(target, target)
        >>> metric.compute()
        tensor(0.)
    """

    is_differentiable = True
    higher_is_better = False
    full_state_update = False
    plot_lower_bound = 0.0
    weighted_emd: Tensor
    weight: Tensor

    def __init__(self, power: str = "real", *, continuity: bool = True, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        check_choice("NPSS", "power", power, NPSS_POWERS)
        self.power = power
        self.continuity = continuity
        self.add_state("weighted_emd", torch.tensor(0.0), dist_reduce_fx="sum")
        self.add_state("weight", torch.tensor(0.0), dist_reduce_fx="sum")

    def update(self, preds: Tensor, target: Tensor, mask: Tensor | None = None) -> None:
        """Accumulate global quaternions ``[B, T, J, 4]``.

        Args:
            preds: Predicted global quaternions.
            target: Ground-truth global quaternions.
            mask: Optional ``[B, T]`` mask selecting one contiguous run of frames per
                sequence (e.g. the transition).
        """
        emd, weight = _npss_update(preds, target, self.power, mask, self.continuity)
        self.weighted_emd += emd.to(self.weighted_emd.device)
        self.weight += weight.to(self.weight.device)

    def compute(self) -> Tensor:
        """Power-weighted mean EMD (NaN if nothing was accumulated)."""
        return _mean_compute(self.weighted_emd, self.weight)
