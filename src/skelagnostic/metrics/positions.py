"""Position metrics: MPJPE (and variants), bone-length consistency, end-effector error."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor
from torchmetrics import Metric

from skelagnostic.metrics._checks import (
    check_bones,
    check_choice,
    check_indices,
    fail,
)
from skelagnostic.metrics.functional._utils import REDUCTIONS, _mean_compute
from skelagnostic.metrics.functional.positions import (
    END_EFFECTOR_DISTANCES,
    MPJPE_MODES,
    _bone_length_consistency_update,
    _end_effector_update,
    _mpjpe_update,
)

__all__ = ["MPJPE", "BoneLengthConsistency", "EndEffectorError"]


class _SumCountMetric(Metric):
    """A mean kept as two ``dist_reduce_fx="sum"`` states: exact under DDP."""

    full_state_update = False
    total: Tensor
    count: Tensor

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.add_state("total", torch.tensor(0.0), dist_reduce_fx="sum")
        self.add_state("count", torch.tensor(0), dist_reduce_fx="sum")

    def _accumulate(self, total: Tensor, count: Tensor) -> None:
        self.total += total.to(self.total.device)
        self.count += count.to(self.count.device)

    def compute(self) -> Tensor:
        """Accumulated mean (NaN if nothing was accumulated)."""
        return _mean_compute(self.total, self.count)


class MPJPE(_SumCountMetric):
    """Mean per-joint position error over every pose and joint seen.

    See [`mpjpe`][skelagnostic.metrics.functional.mpjpe] for the definition.

    Args:
        mode: ``"plain"``, ``"root"`` (root-relative) or ``"procrustes"`` (PA-MPJPE).
        root_index: Joint used as the origin in ``"root"`` mode.
        normalize_by_height: If ``True`` every `update()` needs ``height`` and the
            errors are divided by it (HuMoT's MPJPE / height); if ``False`` passing a
            height is an error, so normalised and raw errors never mix.
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = MPJPE()
        >>> target = torch.zeros(2, 3, 4, 3)                  # [B, T, J, 3]
        >>> metric.update(target + torch.tensor([0.0, 2.0, 0.0]), target)
        >>> metric.update(target, target)
        >>> metric.compute()
        tensor(1.)
        >>> normalised = MPJPE(normalize_by_height=True)
        >>> normalised.update(target + 1.0, target, height=torch.tensor([1.0, 2.0]))
        >>> normalised.compute()
        tensor(1.2990)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(
        self,
        mode: str = "plain",
        *,
        root_index: int = 0,
        normalize_by_height: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        check_choice("MPJPE", "mode", mode, MPJPE_MODES)
        self.mode = mode
        self.root_index = root_index
        self.normalize_by_height = normalize_by_height

    def update(self, preds: Tensor, target: Tensor, height: float | Tensor | None = None) -> None:
        """Accumulate a batch of poses.

        Args:
            preds: Predicted global joint positions ``[..., J, 3]``.
            target: Ground-truth positions, same shape.
            height: Skeleton height (number, or a tensor whose shape is a prefix of the
                leading dims); required exactly when ``normalize_by_height``.
        """
        if self.normalize_by_height and height is None:
            raise fail("MPJPE", "normalize_by_height=True needs a height in every update")
        if not self.normalize_by_height and height is not None:
            raise fail("MPJPE", "height given, but the metric has normalize_by_height=False")
        self._accumulate(*_mpjpe_update(preds, target, self.mode, self.root_index, height))


class BoneLengthConsistency(_SumCountMetric):
    """Temporal variance of predicted / ground-truth bone lengths (HuMoT Eq. 2).

    See [`bone_length_consistency`][skelagnostic.metrics.functional.bone_length_consistency]. Every
    (sequence, bone) pair has the same weight.

    Args:
        bones: ``(parent, child)`` joint index pairs, e.g. ``skeleton.bones()``.
        correction: ``0`` population variance (default), ``1`` sample variance.
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = BoneLengthConsistency(bones=[(0, 1)])
        >>> target = torch.tensor([[0.0, 0, 0], [0, 1, 0]]).expand(1, 4, 2, 3)
        >>> metric.update(target * 2.0, target)             # scaled but rigid: 0
        >>> metric.update(target * torch.tensor([1.0, 1, 1, 3])[:, None, None], target)
        >>> metric.compute()
        tensor(0.3750)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(
        self, bones: Sequence[tuple[int, int]], *, correction: int = 0, **kwargs: Any
    ) -> None:
        super().__init__(**kwargs)
        check_bones("BoneLengthConsistency", bones)
        self.bones = [(int(p), int(c)) for p, c in bones]
        self.correction = correction

    def update(self, preds: Tensor, target: Tensor) -> None:
        """Accumulate sequences of global positions ``[..., T, J, 3]``."""
        self._accumulate(
            *_bone_length_consistency_update(preds, target, self.bones, self.correction)
        )


class EndEffectorError(_SumCountMetric):
    """Error between matched end effectors of two skeletons (PC-MRL Eq. 6).

    See [`end_effector_error`][skelagnostic.metrics.functional.end_effector_error]; every
    sequence has the same weight.

    Args:
        preds_indices: End-effector joints of the predicted skeleton (all when ``None``),
            e.g. ``target_skeleton.end_effectors()``.
        target_indices: Matching joints of the reference skeleton, same order.
        reduction: ``"sum"`` over pairs (Eq. 6, default) or ``"mean"``.
        distance: ``"euclidean"`` (Eq. 6, default) or ``"mean_abs"``, the mean absolute
            coordinate difference; with ``reduction="mean"`` the definition of the PC-MRL
            authors' code.
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = EndEffectorError(preds_indices=[0, 1], target_indices=[2, 0])
        >>> target = torch.zeros(2, 5, 3, 3)                # [B, T, J_A, 3]
        >>> preds = torch.zeros(2, 5, 2, 3)                 # [B, T, J_B, 3]
        >>> preds[0, :, 1, 2] = 1.0                         # first sequence, second pair off by 1
        >>> metric.update(preds, target)
        >>> metric.compute()
        tensor(0.5000)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(
        self,
        preds_indices: Sequence[int] | None = None,
        target_indices: Sequence[int] | None = None,
        *,
        reduction: str = "sum",
        distance: str = "euclidean",
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        check_choice("EndEffectorError", "reduction", reduction, REDUCTIONS)
        check_choice("EndEffectorError", "distance", distance, END_EFFECTOR_DISTANCES)
        self.preds_indices = check_indices("EndEffectorError", "preds_indices", preds_indices)
        self.target_indices = check_indices("EndEffectorError", "target_indices", target_indices)
        self.reduction = reduction
        self.distance = distance

    def update(self, preds: Tensor, target: Tensor) -> None:
        """Accumulate sequences ``preds [..., T, J_B, 3]`` and ``target [..., T, J_A, 3]``."""
        self._accumulate(
            *_end_effector_update(
                preds,
                target,
                self.preds_indices,
                self.target_indices,
                self.reduction,
                self.distance,
            )
        )
