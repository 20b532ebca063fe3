"""Temporally consistent KNN distance between point-cloud motions (PC-MRL)."""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import Any

from torch import Tensor

from skelagnostic.metrics._checks import check_choice, check_positive_int
from skelagnostic.metrics.functional._utils import REDUCTIONS
from skelagnostic.metrics.functional.point_cloud import _temporal_knn_update
from skelagnostic.metrics.positions import _SumCountMetric

__all__ = ["TemporalKNNDistance"]


class TemporalKNNDistance(_SumCountMetric):
    """KNN distance between point trajectories, per body group (PC-MRL Eq. 5 / Table 2).

    See [`temporal_knn_distance`][skelagnostic.metrics.functional.temporal_knn_distance]; every
    sequence has the same weight. Sampling the point clouds from a skeleton is
    the caller's job (PC-MRL samples 1024 points around the bones).

    Args:
        k: Number of neighbours (8 in the paper).
        reduction: ``"mean"`` (per-frame distance to a neighbour, the scale of
            Table 2; default) or ``"sum"`` (Eq. 5).
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = TemporalKNNDistance(k=2)
        >>> target = torch.zeros(1, 3, 4, 3)              # [B, T, M points, 3]
        >>> groups = ["left_arm", "left_arm", "spine", "spine"]
        >>> preds = target + torch.tensor([0.0, 0.5, 0.0])
        >>> metric.update(preds, target, preds_groups=groups, target_groups=groups)
        >>> metric.compute()
        tensor(0.5000)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(self, k: int = 8, *, reduction: str = "mean", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        check_positive_int("TemporalKNNDistance", "k", k)
        check_choice("TemporalKNNDistance", "reduction", reduction, REDUCTIONS)
        self.k = k
        self.reduction = reduction

    def update(
        self,
        preds: Tensor,
        target: Tensor,
        preds_groups: Tensor | Sequence[Hashable] | None = None,
        target_groups: Tensor | Sequence[Hashable] | None = None,
    ) -> None:
        """Accumulate point trajectories ``preds [..., T, N, 3]`` and ``target [..., T, M, 3]``.

        Args:
            preds: Predicted (reconstructed) point trajectories.
            target: Reference point trajectories.
            preds_groups: Body group of every predicted point (``N`` ints or labels).
            target_groups: Body group of every reference point (``M`` entries).
        """
        self._accumulate(
            *_temporal_knn_update(
                preds, target, preds_groups, target_groups, self.k, self.reduction
            )
        )
