"""Position metrics as functions: MPJPE (and variants), bone lengths, end-effector error.

The functional twins of :mod:`skelagnostic.metrics.positions`.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.metrics._checks import (
    check_bones,
    check_choice,
    check_indices,
    check_same_frames,
    check_same_shape,
    check_tensor,
    fail,
    promote,
    reshape_per_item,
)
from skelagnostic.metrics.functional._utils import REDUCTIONS, _mean_compute

__all__ = ["bone_length_consistency", "end_effector_error", "mpjpe"]

MPJPE_MODES = ("plain", "root", "procrustes")
#: Per-frame distances of :func:`end_effector_error`: the Euclidean norm (PC-MRL Eq. 6) or
#: the mean absolute coordinate difference (the authors' ``train_pointcloud.py``).
END_EFFECTOR_DISTANCES = ("euclidean", "mean_abs")


# --------------------------------------------------------------------------- MPJPE


def _procrustes_align(preds: Tensor, target: Tensor) -> Tensor:
    """Similarity-align every pose of ``preds`` to ``target`` (Umeyama, with scale).

    Both are ``[N, J, 3]``. Returns ``s * R @ preds + t`` per pose, with the
    rotation ``R`` forced proper (no reflection) and the scale ``s`` minimising
    the squared error.
    """
    mu_p = preds.mean(dim=-2, keepdim=True)
    mu_t = target.mean(dim=-2, keepdim=True)
    p0 = preds - mu_p
    t0 = target - mu_t
    cov = p0.transpose(-1, -2) @ t0  # [N, 3, 3] = sum_j p_j t_j^T
    u, s, vh = torch.linalg.svd(cov)
    v = vh.transpose(-1, -2)
    sign = torch.sign(torch.linalg.det(v @ u.transpose(-1, -2)))
    sign = torch.where(sign == 0, torch.ones_like(sign), sign)
    z = torch.ones_like(s)
    z[..., -1] = sign
    rot = v @ torch.diag_embed(z) @ u.transpose(-1, -2)  # maps preds onto target
    var_p = p0.square().sum(dim=(-1, -2))
    scale = (s * z).sum(dim=-1) / var_p.clamp_min(torch.finfo(preds.dtype).tiny)
    return scale[:, None, None] * (p0 @ rot.transpose(-1, -2)) + mu_t


def _mpjpe_update(
    preds: Tensor,
    target: Tensor,
    mode: str = "plain",
    root_index: int = 0,
    height: float | Tensor | None = None,
) -> tuple[Tensor, Tensor]:
    """Sum of per-joint position errors and the number of (pose, joint) pairs."""
    name = "mpjpe"
    check_choice(name, "mode", mode, MPJPE_MODES)
    check_tensor(name, "preds", preds, min_ndim=2, last_dim=3, layout="[..., J, 3]")
    check_tensor(name, "target", target, min_ndim=2, last_dim=3, layout="[..., J, 3]")
    check_same_shape(name, preds, target, ("joints", "xyz"))
    preds, target = promote(preds, target)
    num_joints = preds.shape[-2]
    if mode == "root":
        if not -num_joints <= root_index < num_joints:
            raise fail(name, f"root_index {root_index} is out of range for {num_joints} joints")
        preds = preds - preds[..., root_index : root_index + 1, :]
        target = target - target[..., root_index : root_index + 1, :]
    elif mode == "procrustes":
        flat_p = preds.reshape(-1, num_joints, 3)
        flat_t = target.reshape(-1, num_joints, 3)
        preds = _procrustes_align(flat_p, flat_t).reshape(preds.shape)
    errors = torch.linalg.vector_norm(preds - target, dim=-1)  # [..., J]
    if height is not None:
        errors = (
            errors / reshape_per_item(name, "height", height, errors.shape[:-1], errors)[..., None]
        )
    return errors.sum(), torch.tensor(errors.numel(), device=errors.device)


def mpjpe(
    preds: Tensor,
    target: Tensor,
    *,
    mode: str = "plain",
    height: float | Tensor | None = None,
    root_index: int = 0,
) -> Tensor:
    r"""Mean per-joint position error.

    $$
    \mathrm{MPJPE} = \frac{1}{N J}\sum_{n,j} \lVert \hat p_{n,j} - p_{n,j} \rVert_2
    $$

    over every pose ``n`` (all leading dimensions) and joint ``j``, in the data's units.

    Args:
        preds: Predicted global joint positions ``[..., J, 3]``.
        target: Ground-truth global joint positions, same shape.
        mode: ``"plain"``; ``"root"`` subtracts joint ``root_index`` from every pose
            first (root-relative MPJPE); ``"procrustes"`` first aligns each predicted
            pose to its target with the optimal similarity transform (rotation,
            uniform scale, translation; PA-MPJPE).
        height: Optional skeleton height to normalise by (HuMoT reports
            MPJPE / height): a number, or a tensor whose shape is a prefix of the
            leading dimensions, e.g. ``[B]`` for ``[B, T, J, 3]`` inputs.
        root_index: Joint used as the origin in ``"root"`` mode.

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf, non-positive heights or an unknown mode.

    Examples:
        >>> import torch
        >>> target = torch.zeros(2, 4, 3)
        >>> preds = target + torch.tensor([3.0, 4.0, 0.0])
        >>> mpjpe(preds, target)
        tensor(5.)
        >>> mpjpe(preds, target, mode="root")
        tensor(0.)
        >>> mpjpe(preds, target, height=torch.tensor([1.0, 2.0]))
        tensor(3.7500)
    """
    return _mean_compute(*_mpjpe_update(preds, target, mode, root_index, height))


# --------------------------------------------------------------------------- bone lengths


def _bone_length_consistency_update(
    preds: Tensor,
    target: Tensor,
    bones: Sequence[tuple[int, int]],
    correction: int = 0,
) -> tuple[Tensor, Tensor]:
    """Sum over (sequence, bone) of the temporal variance of the length ratio, and the count."""
    name = "bone_length_consistency"
    parents, children = check_bones(name, bones)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_same_shape(name, preds, target, ("frames", "joints", "xyz"))
    preds, target = promote(preds, target)
    num_joints, frames = preds.shape[-2], preds.shape[-3]
    if max(max(parents), max(children)) >= num_joints:
        raise fail(name, f"bones refer to joints beyond the {num_joints} joints of preds")
    if correction not in (0, 1):
        raise fail(name, f"correction must be 0 (population) or 1 (sample), got {correction!r}")
    if frames <= correction:
        raise fail(name, f"the temporal variance needs more than {correction} frame(s)")

    def lengths(x: Tensor) -> Tensor:
        return torch.linalg.vector_norm(x[..., children, :] - x[..., parents, :], dim=-1)

    len_t = lengths(target)  # [..., T, nb]
    zero = (len_t == 0).flatten(0, -2).any(dim=0).nonzero().flatten().tolist()
    if zero:
        raise fail(name, f"target bone {tuple(bones[zero[0]])} has zero length in some frame")
    variance = torch.var(lengths(preds) / len_t, dim=-2, correction=correction)  # [..., nb]
    return variance.sum(), torch.tensor(variance.numel(), device=variance.device)


def bone_length_consistency(
    preds: Tensor,
    target: Tensor,
    bones: Sequence[tuple[int, int]],
    *,
    correction: int = 0,
) -> Tensor:
    r"""Temporal bone-length consistency (HuMoT Eq. 2).

    For every bone ``b`` of every sequence, the temporal variance of the
    predicted length divided by the ground-truth length, averaged over bones
    (and sequences):

    $$
    \mathrm{BLC} = \frac{1}{B}\sum_b
    \operatorname{Var}_t\Big(\frac{\hat\ell_b(t)}{\ell_b(t)}\Big)
    $$

    Args:
        preds: Predicted global positions ``[..., T, J, 3]`` (leading dims = sequences).
        target: Ground-truth global positions, same shape.
        bones: ``(parent, child)`` joint index pairs, e.g. ``skeleton.bones()``.
        correction: ``0`` population variance (default), ``1`` unbiased sample variance.

    Returns:
        Scalar tensor (0 for perfectly rigid bones, even if they are scaled).

    Raises:
        MotionError: On mismatched shapes, NaN/inf, bad bones or zero-length target bones.

    Examples:
        >>> import torch
        >>> target = torch.tensor([[0.0, 0, 0], [0, 1, 0]]).expand(4, 2, 3)
        >>> preds = target * torch.tensor([1.0, 1.0, 1.0, 3.0])[:, None, None]
        >>> bone_length_consistency(preds, target, [(0, 1)])
        tensor(0.7500)
    """
    return _mean_compute(*_bone_length_consistency_update(preds, target, bones, correction))


# --------------------------------------------------------------------------- end effectors


def _end_effector_update(
    preds: Tensor,
    target: Tensor,
    preds_indices: Sequence[int] | None = None,
    target_indices: Sequence[int] | None = None,
    reduction: str = "sum",
    distance: str = "euclidean",
) -> tuple[Tensor, Tensor]:
    """Sum of the per-sequence end-effector errors, and the number of sequences."""
    name = "end_effector_error"
    check_choice(name, "reduction", reduction, REDUCTIONS)
    check_choice(name, "distance", distance, END_EFFECTOR_DISTANCES)
    check_tensor(name, "preds", preds, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_tensor(name, "target", target, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    check_same_frames(name, preds, target)
    preds, target = promote(preds, target)
    idx_p = check_indices(name, "preds_indices", preds_indices)
    idx_t = check_indices(name, "target_indices", target_indices)
    for arg, idx, x in (("preds_indices", idx_p, preds), ("target_indices", idx_t, target)):
        if idx is not None and not all(-x.shape[-2] <= i < x.shape[-2] for i in idx):
            raise fail(name, f"{arg} {idx} out of range for {x.shape[-2]} joints")
    if idx_p is not None:
        preds = preds[..., idx_p, :]
    if idx_t is not None:
        target = target[..., idx_t, :]
    if preds.shape[-2] != target.shape[-2]:
        raise fail(
            name,
            f"{preds.shape[-2]} predicted vs {target.shape[-2]} target end effectors; "
            "give matching preds_indices and target_indices",
        )
    diff = preds - target
    if distance == "euclidean":
        per_frame = torch.linalg.vector_norm(diff, dim=-1)  # [..., T, E]
    else:
        per_frame = diff.abs().mean(dim=-1)
    per_pair = per_frame.mean(dim=-2)  # [..., E]
    per_sequence = per_pair.sum(dim=-1) if reduction == "sum" else per_pair.mean(dim=-1)
    return per_sequence.sum(), torch.tensor(per_sequence.numel(), device=preds.device)


def end_effector_error(
    preds: Tensor,
    target: Tensor,
    *,
    preds_indices: Sequence[int] | None = None,
    target_indices: Sequence[int] | None = None,
    reduction: str = "sum",
    distance: str = "euclidean",
) -> Tensor:
    r"""End-effector error between matched joints of two skeletons (PC-MRL Eq. 6).

    $$
    L_{end} = \sum_{(a, b) \in E} \frac{1}{T}\sum_t \lVert \hat p_{b,t} - p_{a,t} \rVert_2
    $$

    over matched end-effector pairs ``E`` (hands, feet, head; see
    ``Skeleton.end_effectors()``), averaged over sequences. ``reduction="sum"``
    (default) sums over pairs as in Eq. 6; ``"mean"`` averages over pairs.

    ``distance="mean_abs"`` replaces the Euclidean norm by the mean absolute
    difference of the three coordinates, $\frac{1}{3}\lVert \hat p_{b,t} - p_{a,t}
    \rVert_1$. With ``reduction="mean"`` this is what the PC-MRL authors' code
    computes (``torch.mean(torch.abs(...))`` over sequences, frames, effectors and
    coordinates in ``train_pointcloud.py``), the definition of the paper's Table 2
    figures (see ``docs/metrics.md``).

    Args:
        preds: Predicted global positions ``[..., T, J_B, 3]`` (e.g. the retargeted skeleton).
        target: Reference global positions ``[..., T, J_A, 3]``.
        preds_indices: End-effector joints of ``preds``; all joints when ``None``.
        target_indices: The matching joints of ``target``, same order and length.
        reduction: ``"sum"`` or ``"mean"`` over pairs.
        distance: ``"euclidean"`` (Eq. 6, default) or ``"mean_abs"`` (the mean absolute
            coordinate difference of the authors' code).

    Returns:
        Scalar tensor.

    Raises:
        MotionError: On mismatched shapes, NaN/inf or unmatched index lists.

    Examples:
        >>> import torch
        >>> target = torch.zeros(2, 5, 3)               # 2 frames, 5 joints
        >>> preds = torch.zeros(2, 3, 3)                # 2 frames, 3 joints
        >>> preds[1, 2, 1] = 4.0                        # joint 2 is off by 4 in frame 1
        >>> end_effector_error(preds, target, preds_indices=[1, 2], target_indices=[3, 4])
        tensor(2.)
        >>> preds[1, 2] = torch.tensor([3.0, -3.0, 0.0])  # off by (3, -3, 0): mean |d| = 2
        >>> end_effector_error(
        ...     preds, target, preds_indices=[1, 2], target_indices=[3, 4], distance="mean_abs"
        ... )
        tensor(1.)
    """
    return _mean_compute(
        *_end_effector_update(preds, target, preds_indices, target_indices, reduction, distance)
    )
