"""Skeleton templates (HuMoT Sec. 3.2, App. A.2), major joints and the model's axes.

**Axes.** HuMoT's templates have the pelvis at the origin, the transverse
plane parallel to XY and the coronal plane parallel to XZ: Z is up, X is
lateral and Y is the front-back axis. skelagnostic's canonical frame
(:meth:`skelagnostic.Skeleton.template`) is Y up, facing +Z, left +X. The
model frame used here is the proper rotation (+90 degrees about X) of it::

    model X = +X (character's left)    model Y = -Z (backward)    model Z = +Y (up)

so the template's transverse plane is XY and its coronal plane XZ. Motions are
mapped with the same rotation from their skeleton's up axis
(:func:`to_model_frame`) and back (:func:`from_model_frame`).

**Templates.** The neutral pose is :meth:`Skeleton.template` (standing, arms
down, root at the origin), rebuilt from the clip's bone lengths: the temporal
median of the forward-kinematics bone lengths (App. A.2; constant for BVH clips,
but not for positional data or decoded motions).

**Major joints.** Ankles, knees, hips, shoulders, elbows and wrists, found for
any human topology from body groups and the template geometry (no name
lists): in each limb group, the main chain runs from the limb's first joint
to the group's end effector; its two longest consecutive bones that hang
straight down in the template are the thigh and shin (legs) or the upper arm
and forearm (arms); their three end points are hip, knee, ankle or shoulder,
elbow, wrist.
"""

from __future__ import annotations

from itertools import pairwise

import torch

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkeletonError

__all__ = [
    "LIMBS",
    "from_model_frame",
    "major_joints",
    "major_mask",
    "median_bone_lengths",
    "motion_positions",
    "skeleton_template",
    "to_model_frame",
]

#: Limb groups and the names of their three major joints, from the body outwards.
LIMBS: dict[str, tuple[str, str, str]] = {
    "left_leg": ("hip", "knee", "ankle"),
    "right_leg": ("hip", "knee", "ankle"),
    "left_arm": ("shoulder", "elbow", "wrist"),
    "right_arm": ("shoulder", "elbow", "wrist"),
}

# Proper rotations taking each up axis to model Z (columns: source x, y, z).
_TO_MODEL = {
    "y": torch.tensor([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "z": torch.eye(3),
    "x": torch.tensor([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]]),
}


def to_model_frame(positions: torch.Tensor, up_axis: str = "y") -> torch.Tensor:
    """Rotate ``[..., 3]`` positions from a ``up_axis``-up frame to the model frame (Z up).

    Raises:
        SkeletonError: ``up_axis`` is not x, y or z.
    """
    if up_axis not in _TO_MODEL:
        raise SkeletonError(f"up_axis must be 'x', 'y' or 'z', got {up_axis!r}")
    return positions @ _TO_MODEL[up_axis].to(positions).T


def from_model_frame(positions: torch.Tensor, up_axis: str = "y") -> torch.Tensor:
    """Inverse of :func:`to_model_frame`.

    Raises:
        SkeletonError: ``up_axis`` is not x, y or z.
    """
    if up_axis not in _TO_MODEL:
        raise SkeletonError(f"up_axis must be 'x', 'y' or 'z', got {up_axis!r}")
    return positions @ _TO_MODEL[up_axis].to(positions)


def median_bone_lengths(positions: torch.Tensor, skeleton: Skeleton) -> torch.Tensor:
    """``[J]`` temporal median of each joint's bone length in ``positions`` ``[F, J, 3]`` (root 0).

    The body root and the joints above it (a trajectory carrier, see
    :attr:`Skeleton.body_root <skelagnostic.Skeleton.body_root>`) get 0, as in
    :meth:`Skeleton.bone_lengths <skelagnostic.Skeleton.bone_lengths>`: the
    carrier's distance to the hips is the trajectory, not a bone.

    Raises:
        SkeletonError: ``positions`` does not have the skeleton's joint count.
    """
    if positions.dim() != 3 or positions.shape[1:] != (skeleton.num_joints, 3):
        raise SkeletonError(
            f"positions must have shape [F, {skeleton.num_joints}, 3], got {list(positions.shape)}"
        )
    parents = torch.tensor([max(p, 0) for p in skeleton.parents], device=positions.device)
    lengths = (positions - positions[:, parents]).norm(dim=-1).median(dim=0).values
    lengths[[*skeleton.carrier_joints(), skeleton.body_root]] = 0.0
    return lengths


def skeleton_template(skeleton: Skeleton, positions: torch.Tensor | None = None) -> torch.Tensor:
    """The HuMoT template of a skeleton, ``[J, 3]`` in the model frame.

    Args:
        skeleton: The skeleton.
        positions: Optional ``[F, J, 3]`` joint positions of a clip; the template
            then takes the clip's median bone lengths instead of the skeleton's.

    Returns:
        Joint positions of the neutral pose (pelvis/root at the origin, Z up,
        X left), float64 unless the skeleton is float32.

    Example:
        >>> import skelagnostic as sa
        >>> from skelagnostic_humot.template import skeleton_template
        >>> offsets = [[0, 0, 0], [0, 1, 0], [0, 2, 0]]
        >>> sk = sa.Skeleton(["hips", "spine", "head"], [-1, 0, 1], offsets)
        >>> skeleton_template(sk).tolist()
        [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0]]
    """
    sk = skeleton
    if positions is not None:
        lengths = median_bone_lengths(positions.to(sk.offsets.dtype), sk)
        norms = sk.offsets.norm(dim=-1, keepdim=True)
        unit = torch.where(
            norms > 0,
            sk.offsets / norms.clamp_min(1e-12),
            torch.tensor([0.0, 1.0, 0.0], dtype=sk.offsets.dtype),
        )
        sk = Skeleton(
            sk.joint_names,
            sk.parents,
            unit * lengths[:, None],
            body_groups=sk.body_groups,
            up_axis=sk.up_axis,
            name=sk.name,
            morphology=sk.morphology,
            body_root=sk.body_root,
        )
    return to_model_frame(sk.template(), "y")


def _limb_chain(skeleton: Skeleton, group: str) -> list[int]:
    groups = skeleton.body_groups
    effectors = [e for e in skeleton.end_effectors() if groups[e] == group]
    if not effectors:
        return []
    chain = [effectors[0]]
    while skeleton.parents[chain[-1]] >= 0 and groups[skeleton.parents[chain[-1]]] == group:
        chain.append(skeleton.parents[chain[-1]])
    return chain[::-1]


def major_joints(skeleton: Skeleton) -> dict[str, int]:
    """The major joints of a human skeleton, ``{"left_knee": index, ...}``.

    Keys are ``<side>_<joint>`` for side in left/right and joint in
    hip/knee/ankle (legs) and shoulder/elbow/wrist (arms); a limb whose chain
    has fewer than two hanging bones contributes nothing.

    Example:
        >>> import skelagnostic as sa
        >>> from skelagnostic_humot.template import major_joints
        >>> sk = sa.procedural.generate("biped22", "walk", seconds=0.1)[0].skeleton
        >>> [sk.joint_names[j] for j in major_joints(sk).values()][:3]
        ['LeftUpLeg', 'LeftLeg', 'LeftFoot']
    """
    tmpl = skeleton.template()
    down = torch.tensor([0.0, -1.0, 0.0], dtype=tmpl.dtype)
    out: dict[str, int] = {}
    for group, names in LIMBS.items():
        chain = _limb_chain(skeleton, group)
        # bones along the chain (ending at chain[i]) that hang down, skipping zero-length ones
        hanging: list[tuple[int, float]] = []
        for j in chain:
            p = skeleton.parents[j]
            vec = tmpl[j] - tmpl[p]
            length = float(vec.norm())
            if length <= 1e-9:
                continue
            if float(vec @ down) / length > 0.99:
                hanging.append((j, length))
            else:
                hanging.append((-1, 0.0))  # breaks consecutiveness
        best, pair = 0.0, None
        for (a, la), (b, lb) in pairwise(hanging):
            if a >= 0 and b >= 0 and la + lb > best:
                best, pair = la + lb, (a, b)
        if pair is None:
            continue
        middle, end = pair
        side = group.split("_")[0]
        out[f"{side}_{names[0]}"] = skeleton.parents[middle]
        out[f"{side}_{names[1]}"] = middle
        out[f"{side}_{names[2]}"] = end
    return out


def major_mask(skeleton: Skeleton) -> torch.Tensor:
    """``[J]`` boolean: whether each joint is a major joint (see :func:`major_joints`)."""
    mask = torch.zeros(skeleton.num_joints, dtype=torch.bool)
    mask[list(major_joints(skeleton).values())] = True
    return mask


def motion_positions(motion: Motion) -> torch.Tensor:
    """``[F, J, 3]`` global joint positions of ``motion`` in the model frame."""
    return to_model_frame(motion.global_positions(), motion.skeleton.up_axis)
