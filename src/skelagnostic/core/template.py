"""Template geometry: a skeleton's canonical neutral pose (:meth:`Skeleton.template`).

The canonical frame is Y up, facing +Z, left +X, root at the origin. Every bone
keeps its length; its direction comes from the rest offsets, turned into the
canonical frame by the body itself, with each limb hung straight down from its
upper-arm or hip joint (:func:`canonical_template`, the steps are in
``docs/skeleton.md``). A skeleton whose rest geometry gives no body frame gets the
length-only construction (:func:`template_from_lengths`). Joint roles (elbows,
knees, twist and toe joints, the head) come from the names
(:mod:`skelagnostic.core.names`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import torch

from skelagnostic.core.names import is_middle_joint, is_toe_joint, is_twist_joint, name_words

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic.core.skeleton import Skeleton

__all__ = ["canonical_template", "template_from_lengths"]

_LIMB_GROUPS = ("left_arm", "right_arm", "left_leg", "right_leg")


def _parallel(d: torch.Tensor, axis: torch.Tensor, tol: float = 0.1) -> bool:
    """Whether unit ``d`` lies along ``axis`` (either way) within ``tol`` of the sine."""
    return float(torch.linalg.cross(d, axis).norm()) < tol


def _axis_rotation(axis: torch.Tensor, angle: float) -> torch.Tensor:
    """``[3, 3]`` rotation by ``angle`` radians about unit ``axis`` (Rodrigues)."""
    k = torch.zeros(3, 3, dtype=axis.dtype)
    k[0, 1], k[0, 2], k[1, 2] = -axis[2], axis[1], -axis[0]
    k = k - k.T
    a = torch.tensor(angle, dtype=axis.dtype)
    return torch.eye(3, dtype=axis.dtype) + torch.sin(a) * k + (1 - torch.cos(a)) * (k @ k)


def _rotation_between(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``[3, 3]`` smallest rotation taking unit ``a`` to unit ``b``.

    For opposite vectors the half turn is about an axis perpendicular to ``a``.
    """
    axis = torch.linalg.cross(a, b)
    sin = float(axis.norm())
    cos = float(a @ b)
    if sin < 1e-9:
        if cos > 0:
            return torch.eye(3, dtype=a.dtype)
        helper = torch.zeros(3, dtype=a.dtype)
        helper[int(torch.argmin(a.abs()))] = 1.0
        perp = torch.linalg.cross(a, helper)
        return _axis_rotation(perp / perp.norm(), torch.pi)
    return _axis_rotation(axis / sin, float(np.arctan2(sin, cos)))


def canonical_template(skeleton: Skeleton) -> torch.Tensor:
    """``[J, 3]`` canonical neutral pose of ``skeleton`` (see :meth:`Skeleton.template`).

    Args:
        skeleton: The skeleton; its rest offsets, body groups, names and morphology
            decide the pose.

    Returns:
        Joint positions, root at the origin, Y up, facing +Z, left +X.
    """
    units, lengths = _rest_directions(skeleton)
    parents = skeleton.parents
    rest = torch.zeros_like(skeleton.offsets)
    for j, p in enumerate(parents):
        if p >= 0:
            rest[j] = rest[p] + lengths[j] * units[j]
    pivots = {g: _limb_pivot(skeleton, g, lengths) for g in _LIMB_GROUPS}
    frame = _body_frame(skeleton, rest, pivots)
    if frame is None:
        return template_from_lengths(skeleton)
    return _template_from_rest(skeleton, frame, units, lengths, rest, pivots)


def _rest_directions(skeleton: Skeleton) -> tuple[torch.Tensor, torch.Tensor]:
    """``[J, 3]`` unit rest directions (zero for zero-length bones), ``[J]`` lengths."""
    offsets = skeleton.rest_offsets()
    norms = offsets.norm(dim=-1, keepdim=True)
    units = torch.where(norms > 1e-12, offsets / norms.clamp_min(1e-12), 0.0)
    units[0] = 0.0
    return units, skeleton.bone_lengths()


def _head_joint(skeleton: Skeleton) -> int | None:
    """The head: the shallowest spine joint named ``head``, else the deepest spine leaf."""
    groups, names = skeleton.body_groups, skeleton.joint_names
    spine = [j for j in range(1, skeleton.num_joints) if groups[j] == "spine"]
    named = [j for j in spine if "head" in name_words(names[j])]
    if named:
        return min(named, key=skeleton.depth)
    has_child = set(skeleton.parents)
    leaves = [j for j in spine if j not in has_child]
    return max(leaves, key=skeleton.depth) if leaves else None


def _limb_pivot(skeleton: Skeleton, group: str, lengths: torch.Tensor) -> int | None:
    """The joint at which a limb is turned to hang down (upper-arm or hip joint).

    The parent of the limb's first joint named as an elbow (arms) or knee (legs),
    moving up past twist/roll joints and zero-length links; failing that, the
    end of the limb's first non-zero bone. ``None`` when nothing of the limb
    hangs below that joint.
    """
    groups, names, parents = skeleton.body_groups, skeleton.joint_names, skeleton.parents
    members = [j for j in range(1, skeleton.num_joints) if groups[j] == group]
    limb = "arm" if group.endswith("_arm") else "leg"
    middle = next((j for j in members if is_middle_joint(names[j], limb)), None)
    if middle is not None:
        pivot = parents[middle]
        while (
            pivot > 0
            and groups[parents[pivot]] == group
            and (is_twist_joint(names[pivot]) or lengths[middle] <= 0)
        ):
            middle, pivot = pivot, parents[pivot]
        if groups[pivot] == group:
            return pivot
    first = next((j for j in members if lengths[j] > 0), None)
    if first is None or not any(groups[c] == group for c in skeleton.children(first)):
        return None
    return first


def _body_frame(
    skeleton: Skeleton, rest: torch.Tensor, pivots: Mapping[str, int | None]
) -> torch.Tensor | None:
    """``[3, 3]`` rotation taking rest vectors into the canonical frame, or ``None``.

    Its rows are the body's left, up and forward directions in the rest pose.
    """
    groups, parents = skeleton.body_groups, skeleton.parents
    lateral = None
    for left, right in (("left_leg", "right_leg"), ("left_arm", "right_arm")):
        if pivots[left] is not None and pivots[right] is not None:
            lateral = rest[pivots[left]] - rest[pivots[right]]
            break
    target = _head_joint(skeleton)
    quadruped = skeleton.morphology == "quadruped"
    if quadruped:
        front = [
            parents[j]
            for j in range(1, skeleton.num_joints)
            if groups[j].endswith("_arm") and not groups[parents[j]].endswith("_arm")
        ]
        target = front[0] if front else target
    if lateral is None or target is None or float(rest[target].norm()) <= 1e-9:
        return None
    axis = rest[target] / rest[target].norm()
    lateral = lateral - (lateral @ axis) * axis
    if float(lateral.norm()) <= 1e-6 * float(rest[target].norm()):
        return None
    lateral = lateral / lateral.norm()
    if quadruped:
        fwd, up = axis, torch.linalg.cross(axis, lateral)
    else:
        up, fwd = axis, torch.linalg.cross(lateral, axis)
    return torch.stack([lateral, up, fwd])


def _template_from_rest(
    skeleton: Skeleton,
    frame: torch.Tensor,
    units: torch.Tensor,
    lengths: torch.Tensor,
    rest: torch.Tensor,
    pivots: Mapping[str, int | None],
) -> torch.Tensor:
    """The construction of :func:`canonical_template` given the body frame and limb pivots."""
    groups, names = skeleton.body_groups, skeleton.joint_names
    dtype = units.dtype
    lat, up, fwd = torch.eye(3, dtype=dtype)
    quad = skeleton.morphology == "quadruped"
    body_axis = fwd if quad else up
    pivot_of = {pv: g for g, pv in pivots.items() if pv is not None}
    # rot[j]: the rotation applied to the rest directions of the bones below joint j
    rot = [frame.to(dtype)] * skeleton.num_joints
    hanging = [False] * skeleton.num_joints  # j lies below its limb's pivot
    pos = torch.zeros_like(skeleton.offsets)
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            continue
        g = groups[j]
        r = rot[p]
        d = r @ units[j]
        hanging[j] = hanging[p] or p in pivot_of
        girdle = g.endswith(("_arm", "_leg")) and not hanging[j]
        if lengths[j] > 0 and float(d.norm()) > 0:
            fix = torch.eye(3, dtype=dtype)
            hind = quad and (g == "tail" or (girdle and g.endswith("_leg")))
            if hind and float(d @ fwd) > 1e-6 and float(d @ up) >= 0:
                # forward and up from the pelvis: a segment rested upside down
                fix = _axis_rotation(lat, torch.pi)
            elif girdle and _parallel(d, body_axis):
                side = (1.0 if g.startswith("left_") else -1.0) * lat
                quad_arm = quad and g.endswith("_arm")
                target = (side - 2 * up + fwd) / 6**0.5 if quad_arm else side
                fix = _rotation_between(d, target)
            elif hanging[j] and is_toe_joint(names[j]) and d @ up < -0.9:
                fix = _rotation_between(d, fwd)
            r, d = fix @ r, fix @ d
        pos[j] = pos[p] + lengths[j] * d
        rot[j] = r
        if j in pivot_of:
            hang = r @ _pivot_vector(skeleton, j, rest)
            if float(hang.norm()) > 1e-12:
                rot[j] = _rotation_between(hang / hang.norm(), -up) @ r
    return pos - pos[0]


def _pivot_vector(skeleton: Skeleton, pivot: int, rest: torch.Tensor) -> torch.Tensor:
    """Rest vector from a limb's pivot to the nearest limb joint below it not on it."""
    groups = skeleton.body_groups
    group = groups[pivot]
    queue = [c for c in skeleton.children(pivot) if groups[c] == group]
    while queue:
        c = queue.pop(0)
        vec = rest[c] - rest[pivot]
        if float(vec.norm()) > 1e-9:
            return vec
        queue.extend(k for k in skeleton.children(c) if groups[k] == group)
    return torch.zeros(3, dtype=rest.dtype)


def template_from_lengths(skeleton: Skeleton) -> torch.Tensor:
    """The length-only template, used when the rest geometry gives no body frame.

    Bipeds stand with the spine straight up; quadrupeds hold the spine forward
    with the head and neck raised by 45 degrees. Each limb's first non-zero bone
    points sideways (hip, clavicle), the rest straight down (arms down), bones
    ending in a toe/ball point forward; the tail points backward.

    Args:
        skeleton: The skeleton; only its bone lengths, groups, names and morphology count.

    Returns:
        ``[J, 3]`` joint positions, root at the origin, Y up, facing +Z, left +X.
    """
    groups, names = skeleton.body_groups, skeleton.joint_names
    quadruped = skeleton.morphology == "quadruped"
    lengths = skeleton.bone_lengths()
    pos = torch.zeros_like(skeleton.offsets)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=pos.dtype)
    fwd = torch.tensor([0.0, 0.0, 1.0], dtype=pos.dtype)
    lat = torch.tensor([1.0, 0.0, 0.0], dtype=pos.dtype)
    # started[j]: a non-zero bone of j's limb already lies between the limb's start and j
    started = [False] * skeleton.num_joints
    for j, p in enumerate(skeleton.parents):
        if p < 0:
            continue
        g = groups[j]
        name = names[j].lower()
        if g in {"spine", "other"}:
            d = fwd if quadruped else up
            if quadruped and ("head" in name or "neck" in name):
                d = (fwd + up) / 2**0.5
        elif g == "tail":
            d = -fwd
        else:
            before = started[p] if groups[p] == g else False
            if not before and lengths[j] > 0:
                d = (1.0 if g.startswith("left_") else -1.0) * lat
            else:
                d = fwd if any(w in name for w in ("toe", "ball")) else -up
            started[j] = before or bool(lengths[j] > 0)
        pos[j] = pos[p] + lengths[j] * d
    return pos - pos[0]
