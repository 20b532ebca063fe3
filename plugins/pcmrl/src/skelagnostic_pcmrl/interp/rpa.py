"""Rest pose augmentation (RPA, PC-MRL Sec. 3.4 and Algorithm 1) and bone tails.

PC-MRL's bones (Sec. 3.1) have a head and a *tail*; a BVH joint only has a
head (its offset from the parent). :func:`bone_tails` gives every joint the
tail its rotation drives: the offset of its *main child* (the child joint of
non-zero offset in the same body group, else the first child of non-zero
offset), else its first ``End Site``, else nothing (zero tail).

RPA (Sec. 3.4): each bone tail gets a random offset; the bone's rotation is
then corrected by the quaternion of maximum real part (:func:`max_real_quaternion`,
Algorithm 1) that turns the augmented rest tail back onto the original tail
direction, so the animated bone keeps pointing where it pointed (only its length
and the attachments of the other children change). The correction is a constant
right factor of every frame's global rotation, so first-frame offset quaternions
(FOQ, Sec. 3.3) are unchanged by RPA: it alters the skeleton the model animates
(bone lengths, hip/shoulder attachments), the first-frame global rotations and
therefore the forward-kinematics targets.

How the tail offsets are drawn (:data:`RPA_OFFSETS`): ``"independent"``
(:func:`random_tail_offsets`, every bone its own draw) or ``"mirrored"``
(:func:`mirrored_tail_offsets`, the draw of the authors' ``train_inpainter.py``:
only the arm and leg bones move, each left bone and its right counterpart by the
same offset mirrored across the body's sagittal plane).

How the motion follows the moved tails (:data:`RPA_SOLVES`): ``"directions"``
(:func:`augment_rest_pose`: the offsets of the children take the new tails, so
the bone lengths change and every bone keeps its direction) or ``"authors"``
(:func:`authors_rest_pose_rotations`, what the authors' ``train_inpainter.py``
does: the offsets stay, so the bone lengths stay, and the rotations are solved
again, which turns the bones).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError, SkeletonError

__all__ = [
    "RPA_OFFSETS",
    "RPA_SOLVES",
    "BoneTails",
    "augment_rest_pose",
    "authors_rest_pose_rotations",
    "bone_tails",
    "lateral_axis",
    "left_right_pairs",
    "max_real_quaternion",
    "mirrored_tail_offsets",
    "random_tail_offsets",
]

#: Ways of drawing the RPA tail offsets (see the module docstring).
RPA_OFFSETS = ("independent", "mirrored")
#: Ways of re-solving the motion for the moved tails (see the module docstring).
RPA_SOLVES = ("directions", "authors")
#: (left, right) body groups whose joints are paired, in the authors' order (arms, then legs).
_PAIRED_GROUPS = (("left_arm", "right_arm"), ("left_leg", "right_leg"))

#: Offsets shorter than this (in the data's units) count as zero-length bones.
EPS = 1e-6


@dataclass(frozen=True)
class BoneTails:
    """The tail of every joint's bone.

    Attributes:
        tails: ``[J, 3]`` rest tail in the joint's own frame (zeros: no tail).
        child: ``[J]`` the main child joint whose offset is the tail, ``-1`` when the
            tail is an ``End Site`` or missing.
    """

    tails: torch.Tensor
    child: torch.Tensor


def bone_tails(skeleton: Skeleton) -> BoneTails:
    """Tails of the bones of ``skeleton`` (see the module docstring for the rule).

    Args:
        skeleton: Any skeleton.

    Returns:
        The tails, in the skeleton's units and dtype.
    """
    offsets = skeleton.offsets
    groups = skeleton.body_groups
    tails = torch.zeros_like(offsets)
    child = torch.full((skeleton.num_joints,), -1, dtype=torch.long)
    for j in range(skeleton.num_joints):
        kids = [c for c in skeleton.children(j) if float(offsets[c].norm()) > EPS]
        same = [c for c in kids if groups[c] == groups[j]]
        pick = (same or kids or [None])[0]
        if pick is not None:
            tails[j] = offsets[pick]
            child[j] = pick
            continue
        for site in skeleton.end_sites.get(j, []):
            site_t = torch.as_tensor(site, dtype=offsets.dtype)
            if float(site_t.norm()) > EPS:
                tails[j] = site_t
                break
    return BoneTails(tails, child)


def max_real_quaternion(rest_tail: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Algorithm 1: the rotation of maximum real part turning ``rest_tail`` onto ``target``.

    With ``eta = T/|T|`` and ``omega = p_IK/|p_IK|`` the algorithm forms
    ``q_min = (0, (eta + omega)/2)`` (a half-turn about the bisector, real part 0)
    and ``q_max = q_min * (0, eta)`` (times a half-turn about ``eta``), which equals
    ``-(1 + eta.omega, eta x omega) / 2``: the shortest-arc rotation from ``eta``
    to ``omega``, scaled by ``cos(theta/2)``. The result here is normalised and
    signed so that its real part is non-negative. Opposite directions (no unique
    shortest arc) get a half-turn about an axis perpendicular to ``eta``;
    zero-length inputs give the identity.

    Args:
        rest_tail: ``[..., 3]`` resting tail ``T`` of the bone.
        target: ``[..., 3]`` IK target ``p_IK`` (broadcastable with ``rest_tail``).

    Returns:
        ``[..., 4]`` unit quaternions (w, x, y, z) with ``rotate(q, eta) = omega``.
    """
    rest_tail, target = torch.broadcast_tensors(rest_tail, target)
    n_eta, n_omega = rest_tail.norm(dim=-1, keepdim=True), target.norm(dim=-1, keepdim=True)
    valid = (n_eta > EPS) & (n_omega > EPS)
    eta = rest_tail / n_eta.clamp_min(EPS)
    omega = target / n_omega.clamp_min(EPS)
    zero = torch.zeros_like(eta[..., :1])
    q_min = torch.cat([zero, (eta + omega) / 2], dim=-1)
    q_max = Q.mul(q_min, torch.cat([zero, eta], dim=-1))
    norm = q_max.norm(dim=-1, keepdim=True)
    q = q_max / norm.clamp_min(1e-12)
    q = torch.where(q[..., :1] < 0, -q, q)
    # opposite directions: a half-turn about any axis perpendicular to eta
    helper = torch.zeros_like(eta)
    helper[..., 0] = 1.0
    parallel_x = eta[..., :1].abs() > 0.9
    helper = torch.where(parallel_x, torch.roll(helper, 1, dims=-1), helper)
    axis = torch.linalg.cross(eta, helper, dim=-1)
    axis = axis / axis.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    half_turn = torch.cat([zero, axis], dim=-1)
    q = torch.where(norm < 1e-6, half_turn, q)
    identity = torch.zeros_like(q)
    identity[..., 0] = 1.0
    return torch.where(valid, q, identity)


def random_tail_offsets(
    num_joints: int,
    scale: float,
    generator: torch.Generator | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """``[J, 3]`` offsets drawn uniformly from ``[-scale, scale]`` per axis (RPA range)."""
    if scale < 0:
        raise SkelagnosticError(f"RPA range must be non-negative, got {scale}")
    u = torch.rand(num_joints, 3, generator=generator, dtype=dtype)
    return (2.0 * u - 1.0) * scale


def left_right_pairs(skeleton: Skeleton) -> list[tuple[int, int]]:
    """``(left, right)`` joint pairs of the arms, then of the legs (each in joint order).

    A joint of a left arm or leg body group is paired with its counterpart of
    :meth:`~skelagnostic.core.skeleton.Skeleton.mirror_map` when that counterpart is in
    the matching right group (the authors' pairs: their arm and leg groups; spine
    joints, such as CMU's ``LHipJoint``, stay unpaired).
    """
    groups, mirror = skeleton.body_groups, skeleton.mirror_map()
    return [
        (j, mirror[j])
        for left, right in _PAIRED_GROUPS
        for j in range(skeleton.num_joints)
        if groups[j] == left and mirror[j] != j and groups[mirror[j]] == right
    ]


def lateral_axis(skeleton: Skeleton, pairs: list[tuple[int, int]] | None = None) -> int:
    """The rest pose's left-right axis: the largest component of the mean left-minus-right.

    Raises:
        SkeletonError: The skeleton has no left/right pairs, or they coincide at rest.
    """
    pairs = left_right_pairs(skeleton) if pairs is None else pairs
    if not pairs:
        raise SkeletonError(f"{skeleton!r} has no left/right joint pairs (see mirror_map)")
    rest = skeleton.rest_positions()
    left, right = zip(*pairs, strict=True)
    side = (rest[list(left)] - rest[list(right)]).abs().mean(dim=0)
    if float(side.max()) <= EPS:
        raise SkeletonError(f"{skeleton!r}: left and right joints coincide in the rest pose")
    return int(side.argmax())


def mirrored_tail_offsets(
    skeleton: Skeleton,
    scale: float,
    generator: torch.Generator | None = None,
    mirror_axis: int | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """``[J, 3]`` RPA offsets drawn per left/right pair, as the authors draw them.

    Every pair of :func:`left_right_pairs` gets one offset uniform in
    ``[-scale, scale)`` per axis (one ``torch.rand(P, 3)`` draw, in pair order);
    the left joint takes it and the right joint takes it with the ``mirror_axis``
    component negated. Unpaired joints get zero.

    Args:
        skeleton: The skeleton whose bones are augmented.
        scale: Half-width of the range (the authors' ``aug_range`` is the full width:
            their 0.1 is ``scale=0.05``).
        generator: Random generator.
        mirror_axis: Component negated for the right joint; ``None``: the rest pose's
            :func:`lateral_axis`, a mirror across the sagittal plane. The authors'
            code negates component 1, the up axis of their Y-up CMU target.
        dtype: Output dtype.

    Raises:
        SkelagnosticError: ``scale`` is negative or ``mirror_axis`` is not 0, 1 or 2.
        SkeletonError: The skeleton has no left/right pairs.
    """
    if scale < 0:
        raise SkelagnosticError(f"RPA range must be non-negative, got {scale}")
    pairs = left_right_pairs(skeleton)
    if not pairs:
        raise SkeletonError(
            f"{skeleton!r} has no left/right arm or leg joint pairs (see "
            "mirror_map and body_groups): mirrored RPA offsets need them"
        )
    axis = lateral_axis(skeleton, pairs) if mirror_axis is None else int(mirror_axis)
    if axis not in (0, 1, 2):
        raise SkelagnosticError(f"RPA mirror axis must be 0, 1 or 2, got {mirror_axis}")
    delta = torch.zeros(skeleton.num_joints, 3, dtype=dtype)
    draw = (2.0 * torch.rand(len(pairs), 3, generator=generator, dtype=dtype) - 1.0) * scale
    left, right = (list(side) for side in zip(*pairs, strict=True))
    delta[left] = draw
    delta[right] = draw
    delta[right, axis] = -draw[:, axis]
    return delta


def augment_rest_pose(
    skeleton: Skeleton,
    global_rotations: torch.Tensor,
    delta: torch.Tensor,
    offsets: torch.Tensor | None = None,
    tails: BoneTails | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Apply RPA to one motion: move the bone tails by ``delta``, re-align the rotations.

    For every joint ``c`` with a non-zero offset the new offset is
    ``offset[c] + delta[c]`` (zero-length bones, which the paper ignores, stay
    zero); an ``End Site`` tail moves by ``delta`` of its joint. Each joint ``j``
    with a tail then gets the global rotation ``q_j * q_max`` where ``q_max`` =
    :func:`max_real_quaternion` (new tail, old tail), so its bone points along
    the original direction in every frame.

    Args:
        skeleton: The motion's skeleton (topology and default offsets/tails).
        global_rotations: ``[..., J, 4]`` global rotations of the motion.
        delta: ``[J, 3]`` tail offsets (e.g. :func:`random_tail_offsets`).
        offsets: ``[J, 3]`` offsets to augment instead of ``skeleton.offsets``
            (the clip's own offsets when several clips share a topology).
        tails: Tails matching ``offsets`` (default: :func:`bone_tails` of ``skeleton``
            with ``offsets`` substituted).

    Returns:
        ``(offsets [J, 3], global_rotations [..., J, 4], tails [J, 3])`` of the
        augmented skeleton and motion.

    Raises:
        SkeletonError: ``delta`` or ``offsets`` do not have shape ``[J, 3]``.
    """
    num_j = skeleton.num_joints
    base = skeleton.offsets if offsets is None else offsets
    for name, t in (("delta", delta), ("offsets", base)):
        if t.shape != (num_j, 3):
            raise SkeletonError(f"RPA: {name} must have shape [{num_j}, 3], got {list(t.shape)}")
    dtype = global_rotations.dtype
    base = base.to(dtype)
    delta = delta.to(dtype)
    info = tails if tails is not None else bone_tails(skeleton)
    child = info.child
    old_tails = info.tails.to(dtype).clone()
    if offsets is not None and tails is None:
        has_child = child >= 0
        old_tails[has_child] = base[child[has_child]]
    nonzero = (base.norm(dim=-1) > EPS).unsqueeze(-1)
    new_offsets = torch.where(nonzero, base + delta, base)
    new_offsets[0] = base[0]
    new_tails = old_tails.clone()
    has_child = child >= 0
    new_tails[has_child] = new_offsets[child[has_child]]
    site = (~has_child) & (old_tails.norm(dim=-1) > EPS)
    new_tails[site] = old_tails[site] + delta[site]
    q_fix = max_real_quaternion(new_tails, old_tails)
    return new_offsets, Q.mul(global_rotations, q_fix.to(global_rotations.device)), new_tails


def authors_rest_pose_rotations(
    global_rotations: torch.Tensor,
    root: torch.Tensor,
    offsets: torch.Tensor,
    tails: torch.Tensor,
    parents: Sequence[int],
    delta: torch.Tensor,
) -> torch.Tensor:
    """RPA as the authors' ``train_inpainter.py`` applies it: new global rotations, same bones.

    Joint by joint from the root, with ``h`` the original and ``h'`` the new
    position of the joint's head (``h'`` from the parent's new rotation and the
    unchanged offset) and ``t`` the original world position of its tail:

    1. ``q_b = arc(t - h, t - h') * q``: the bone turned to reach its old tail
       from its new head;
    2. ``a = q_b * (T + delta) / |T + delta|``, the moved rest tail in that pose;
    3. ``q' = arc(t - h', a) * q_b``, in the order of their code (from the bone to
       ``a``).

    ``arc(u, v)`` is :func:`max_real_quaternion` (Algorithm 1, normalised; their
    code's result differs only by the sign of the quaternion). The root position,
    the offsets and the tails stay as they are; the bone lengths are kept.

    Args:
        global_rotations: ``[..., J, 4]`` global rotations.
        root: ``[..., 3]`` root positions.
        offsets: ``[J, 3]`` rest offsets.
        tails: ``[J, 3]`` rest tails (zeros: no tail, the rotation is kept).
        parents: Parent index per joint (parents first).
        delta: ``[J, 3]`` tail offsets (:func:`mirrored_tail_offsets`).

    Returns:
        ``[..., J, 4]`` new global rotations.

    Raises:
        SkeletonError: A shape does not match the number of joints.
    """
    num_j = global_rotations.shape[-2]
    for name, t in (("offsets", offsets), ("tails", tails), ("delta", delta)):
        if t.shape != (num_j, 3):
            raise SkeletonError(f"RPA: {name} must have shape [{num_j}, 3], got {list(t.shape)}")
    if len(parents) != num_j:
        raise SkeletonError(f"RPA: {len(parents)} parents for {num_j} joints")
    dtype = global_rotations.dtype
    offsets, tails, delta = offsets.to(dtype), tails.to(dtype), delta.to(dtype)
    heads = fk_from_global(global_rotations, root, offsets, parents)
    new_heads: list[torch.Tensor] = []
    new_rots: list[torch.Tensor] = []
    for j, p in enumerate(parents):
        q = global_rotations[..., j, :]
        head = root if p < 0 else new_heads[p] + Q.rotate(new_rots[p], offsets[j])
        new_heads.append(head)
        if float(tails[j].norm()) <= EPS:
            new_rots.append(q)
            continue
        tail = heads[..., j, :] + Q.rotate(q, tails[j])
        reach = tail - head
        q_base = Q.mul(max_real_quaternion(tail - heads[..., j, :], reach), q)
        moved = Q.rotate(q_base, (tails[j] + delta[j]).expand_as(reach))
        new_rots.append(Q.mul(max_real_quaternion(reach, moved), q_base))
    return torch.stack(new_rots, dim=-2)
