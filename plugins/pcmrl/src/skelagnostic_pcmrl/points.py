"""Point-cloud obfuscation of skeletal motion (PC-MRL Sec. 3.1-3.2, Eq. 1 and Eq. 3).

What the core :class:`~skelagnostic.representations.PointCloud` already does
(bone chosen with probability proportional to its length, ``alpha ~ U[0, 1]``
along it plus a Gaussian offset of standard deviation ``sigma`` in the bone's
local frame, the point following the bone's global rotation, one-hot body
group) is reused here for the point positions (:meth:`PointCloud.points`).
This module adds what training needs on top of it:

* :class:`PointLayout`: the random draws of a sampling (bone, ``alpha``,
  noise) kept apart from the bone offsets, so one draw can be laid on a batch
  of clips whose offsets differ slightly (same topology), and a fresh cloud
  can be drawn for every training sequence in one vectorised call;
* zero-length bones: the paper's objective needs bones of non-zero length
  (Sec. 5); zero-length bones are never sampled and the global rotations of
  joints that carry no non-zero bone are not predicted
  (:func:`effective_joints`); :func:`warn_zero_length_bones` names them;
* Eq. 1 from *global* quaternions, the map the reconstruction network's
  output goes through, and the global-to-local conversion for writing a
  :class:`~skelagnostic.Motion`, are the core's
  :func:`~skelagnostic.core.kinematics.fk_from_global` and
  :func:`~skelagnostic.core.kinematics.local_from_global` (also importable
  here under their former names ``positions_from_global`` and ``global_to_local``);
* length units: the paper works in metres (Sec. 4.2); :func:`infer_units`
  guesses a human skeleton's units from its height;
* facing: :func:`lateral_direction` / :func:`heading_frames` estimate a body's
  heading from the body groups of its points alone (left minus right), which
  the reconstruction uses to encode every cloud in a heading-free frame
  (``model.canonical_yaw``; not in the paper).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global, local_from_global
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import infer_units
from skelagnostic.errors import SkelagnosticError, SkeletonError
from skelagnostic.representations import POINT_GROUPS, PointCloud, PointSamples

__all__ = [
    "ZERO_LENGTH",
    "PointLayout",
    "ZeroLengthBoneWarning",
    "effective_joints",
    "end_effector_pairs",
    "global_to_local",
    "group_of_joints",
    "heading_frames",
    "infer_units",
    "lateral_direction",
    "positions_from_global",
    "sample_layout",
    "warn_zero_length_bones",
    "zero_length_bones",
]

#: Former names of the core's geometry maps, kept so that existing imports work.
positions_from_global = fk_from_global
global_to_local = local_from_global

#: Bones shorter than this (in the skeleton's units, relative to its height) count as zero-length.
ZERO_LENGTH = 1e-6


class ZeroLengthBoneWarning(UserWarning):
    """A skeleton has bones of zero length, which PC-MRL ignores (paper Sec. 5)."""


def zero_length_bones(skeleton: Skeleton) -> list[int]:
    """Child joints of the bones of (near) zero length, in skeleton order."""
    lengths = skeleton.bone_lengths()
    scale = max(float(lengths.max()), 1e-12) if len(lengths) else 1.0
    return [c for _, c in skeleton.bones() if float(lengths[c]) <= ZERO_LENGTH * scale]


def effective_joints(skeleton: Skeleton) -> list[int]:
    """Joints whose global rotation moves a point: heads of at least one non-zero bone.

    The root is always included (it also carries the root position). Other
    joints' global rotations are unobservable in a point cloud and are set to
    their parent's (identity local rotation).
    """
    zero = set(zero_length_bones(skeleton))
    heads = {p for p, c in skeleton.bones() if c not in zero}
    return sorted(heads | {0})


def warn_zero_length_bones(skeleton: Skeleton, role: str = "skeleton") -> list[str]:
    """Warn (:class:`ZeroLengthBoneWarning`) about zero-length bones, naming the joints.

    Args:
        skeleton: The skeleton to check.
        role: How to call it in the message (``"source skeleton"``, ...).

    Returns:
        The names of the child joints of the zero-length bones.

    Raises:
        SkeletonError: No bone has a non-zero length (nothing to sample points on).
    """
    zero = zero_length_bones(skeleton)
    if len(zero) == len(skeleton.bones()):
        raise SkeletonError(
            f"{role} {skeleton!r} has no bone of non-zero length; PC-MRL samples points on bones"
        )
    names = [skeleton.joint_names[j] for j in zero]
    if names:
        effective = set(effective_joints(skeleton))
        frozen = [n for j, n in enumerate(skeleton.joint_names) if j not in effective]
        warnings.warn(
            f"PC-MRL: the {role} {(skeleton.name or '') + ' '}({skeleton.num_joints} joints) has "
            f"{len(names)} zero-length bone(s) ending at {', '.join(names)}; they carry no "
            "points and are ignored (paper Sec. 5). Rotations not predicted (identity local "
            f"rotation): {', '.join(frozen) or 'none'}",
            ZeroLengthBoneWarning,
            stacklevel=2,
        )
    return names


def group_of_joints(skeleton: Skeleton) -> torch.Tensor:
    """``[J]`` index into :data:`POINT_GROUPS` of every joint (tail/other count as spine)."""
    index = {g: i for i, g in enumerate(POINT_GROUPS)}
    return torch.tensor([index.get(g, 0) for g in skeleton.body_groups], dtype=torch.long)


@dataclass
class PointLayout:
    """The random draws of point clouds on one skeleton topology.

    Leading dimensions ``[...]`` are independent clouds (one per sequence of a
    batch, or none). The offset of a point in its head joint's frame is
    ``alpha * offsets[tail] + sigma * noise`` (PC-MRL Eq. 3).

    Attributes:
        heads: ``[..., P]`` joint whose global rotation and position the point follows.
        tails: ``[..., P]`` child joint of the point's bone.
        alpha: ``[..., P, 1]`` position along the bone.
        noise: ``[..., P, 3]`` standard normal offset.
        groups: ``[..., P]`` index into :data:`POINT_GROUPS` (the bone's group).
        sigma: Standard deviation of the offset (metres in PC-MRL).
    """

    heads: torch.Tensor
    tails: torch.Tensor
    alpha: torch.Tensor
    noise: torch.Tensor
    groups: torch.Tensor
    sigma: float

    def local(self, offsets: torch.Tensor) -> torch.Tensor:
        """``[..., P, 3]`` point offsets in their head joint's frame.

        Args:
            offsets: ``[J, 3]`` or ``[..., J, 3]`` bone offsets (one set per cloud).
        """
        offsets = offsets.to(self.noise.dtype)
        if offsets.dim() == 2:
            bone = offsets[self.tails]
        else:
            bone = torch.gather(offsets, -2, self.tails.unsqueeze(-1).expand(*self.tails.shape, 3))
        return self.alpha * bone + self.sigma * self.noise

    def points(
        self,
        global_rotations: torch.Tensor,
        global_positions: torch.Tensor,
        offsets: torch.Tensor,
    ) -> torch.Tensor:
        """``[..., T, P, 3]`` point trajectories of a pose sequence (differentiable).

        Args:
            global_rotations: ``[..., T, J, 4]`` global joint rotations (w, x, y, z).
            global_positions: ``[..., T, J, 3]`` global joint positions.
            offsets: ``[J, 3]`` or ``[..., J, 3]`` bone offsets of the skeleton(s).
        """
        local = self.local(offsets).to(global_positions.dtype)
        if self.heads.dim() == 1:
            samples = PointSamples(self.heads, local, self.groups)
            return PointCloud.points(global_rotations, global_positions, samples)
        # one layout per sequence: gather the head joints per sequence
        idx = self.heads.unsqueeze(-2).unsqueeze(-1)  # [..., 1, P, 1]
        frames = global_positions.shape[-3]
        rot = torch.gather(
            global_rotations,
            -2,
            idx.expand(*self.heads.shape[:-1], frames, self.heads.shape[-1], 4),
        )
        pos = torch.gather(
            global_positions,
            -2,
            idx.expand(*self.heads.shape[:-1], frames, self.heads.shape[-1], 3),
        )
        return pos + Q.rotate(rot, local.unsqueeze(-3))

    def onehot(self, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        """``[..., P, 5]`` one-hot body groups."""
        return torch.nn.functional.one_hot(self.groups, len(POINT_GROUPS)).to(dtype)


def sample_layout(
    skeleton: Skeleton,
    num_points: int,
    sigma: float,
    batch: Sequence[int] = (),
    generator: torch.Generator | None = None,
    device: torch.device | str | None = None,
) -> PointLayout:
    """Draw temporally consistent point clouds on ``skeleton`` (PC-MRL Eq. 3).

    Each point picks a bone with probability proportional to its length
    (zero-length bones are never picked), ``alpha ~ U[0, 1]`` and a standard
    normal offset scaled by ``sigma``. Draws follow
    :meth:`PointCloud.sample` (same order of random calls) so that with
    ``batch=()`` and the same generator the clouds are identical.

    Args:
        skeleton: The skeleton (its offsets decide the bone probabilities).
        num_points: Points per cloud (PC-MRL: 256 source, 1024 target).
        sigma: Offset standard deviation, in the skeleton's units.
        batch: Leading shape of independent clouds.
        generator: Random generator (default: torch's global one).
        device: Device of the result.

    Raises:
        SkeletonError: The skeleton has no bone of non-zero length.
    """
    if num_points < 1:
        raise SkelagnosticError(f"num_points must be positive, got {num_points}")
    bones = skeleton.bones()
    lengths = skeleton.bone_lengths().double()
    zero = set(zero_length_bones(skeleton))
    weights = torch.tensor(
        [0.0 if c in zero else float(lengths[c]) for _, c in bones], dtype=torch.float64
    )
    if not bones or float(weights.sum()) <= 0:
        raise SkeletonError(f"{skeleton!r} has no bone of non-zero length to sample points on")
    heads = torch.tensor([p for p, _ in bones], dtype=torch.long)
    tails = torch.tensor([c for _, c in bones], dtype=torch.long)
    count = math.prod(batch) if batch else 1
    pick = torch.multinomial(
        weights.expand(count, -1), num_points, replacement=True, generator=generator
    )
    alpha = torch.rand(count, num_points, 1, generator=generator, dtype=torch.float64)
    noise = torch.randn(count, num_points, 3, generator=generator, dtype=torch.float64)
    shape = tuple(batch)
    groups = group_of_joints(skeleton)[tails[pick]]
    layout = PointLayout(
        heads[pick].reshape(*shape, num_points),
        tails[pick].reshape(*shape, num_points),
        alpha.reshape(*shape, num_points, 1).float(),
        noise.reshape(*shape, num_points, 3).float(),
        groups.reshape(*shape, num_points),
        float(sigma),
    )
    if device is not None:
        layout = PointLayout(
            *(
                t.to(device)
                for t in (layout.heads, layout.tails, layout.alpha, layout.noise, layout.groups)
            ),
            layout.sigma,
        )
    return layout


def end_effector_pairs(source: Skeleton, target: Skeleton) -> list[tuple[int, int]]:
    """Matched end effectors ``(source joint, target joint)``: one per shared body group.

    Uses :meth:`Skeleton.end_effectors` (hands, feet/toes, head) on both sides.
    """
    by_group = {source.body_groups[j]: j for j in source.end_effectors()}
    return [
        (by_group[target.body_groups[j]], j)
        for j in target.end_effectors()
        if target.body_groups[j] in by_group
    ]


def lateral_direction(points: torch.Tensor, groups: torch.Tensor, up: int = 1) -> torch.Tensor:
    """``[B, T, 3]`` ground-projected left-minus-right direction of clouds ``[B, T, P, 3]``.

    The centroids of the left arm and left leg minus those of the right arm and
    right leg (body groups ``groups`` ``[B, P]``), with the ``up`` component set to
    zero. Only the group labels are used, so it works on any skeleton's cloud. A
    cloud without points on both sides gives a zero vector (see :func:`heading_frames`).
    """
    index = {g: i for i, g in enumerate(POINT_GROUPS)}
    onehot = torch.nn.functional.one_hot(groups, len(POINT_GROUPS)).to(points.dtype)
    count = onehot.sum(-2)  # [B, G]
    scale = count.clamp_min(1.0)[:, None, :, None]
    centroid = torch.einsum("btpc,bpg->btgc", points, onehot) / scale
    lateral = points.new_zeros((*points.shape[:2], 3))
    for left, right in (("left_arm", "right_arm"), ("left_leg", "right_leg")):
        a, b = index[left], index[right]
        both = ((count[:, a] > 0) & (count[:, b] > 0)).to(points.dtype)[:, None, None]
        lateral = lateral + both * (centroid[:, :, a] - centroid[:, :, b])
    lateral[..., up] = 0.0
    return lateral


def heading_frames(
    points: torch.Tensor, groups: torch.Tensor, up: int = 1, width: int = 15
) -> torch.Tensor:
    """``[B, T, 4]`` rotations about ``up`` that map the canonical axis onto each frame's heading.

    The canonical axis is ``(up + 1) % 3``; a frame's heading is its
    :func:`lateral_direction` averaged over a centred window of ``width`` frames
    (cut at the ends of the sequence), so the left/right swing of the limbs in a
    gait cycle averages out. Frames whose averaged direction is (numerically)
    zero get the identity, which is what a cloud without left and right groups
    gets everywhere.

    Args:
        points: ``[B, T, P, 3]`` clouds.
        groups: ``[B, P]`` body-group ids (:data:`POINT_GROUPS`).
        up: Up axis index.
        width: Frames of the moving average (1: per frame).
    """
    if width < 1:
        raise SkelagnosticError(f"heading window must be at least 1 frame, got {width}")
    lateral = lateral_direction(points, groups, up)
    frames = lateral.shape[1]
    if width > 1 and frames > 1:
        # mean over the frames of the window that exist (padding not counted)
        mean = torch.nn.functional.avg_pool1d(
            lateral.transpose(1, 2), width, stride=1, padding=width // 2, count_include_pad=False
        )
        lateral = mean[..., :frames].transpose(1, 2)
    forward = (up + 1) % 3
    heading = Q.heading_from_direction(lateral, up=up, forward=forward)
    degenerate = lateral.norm(dim=-1, keepdim=True) < 1e-6
    return torch.where(
        degenerate,
        Q.identity(*heading.shape[:-1], dtype=heading.dtype, device=heading.device),
        heading,
    )
