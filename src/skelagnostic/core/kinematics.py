"""Batched forward kinematics in torch.

The tree is walked joint by joint on a structure-of-arrays layout: each
quaternion component and each coordinate is its own contiguous tensor over
all leading batch dimensions (clips, frames). Every step is a handful of
fused-size elementwise operations on contiguous memory, with no gathers or
strided (w, x, y, z) slices; rest offsets enter as Python scalars (as
tensors when they require gradients). Results are kept in lists and
stacked once at the end, so the function is differentiable (no in-place
writes). See ``benchmarks/run.py --suite io`` for its speed
against pybvh and ``--suite kinematics`` for how it scales with frame count.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import torch

from skelagnostic.errors import MotionError

__all__ = ["depth_levels", "forward_kinematics"]


@lru_cache(maxsize=256)
def _levels(parents: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    depth = [0] * len(parents)
    for j, p in enumerate(parents):
        depth[j] = 0 if p < 0 else depth[p] + 1
    levels: dict[int, list[int]] = {}
    for j, d in enumerate(depth):
        levels.setdefault(d, []).append(j)
    return tuple(tuple(levels[d]) for d in sorted(levels))


def depth_levels(parents: Sequence[int]) -> list[list[int]]:
    """Group joint indices by their depth in the tree (root level first)."""
    return [list(level) for level in _levels(tuple(int(p) for p in parents))]


def forward_kinematics(
    rotations: torch.Tensor,
    root_positions: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
    translations: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global rotations and positions from local joint rotations.

    Args:
        rotations: ``[..., J, 4]`` local unit quaternions (w, x, y, z).
        root_positions: ``[..., 3]`` global position of the root joint.
        offsets: ``[J, 3]`` rest offsets of each joint from its parent (the root's is ignored).
        parents: Parent index per joint, ``-1`` for the root (joint 0), parents before children.
        translations: Optional ``[..., J, 3]`` animated local translations that replace
            ``offsets`` per frame (BVH files with position channels on non-root joints).

    Returns:
        ``(global_rotations [..., J, 4], global_positions [..., J, 3])``.

    Raises:
        MotionError: If the shapes disagree with ``parents`` or the hierarchy is invalid
            (a ``ValueError`` subclass).
    """
    parents = tuple(int(p) for p in parents)
    num_joints = len(parents)
    if rotations.shape[-2] != num_joints or offsets.shape[-2] != num_joints:
        raise MotionError(
            f"forward_kinematics: {num_joints} parents but rotations have "
            f"{rotations.shape[-2]} joints and offsets {offsets.shape[-2]}"
        )
    if (
        num_joints == 0
        or parents[0] >= 0
        or any(not 0 <= p < j for j, p in enumerate(parents) if j > 0)
    ):
        raise MotionError(
            "forward_kinematics: joint 0 must be the only root and parents must precede children"
        )
    # [4, J, ...] and [3, ...]: one contiguous tensor per component
    comp = rotations.movedim(-1, 0).movedim(-1, 1).contiguous()
    root = root_positions.movedim(-1, 0)
    local: list[tuple]
    if translations is None and not offsets.requires_grad:
        local = [tuple(v) for v in offsets.detach().to("cpu", torch.float64).tolist()]
    elif translations is None:  # keep gradients with respect to the bone offsets
        off = offsets.to(rotations)
        local = [(off[j, 0], off[j, 1], off[j, 2]) for j in range(num_joints)]
    else:
        tcomp = translations.movedim(-1, 0).movedim(-1, 1)
        local = [(tcomp[0, j], tcomp[1, j], tcomp[2, j]) for j in range(num_joints)]
    grot: list[tuple[torch.Tensor, ...]] = [tuple(comp[:, 0].unbind(0))]
    gpos: list[tuple[torch.Tensor, ...]] = [tuple(root.unbind(0))]
    for j in range(1, num_joints):
        p = parents[j]
        aw, ax, ay, az = grot[p]
        bw, bx, by, bz = comp[0, j], comp[1, j], comp[2, j], comp[3, j]
        grot.append(
            (
                aw * bw - ax * bx - ay * by - az * bz,
                aw * bx + ax * bw + ay * bz - az * by,
                aw * by - ax * bz + ay * bw + az * bx,
                aw * bz + ax * by - ay * bx + az * bw,
            )
        )
        # rotate the local offset by the parent's global rotation:
        # v' = v + w t + u x t with t = 2 u x v
        vx, vy, vz = local[j]
        tx = 2.0 * (ay * vz - az * vy)
        ty = 2.0 * (az * vx - ax * vz)
        tz = 2.0 * (ax * vy - ay * vx)
        px, py, pz = gpos[p]
        gpos.append((
            px + vx + aw * tx + ay * tz - az * ty,
            py + vy + aw * ty + az * tx - ax * tz,
            pz + vz + aw * tz + ax * ty - ay * tx,
        ))  # fmt: skip
    out_rot = torch.stack([torch.stack(q, dim=-1) for q in grot], dim=-2)
    out_pos = torch.stack([torch.stack(v, dim=-1) for v in gpos], dim=-2)
    return out_rot, out_pos
