"""Batched forward kinematics in torch.

Joints are processed level by level (all joints at the same depth of the tree
at once), so a skeleton costs ``depth`` vectorised steps instead of ``J``
Python iterations; any leading batch dimensions (clips, frames) ride along.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import torch

from skelagnostic.core import quaternion as Q

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
        parents: Parent index per joint, ``-1`` for the root, parents before children.
        translations: Optional ``[..., J, 3]`` animated local translations that replace
            ``offsets`` per frame (BVH files with position channels on non-root joints).

    Returns:
        ``(global_rotations [..., J, 4], global_positions [..., J, 3])``.
    """
    parents = tuple(int(p) for p in parents)
    num_joints = len(parents)
    if rotations.shape[-2] != num_joints or offsets.shape[-2] != num_joints:
        raise ValueError(
            f"forward_kinematics: {num_joints} parents but rotations have "
            f"{rotations.shape[-2]} joints and offsets {offsets.shape[-2]}"
        )
    batch = rotations.shape[:-2]
    offsets = offsets.to(dtype=rotations.dtype, device=rotations.device)
    local_t = offsets.expand(*batch, num_joints, 3) if translations is None else translations
    grot = torch.empty_like(rotations)
    gpos = torch.empty(*batch, num_joints, 3, dtype=rotations.dtype, device=rotations.device)
    for level in _levels(parents):
        idx = list(level)
        par = [parents[j] for j in idx]
        if par[0] < 0:  # the root level
            roots = [j for j, p in zip(idx, par, strict=True) if p < 0]
            if len(roots) != len(idx) or len(roots) != 1:
                raise ValueError("forward_kinematics: the skeleton must have exactly one root")
            grot[..., roots[0], :] = rotations[..., roots[0], :]
            gpos[..., roots[0], :] = root_positions
            continue
        pr = grot[..., par, :]
        grot[..., idx, :] = Q.mul(pr, rotations[..., idx, :])
        gpos[..., idx, :] = gpos[..., par, :] + Q.rotate(pr, local_t[..., idx, :])
    return grot, gpos
