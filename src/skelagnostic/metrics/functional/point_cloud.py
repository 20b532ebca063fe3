"""Temporally consistent KNN distance between point-cloud motions as a function (PC-MRL).

The functional twin of :mod:`skelagnostic.metrics.point_cloud`.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import torch
from torch import Tensor

from skelagnostic.metrics._checks import (
    check_choice,
    check_positive_int,
    check_same_frames,
    check_tensor,
    fail,
    promote,
)
from skelagnostic.metrics.functional._utils import REDUCTIONS, _mean_compute

__all__ = ["temporal_knn_distance"]

# Largest number of pairwise distances the KNN metric materialises at once.
_KNN_CHUNK_ELEMENTS = 1 << 24


# --------------------------------------------------------------------------- point clouds


def _group_ids(
    name: str,
    preds_groups: Tensor | Sequence[Hashable] | None,
    target_groups: Tensor | Sequence[Hashable] | None,
    num_preds: int,
    num_target: int,
    device: torch.device,
) -> tuple[Tensor, Tensor]:
    """Body-group ids of the predicted and target points as two integer tensors."""
    if preds_groups is None and target_groups is None:
        return (
            torch.zeros(num_preds, dtype=torch.long, device=device),
            torch.zeros(num_target, dtype=torch.long, device=device),
        )
    if preds_groups is None or target_groups is None:
        raise fail(name, "give both preds_groups and target_groups, or neither")
    vocabulary: dict[Hashable, int] = {}
    out = []
    for arg, groups, count in (
        ("preds_groups", preds_groups, num_preds),
        ("target_groups", target_groups, num_target),
    ):
        if isinstance(groups, Tensor):
            if groups.is_floating_point() or groups.ndim != 1:
                raise fail(name, f"{arg} must be a 1-D integer tensor or a sequence of labels")
            labels: list[Hashable] = groups.tolist()
        else:
            labels = list(groups)
        if len(labels) != count:
            raise fail(name, f"{arg} has {len(labels)} labels for {count} points")
        out.append(
            torch.tensor(
                [vocabulary.setdefault(g, len(vocabulary)) for g in labels],
                dtype=torch.long,
                device=device,
            )
        )
    return out[0], out[1]


def _temporal_knn_update(
    preds: Tensor,
    target: Tensor,
    preds_groups: Tensor | Sequence[Hashable] | None = None,
    target_groups: Tensor | Sequence[Hashable] | None = None,
    k: int = 8,
    reduction: str = "mean",
) -> tuple[Tensor, Tensor]:
    """Sum of the per-sequence KNN distances, and the number of sequences."""
    name = "temporal_knn_distance"
    check_positive_int(name, "k", k)
    check_choice(name, "reduction", reduction, REDUCTIONS)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, N, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, M, 3]")
    check_same_frames(name, preds, target)
    frames, num_p, num_t = preds.shape[-3], preds.shape[-2], target.shape[-2]
    g_p, g_t = _group_ids(name, preds_groups, target_groups, num_p, num_t, preds.device)
    for group in g_t.unique().tolist():
        available = int((g_p == group).sum())
        if available < k:
            raise fail(
                name,
                f"body group {group} has {available} predicted points, fewer than k={k}",
            )
    preds, target = promote(preds, target)
    p = preds.reshape(-1, frames, num_p, 3)
    t = target.reshape(-1, frames, num_t, 3)
    chunk = max(1, _KNN_CHUNK_ELEMENTS // max(1, p.shape[0] * num_p * num_t))
    delta = p.new_zeros(p.shape[0], num_t, num_p)
    for start in range(0, frames, chunk):
        delta = delta + torch.cdist(
            t[:, start : start + chunk],
            p[:, start : start + chunk],
            compute_mode="donot_use_mm_for_euclid_dist",
        ).sum(dim=1)
    delta = delta.masked_fill(g_t[:, None] != g_p[None, :], float("inf"))
    per_sequence = delta.topk(k, dim=-1, largest=False).values.sum(dim=(-1, -2))
    if reduction == "mean":
        per_sequence = per_sequence / (num_t * k * frames)
    return per_sequence.sum(), torch.tensor(per_sequence.numel(), device=preds.device)


def temporal_knn_distance(
    preds: Tensor,
    target: Tensor,
    *,
    preds_groups: Tensor | Sequence[Hashable] | None = None,
    target_groups: Tensor | Sequence[Hashable] | None = None,
    k: int = 8,
    reduction: str = "mean",
) -> Tensor:
    r"""Temporally consistent KNN point-cloud distance (PC-MRL Eq. 5, Table 2).

    The distance between two point trajectories is the sum over frames of their
    per-frame L2 distance, infinite across body groups:
    $\delta(u_A, u_B) = \sum_t \lVert p_{u_A,t} - p_{u_B,t} \rVert_2$.
    For every reference point ``u_A`` (``target``, the source motion's cloud)
    the ``k`` nearest predicted points ``u_B`` (``preds``, the reconstructed
    motion's cloud) are found by ``delta`` and their distances summed:

    $$
    L_{KNN} = \sum_{u_A}\sum_{u_B \in N_k(u_A)} \delta(u_A, u_B)
    $$

    ``reduction="sum"`` returns this sum (Eq. 5, the training loss);
    ``reduction="mean"`` (default) divides it by ``M * k * T``, the mean
    per-frame distance to a neighbour, which is the scale of the paper's Table 2
    (there in metres and multiplied by 100). Several sequences are averaged.

    Args:
        preds: Predicted point trajectories ``[..., T, N, 3]``.
        target: Reference point trajectories ``[..., T, M, 3]`` (same leading dims and T).
        preds_groups: Body group of every predicted point (``N`` ints or labels such
            as ``"left_arm"``); ``None`` with ``target_groups=None`` means one group.
        target_groups: Body group of every reference point (``M`` entries).
        k: Number of neighbours (8 in the paper).
        reduction: ``"mean"`` or ``"sum"`` (see above).

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, or a body group with fewer than
            ``k`` predicted points.

    Examples:
        >>> import torch
        >>> target = torch.zeros(3, 2, 3)               # 3 frames, 2 points at the origin
        >>> preds = torch.zeros(3, 2, 3)
        >>> preds[:, 1, 0] = 2.0                        # second predicted point 2 units away
        >>> temporal_knn_distance(preds, target, k=1)   # nearest is always the first
        tensor(0.)
        >>> temporal_knn_distance(preds, target, k=2)   # (0 + 2) per frame and point / 2
        tensor(1.)
        >>> temporal_knn_distance(preds, target, k=2, reduction="sum")
        tensor(12.)
    """
    return _mean_compute(
        *_temporal_knn_update(preds, target, preds_groups, target_groups, k, reduction)
    )
