"""Training objectives of the reconstruction stage (PC-MRL Sec. 3.2, Eq. 4-6, Sec. 4.2).

* :func:`temporal_knn_loss`: Eq. 4-5. For every source point ``u_A`` the ``k``
  nearest points ``u_B`` of the reconstructed cloud *of the same body group*
  are found by the trajectory distance ``delta = sum_t ||p_A,t - p_B,t||``
  over the whole sequence (not frame by frame), and their distances summed.
  The neighbour search runs without gradients (the selection is piecewise
  constant); the distances of the selected pairs are recomputed with
  gradients, which gives the same gradient as differentiating through a full
  distance matrix at a fraction of the memory.
  ``variant="authors"`` is :func:`authors_knn_terms`, the loss of the authors'
  code (``models/utils/knn_loss.py``), which differs from Eq. 5: trajectories
  are compared by the L2 norm of the flattened ``[T*3]`` difference (not a sum
  of per-frame distances), and three terms are averaged over points and
  neighbours and divided by ``sqrt(T)``: global positions, positions normalised
  per body group (centred on the sequence mean, divided by the per-frame
  standard deviation; neighbours searched again on those) and velocities
  gathered with the global-position neighbours. The total is
  ``glob + alpha * norm + vel``; the authors ramp ``alpha`` with their
  learning-rate schedule (:func:`authors_alpha`). Equal to their code within
  1e-6 on the fixtures of ``tests/fixtures/pcmrl``.
* :func:`end_effector_loss`: Eq. 6, optional.
* :func:`unit_norm_penalty`: ``(|q| - 1)^2`` on the raw quaternion outputs (the
  paper's L_q, weighted 0.01).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from skelagnostic.errors import SkelagnosticError

__all__ = [
    "authors_alpha",
    "authors_knn_terms",
    "end_effector_loss",
    "knn_pairs",
    "temporal_knn_loss",
    "unit_norm_penalty",
]

#: Elements of one chunk of the no-grad distance computation.
_CHUNK = 1 << 24
KNN_VARIANTS = ("paper", "authors")
REDUCTIONS = ("mean", "sum")


def _groups(groups: torch.Tensor, batch: int, num: int, what: str) -> torch.Tensor:
    groups = torch.as_tensor(groups)
    if groups.shape[-1] != num:
        raise SkelagnosticError(
            f"temporal_knn_loss: {what} has {groups.shape[-1]} entries for {num} points"
        )
    return groups.expand(batch, num)


def _clouds(
    name: str, preds: torch.Tensor, target: torch.Tensor, preds_groups: Any, target_groups: Any
) -> tuple[torch.Tensor, torch.Tensor]:
    """Check a pair of ``[B, T, N, 3]`` clouds; return their ``[B, N]`` group ids."""
    if preds.dim() != 4 or target.dim() != 4 or preds.shape[-1] != 3 or target.shape[-1] != 3:
        raise SkelagnosticError(
            f"{name}: expected [B, T, N, 3] clouds, got "
            f"{list(preds.shape)} and {list(target.shape)}"
        )
    if preds.shape[:2] != target.shape[:2]:
        raise SkelagnosticError(
            f"{name}: batch/frames differ: {list(preds.shape)} vs {list(target.shape)}"
        )
    batch, num_p, num_t = preds.shape[0], preds.shape[2], target.shape[2]
    g_p = _groups(torch.as_tensor(preds_groups, device=preds.device), batch, num_p, "preds_groups")
    g_t = _groups(
        torch.as_tensor(target_groups, device=preds.device), batch, num_t, "target_groups"
    )
    return g_p, g_t


def knn_pairs(
    preds: torch.Tensor,
    target: torch.Tensor,
    preds_groups: torch.Tensor,
    target_groups: torch.Tensor,
    k: int,
) -> tuple[torch.Tensor, torch.Tensor]:
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
            delta += torch.cdist(
                t[:, s : s + step], p[:, s : s + step], compute_mode="use_mm_for_euclid_dist"
            ).sum(1)
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


def temporal_knn_loss(
    preds: torch.Tensor,
    target: torch.Tensor,
    preds_groups: torch.Tensor | Sequence[int],
    target_groups: torch.Tensor | Sequence[int],
    k: int = 8,
    reduction: str = "mean",
    variant: str = "paper",
    alpha: float = 1.0,
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
        variant: ``"paper"`` (Eq. 5) or ``"authors"``
            (:func:`authors_knn_terms`: ``glob + alpha * norm + vel``, which is a
            mean; ``"sum"`` multiplies it by ``M * k``).
        alpha: Weight of the normalised term of ``variant="authors"``.

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
    g_p, g_t = _clouds("temporal_knn_loss", preds, target, preds_groups, target_groups)
    frames, num_t = preds.shape[1], target.shape[2]
    if variant == "authors":
        glob, norm, vel = authors_knn_terms(preds, target, g_p, g_t, k)
        total = glob + alpha * norm + vel
        return total * (num_t * k) if reduction == "sum" else total
    idx, valid = knn_pairs(preds, target, g_p, g_t, k)
    kk = idx.shape[-1]
    dist = _pair_distances(preds, target, idx) * valid.unsqueeze(1)
    per_seq = dist.sum(dim=(1, 2, 3))
    if reduction == "mean":
        per_seq = per_seq / (num_t * kk * frames)
    return per_seq.mean()


def _authors_group_terms(
    preds: torch.Tensor, target: torch.Tensor, vel_p: torch.Tensor, vel_t: torch.Tensor, k: int
) -> tuple[torch.Tensor, ...]:
    """Sums over target points and neighbours of the three authors' distances, one group.

    ``preds``/``vel_p`` ``[B, T, N_g, 3]``, ``target``/``vel_t`` ``[B, T, M_g, 3]``.
    """
    batch = preds.shape[0]

    def normalised(x: torch.Tensor) -> torch.Tensor:
        x = x - x.mean(dim=(1, 2), keepdim=True)  # sequence mean of the group, per axis
        return x / x.std(dim=(2, 3), keepdim=True)  # per-frame std over points and axes

    def flat(x: torch.Tensor) -> torch.Tensor:
        return x.transpose(1, 2).reshape(batch, x.shape[2], -1)  # [B, points, T*3]

    d_glob, idx = torch.cdist(flat(target), flat(preds)).topk(k, dim=-1, largest=False)
    d_norm = (
        torch.cdist(flat(normalised(target)), flat(normalised(preds)))
        .topk(k, dim=-1, largest=False)
        .values
    )
    d_vel = torch.cdist(flat(vel_t), flat(vel_p)).gather(-1, idx)
    return d_glob.sum(), d_norm.sum(), d_vel.sum()


def authors_knn_terms(
    preds: torch.Tensor,
    target: torch.Tensor,
    preds_groups: torch.Tensor | Sequence[int],
    target_groups: torch.Tensor | Sequence[int],
    k: int = 8,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    r"""The three terms of the authors' KNN loss (``KNNLoss`` of their code), differentiable.

    Per body group, every trajectory is flattened to ``[T*3]`` and, for every
    target point, the ``k`` nearest predicted points of its group are taken by
    the Euclidean distance of the flattened trajectories. The terms are the mean
    over batch, target points and neighbours, divided by $\sqrt{T}$, of

    * ``glob``: the distances of the global positions;
    * ``norm``: the same on positions normalised per group and sequence (minus
      the mean over frames and points, divided by the standard deviation over
      points and axes of each frame; Bessel-corrected), with its own neighbours;
    * ``vel``: the distances of the velocity trajectories (first frame 0) of the
      pairs chosen by ``glob``.

    Groups may differ between sequences (each sequence then uses its own);
    every group with target points needs at least ``k`` predicted points.

    Args:
        preds: ``[B, T, N, 3]`` cloud on the predicted motion.
        target: ``[B, T, M, 3]`` source cloud.
        preds_groups: ``[N]`` or ``[B, N]`` body-group ids of ``preds``.
        target_groups: ``[M]`` or ``[B, M]`` body-group ids of ``target``.
        k: Neighbours (8).

    Returns:
        ``(glob, norm, vel)`` scalars.

    Raises:
        SkelagnosticError: Bad shapes, or a group with fewer than ``k`` predicted points.
    """
    if k < 1:
        raise SkelagnosticError(f"knn k must be positive, got {k}")
    g_p, g_t = _clouds("authors_knn_terms", preds, target, preds_groups, target_groups)
    batch, frames = preds.shape[:2]
    num_t = target.shape[2]

    def velocity(x: torch.Tensor) -> torch.Tensor:
        return torch.cat([torch.zeros_like(x[:, :1]), x.diff(dim=1)], dim=1)

    vel_p, vel_t = velocity(preds), velocity(target)
    shared = bool((g_p == g_p[:1]).all()) and bool((g_t == g_t[:1]).all())
    rows = [slice(None)] if shared else [slice(b, b + 1) for b in range(batch)]
    sums = [preds.new_zeros(()) for _ in range(3)]
    for row in rows:
        gp, gt = g_p[row][0], g_t[row][0]
        for g in torch.unique(gt).tolist():
            mp, mt = gp == g, gt == g
            if int(mp.sum()) < k:
                raise SkelagnosticError(
                    f"authors_knn_terms: body group {g} has {int(mp.sum())} predicted points, "
                    f"fewer than k={k}"
                )
            terms = _authors_group_terms(
                preds[row][:, :, mp],
                target[row][:, :, mt],
                vel_p[row][:, :, mp],
                vel_t[row][:, :, mt],
                k,
            )
            sums = [a + b for a, b in zip(sums, terms, strict=True)]
    scale = batch * num_t * k * frames**0.5
    glob, norm, vel = (s / scale for s in sums)
    return glob, norm, vel


def authors_alpha(step: int, warmup: int, total: int) -> float:
    """Weight of the normalised KNN term at ``step`` in the authors' training.

    ``min(step / warmup, (total - step) / (total - warmup))``: a linear ramp to 1
    over ``warmup`` steps, then a linear decay to 0 at ``total`` (their learning-rate
    schedule; 500 and 50000 in their ``config.json`` and ``train_pointcloud.py``).
    ``warmup <= 0`` gives 1.
    """
    if warmup <= 0:
        return 1.0
    if total <= warmup:
        return min(1.0, step / warmup)
    return max(0.0, min(step / warmup, (total - step) / (total - warmup)))


def end_effector_loss(
    preds: torch.Tensor, target: torch.Tensor, pairs: Sequence[tuple[int, int]]
) -> torch.Tensor:
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
