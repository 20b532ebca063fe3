"""Training objectives of the reconstruction stage (PC-MRL Sec. 3.2, Eq. 4-6, Sec. 4.2).

* :func:`temporal_knn_loss`: Eq. 4-5. For every source point ``u_A`` the ``k``
  nearest points ``u_B`` of the reconstructed cloud *of the same body group*
  are found by the trajectory distance ``delta = sum_t ||p_A,t - p_B,t||``
  over the whole sequence (not frame by frame), and their distances summed.
  The neighbour search runs without gradients (the selection is piecewise
  constant); the distances of the selected pairs are recomputed with
  gradients, which gives the same gradient as differentiating through a full
  distance matrix at a fraction of the memory.
  ``variant="authors"`` is the authors' code: three terms per body group,
  each divided by ``sqrt(T)``: global positions, positions relative to the
  group's per-frame centroid (neighbours searched again on those), and
  velocities gathered with the position neighbours.
* :func:`end_effector_loss`: Eq. 6, optional.
* :func:`unit_norm_penalty`: ``(|q| - 1)^2`` on the raw quaternion outputs (the
  paper's L_q, weighted 0.01).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from skelagnostic.errors import SkelagnosticError

__all__ = ["end_effector_loss", "knn_pairs", "temporal_knn_loss", "unit_norm_penalty"]

#: Elements of one chunk of the no-grad distance computation.
_CHUNK = 1 << 24
KNN_VARIANTS = ("paper", "authors")
REDUCTIONS = ("mean", "sum")


def _groups(groups: torch.Tensor, batch: int, num: int, what: str) -> torch.Tensor:
    groups = torch.as_tensor(groups)
    if groups.shape[-1] != num:
        raise SkelagnosticError(f"temporal_knn_loss: {what} has {groups.shape[-1]} entries for "
                                f"{num} points")
    return groups.expand(batch, num)


def knn_pairs(preds: torch.Tensor, target: torch.Tensor, preds_groups: torch.Tensor,
              target_groups: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``k`` nearest predicted trajectories of every target trajectory, same group only.

    Args:
        preds: ``[B, T, N, 3]``.
        target: ``[B, T, M, 3]``.
        preds_groups: ``[B, N]`` group ids.
        target_groups: ``[B, M]`` group ids.
        k: Neighbours.

    Returns:
        ``(indices [B, M, k], valid [B, M, k])``: indices into ``N``; ``valid`` is
        false where the group has fewer than ``k`` predicted points.
    """
    batch, frames, num_p, _ = preds.shape
    num_t = target.shape[2]
    with torch.no_grad():
        p, t = preds.detach(), target.detach()
        delta = p.new_zeros(batch, num_t, num_p)
        step = max(1, _CHUNK // max(1, batch * num_p * num_t))
        for s in range(0, frames, step):
            delta += torch.cdist(t[:, s:s + step], p[:, s:s + step],
                                 compute_mode="use_mm_for_euclid_dist").sum(1)
        delta.masked_fill_(target_groups[:, :, None] != preds_groups[:, None, :], float("inf"))
        kk = min(k, num_p)
        values, idx = delta.topk(kk, dim=-1, largest=False)
    return idx, torch.isfinite(values)


def _pair_distances(preds: torch.Tensor, target: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """``[B, T, M, k]`` per-frame distances of the selected pairs (differentiable)."""
    batch, frames = preds.shape[:2]
    m, k = idx.shape[1:]
    gather = idx.reshape(batch, 1, m * k, 1).expand(batch, frames, m * k, 3)
    sel = torch.gather(preds, 2, gather).reshape(batch, frames, m, k, 3)
    return (sel - target.unsqueeze(-2)).norm(dim=-1)


def _centred(points: torch.Tensor, groups: torch.Tensor, num_groups: int) -> torch.Tensor:
    """Points minus the per-frame centroid of their body group in their own cloud."""
    onehot = torch.nn.functional.one_hot(groups, num_groups).to(points.dtype)  # [B, N, G]
    count = onehot.sum(1).clamp_min(1.0)  # [B, G]
    centroid = torch.einsum("btnc,bng->btgc", points, onehot) / count[:, None, :, None]
    return points - torch.einsum("btgc,bng->btnc", centroid, onehot)


def temporal_knn_loss(
    preds: torch.Tensor,
    target: torch.Tensor,
    preds_groups: torch.Tensor | Sequence[int],
    target_groups: torch.Tensor | Sequence[int],
    k: int = 8,
    reduction: str = "mean",
    variant: str = "paper",
) -> torch.Tensor:
    r"""Temporally consistent KNN loss (PC-MRL Eq. 5), differentiable in ``preds``.

    $L = \sum_{u_A}\sum_{u_B \in N_k(u_A)} \sum_t \lVert p_{u_A,t} - p_{u_B,t} \rVert$
    per sequence, neighbours restricted to the same body group.

    Args:
        preds: ``[B, T, N, 3]`` cloud sampled on the predicted motion (``X_B``).
        target: ``[B, T, M, 3]`` source cloud (``X_A``).
        preds_groups: ``[N]`` or ``[B, N]`` body-group ids of ``preds``.
        target_groups: ``[M]`` or ``[B, M]`` body-group ids of ``target``.
        k: Neighbours (8 in the paper).
        reduction: ``"sum"``: Eq. 5 per sequence; ``"mean"``: divided by
            ``M * k * T`` (the mean per-frame neighbour distance, the scale of
            Table 2 before the x100). Both are averaged over the batch.
        variant: ``"paper"`` (Eq. 5) or ``"authors"`` (three terms each divided by
            ``sqrt(T)``; ``"mean"`` then divides by ``M * k`` only).

    Returns:
        Scalar loss.

    Raises:
        SkelagnosticError: Bad shapes, ``k``, ``reduction`` or ``variant``.
    """
    if variant not in KNN_VARIANTS:
        raise SkelagnosticError(f"knn variant must be one of {KNN_VARIANTS}, got {variant!r}")
    if reduction not in REDUCTIONS:
        raise SkelagnosticError(f"knn reduction must be one of {REDUCTIONS}, got {reduction!r}")
    if k < 1:
        raise SkelagnosticError(f"knn k must be positive, got {k}")
    if preds.dim() != 4 or target.dim() != 4 or preds.shape[-1] != 3 or target.shape[-1] != 3:
        raise SkelagnosticError(f"temporal_knn_loss: expected [B, T, N, 3] clouds, got "
                                f"{list(preds.shape)} and {list(target.shape)}")
    if preds.shape[:2] != target.shape[:2]:
        raise SkelagnosticError(f"temporal_knn_loss: batch/frames differ: {list(preds.shape)} "
                                f"vs {list(target.shape)}")
    batch, frames, num_p, _ = preds.shape
    num_t = target.shape[2]
    g_p = _groups(torch.as_tensor(preds_groups, device=preds.device), batch, num_p, "preds_groups")
    g_t = _groups(torch.as_tensor(target_groups, device=preds.device), batch, num_t,
                  "target_groups")
    idx, valid = knn_pairs(preds, target, g_p, g_t, k)
    kk = idx.shape[-1]
    dist = _pair_distances(preds, target, idx) * valid.unsqueeze(1)
    if variant == "paper":
        per_seq = dist.sum(dim=(1, 2, 3))
        if reduction == "mean":
            per_seq = per_seq / (num_t * kk * frames)
        return per_seq.mean()
    scale = frames ** 0.5
    num_groups = int(max(int(g_p.max()), int(g_t.max()))) + 1
    cp, ct = _centred(preds, g_p, num_groups), _centred(target, g_t, num_groups)
    idx_c, valid_c = knn_pairs(cp, ct, g_p, g_t, k)
    dist_c = _pair_distances(cp, ct, idx_c) * valid_c.unsqueeze(1)
    if frames > 1:
        vel = _pair_distances(preds.diff(dim=1), target.diff(dim=1), idx) * valid.unsqueeze(1)
        vel_sum = vel.sum(dim=(1, 2, 3))
    else:
        vel_sum = preds.new_zeros(batch)
    per_seq = (dist.sum(dim=(1, 2, 3)) + dist_c.sum(dim=(1, 2, 3)) + vel_sum) / scale
    if reduction == "mean":
        per_seq = per_seq / (num_t * kk)
    return per_seq.mean()


def end_effector_loss(preds: torch.Tensor, target: torch.Tensor,
                      pairs: Sequence[tuple[int, int]]) -> torch.Tensor:
    """Eq. 6: sum over matched end-effector pairs of the mean distance over frames.

    Args:
        preds: ``[B, T, J_B, 3]`` joint positions of the reconstructed motion.
        target: ``[B, T, J_A, 3]`` joint positions of the source motion.
        pairs: ``(source joint, target joint)`` index pairs.

    Returns:
        Scalar, averaged over the batch (0 without pairs).
    """
    if not pairs:
        return preds.new_zeros(())
    a = torch.tensor([p[0] for p in pairs], device=target.device)
    b = torch.tensor([p[1] for p in pairs], device=preds.device)
    return (preds[:, :, b] - target[:, :, a]).norm(dim=-1).mean(dim=1).sum(-1).mean()


def unit_norm_penalty(raw_quaternions: torch.Tensor) -> torch.Tensor:
    """Mean of ``(|q| - 1)^2`` over the raw quaternion outputs (the paper's L_q)."""
    return (raw_quaternions.norm(dim=-1) - 1.0).square().mean()
