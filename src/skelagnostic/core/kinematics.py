"""Batched forward kinematics and the local/global rotation maps, in torch.

:func:`forward_kinematics` goes from local rotations to global rotations and
positions; :func:`global_from_local` is its rotation half,
:func:`local_from_global` its inverse, and :func:`fk_from_global` the position
half given *global* rotations (what PC-MRL's networks predict). All four take
(w, x, y, z) unit quaternions with arbitrary leading batch dimensions.

The tree is walked joint by joint on a structure-of-arrays layout: each
quaternion component and each coordinate is its own contiguous tensor over
all leading batch dimensions (clips, frames). Every step is a handful of
fused-size elementwise operations on contiguous memory, with no gathers or
strided (w, x, y, z) slices; rest offsets enter as Python scalars (as
tensors when they require gradients). Results are kept in lists and
stacked once at the end, so :func:`forward_kinematics` is differentiable (no in-place
writes). See ``benchmarks/run.py --suite io`` for its speed
against pybvh and ``--suite kinematics`` for how it scales with frame count.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.errors import MotionError

__all__ = [
    "ancestor_matrix",
    "depth_levels",
    "fk_from_global",
    "forward_kinematics",
    "global_from_local",
    "global_rotations_from_directions",
    "local_from_global",
]


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
    _check_parents(parents, num_joints, "forward_kinematics")
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


def _check_parents(parents: Sequence[int], num_joints: int, where: str) -> tuple[int, ...]:
    parents = tuple(int(p) for p in parents)
    if len(parents) != num_joints:
        raise MotionError(f"{where}: {len(parents)} parents but the tensor has {num_joints} joints")
    if (
        num_joints == 0
        or parents[0] >= 0
        or any(not 0 <= p < j for j, p in enumerate(parents) if j)
    ):
        raise MotionError(
            f"{where}: joint 0 must be the only root and parents must precede children"
        )
    return parents


def global_from_local(local_rotations: torch.Tensor, parents: Sequence[int]) -> torch.Tensor:
    """Global rotations from local ones: the rotation half of :func:`forward_kinematics`.

    ``q_global[j] = q_global[parent[j]] * q_local[j]``, the root's global rotation
    being its local one.

    Args:
        local_rotations: ``[..., J, 4]`` local unit quaternions (w, x, y, z).
        parents: Parent index per joint, ``-1`` for the root (joint 0), parents before children.

    Returns:
        ``[..., J, 4]`` global unit quaternions (w, x, y, z).

    Raises:
        MotionError: ``parents`` does not fit the tensor or is not a valid hierarchy.

    Example:
        >>> import torch
        >>> q = torch.tensor([[0.7071068, 0.0, 0.7071068, 0.0]]).expand(3, 4)
        >>> global_from_local(q, [-1, 0, 1])[2].round(decimals=4)
        tensor([-0.7071,  0.0000,  0.7071,  0.0000])
    """
    parents = _check_parents(parents, local_rotations.shape[-2], "global_from_local")
    out: list[torch.Tensor] = [local_rotations[..., 0, :]]
    for j in range(1, len(parents)):
        out.append(Q.mul(out[parents[j]], local_rotations[..., j, :]))
    return torch.stack(out, dim=-2)


def local_from_global(global_rotations: torch.Tensor, parents: Sequence[int]) -> torch.Tensor:
    """Local rotations ``q_global[parent]^-1 * q_global[j]`` from global ones.

    The inverse of :func:`global_from_local`; the root keeps its global rotation.

    Args:
        global_rotations: ``[..., J, 4]`` global unit quaternions (w, x, y, z).
        parents: Parent index per joint, ``-1`` for the root (joint 0), parents before children.

    Returns:
        ``[..., J, 4]`` local unit quaternions (w, x, y, z).

    Raises:
        MotionError: ``parents`` does not fit the tensor or is not a valid hierarchy.
    """
    parents = _check_parents(parents, global_rotations.shape[-2], "local_from_global")
    idx = torch.tensor(parents[1:], dtype=torch.long, device=global_rotations.device)
    child = Q.mul(Q.inv(global_rotations[..., idx, :]), global_rotations[..., 1:, :])
    return torch.cat([global_rotations[..., :1, :], child], dim=-2)


def global_rotations_from_directions(
    directions: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
    known: Sequence[bool] | None = None,
    eps: float = 1e-9,
) -> torch.Tensor:
    """Global rotations that point every bone along given world directions, without twist.

    ``directions[..., c, :]`` is the wanted direction of the bone from
    ``parents[c]`` to ``c`` (any length; the root's entry is not read). A bone
    *counts* when its rest offset is longer than ``eps`` and ``known[c]``. Joint by
    joint from the root down:

    * a joint with one counting child bone gets the shortest-arc (swing) rotation
      from that bone's rest offset, carried by the parent's global rotation, to its
      direction (:func:`~skelagnostic.core.quaternion.rotation_between`);
    * a joint with several gets the rotation that best maps their rest offsets onto
      their directions (Kabsch, :func:`~skelagnostic.core.quaternion.best_rotation`,
      unit vectors, equal weights);
    * a joint with none keeps its parent's global rotation (the root: identity).

    Twist about a bone is not determined by its direction; single-child joints get none
    relative to their parent.

    Args:
        directions: ``[..., J, 3]`` bone directions in world axes.
        offsets: ``[J, 3]`` rest offsets (rest pose = identity rotations).
        parents: Parent index per joint, ``-1`` for the root (joint 0), parents before children.
        known: Per joint, whether its bone's direction is given (default: all).
        eps: Rest offsets not longer than this are not bones.

    Returns:
        ``[..., J, 4]`` global unit quaternions (w, x, y, z).

    Raises:
        MotionError: ``parents`` or ``known`` does not fit the tensor, or ``parents``
            is not a valid hierarchy.

    Example:
        >>> import torch
        >>> offsets = torch.tensor([[0.0, 0, 0], [0, 1, 0], [0, 1, 0]])
        >>> dirs = torch.tensor([[0.0, 0, 0], [1, 0, 0], [1, 0, 0]])
        >>> g = global_rotations_from_directions(dirs, offsets, [-1, 0, 1])
        >>> Q.rotate(g[0], offsets[1]).round(decimals=6).tolist()
        [1.0, 0.0, 0.0]
    """
    num = directions.shape[-2]
    parents = _check_parents(parents, num, "global_rotations_from_directions")
    if known is not None and len(known) != num:
        raise MotionError(
            f"global_rotations_from_directions: known has {len(known)} entries for {num} joints"
        )
    offsets = offsets.to(directions)
    lengths = offsets.norm(dim=-1)
    kids: list[list[int]] = [[] for _ in parents]
    for c, p in enumerate(parents):
        if p >= 0 and float(lengths[c]) > eps and (known is None or bool(known[c])):
            kids[p].append(c)
    lead = directions.shape[:-2]
    identity = Q.identity(*lead, dtype=directions.dtype, device=directions.device)
    glob: list[torch.Tensor] = []
    for j, p in enumerate(parents):
        g_parent = identity if p < 0 else glob[p]
        if not kids[j]:
            g = g_parent
        elif len(kids[j]) == 1:
            c = kids[j][0]
            rest_dir = Q.rotate(g_parent, offsets[c].expand(*lead, 3))
            g = Q.mul(Q.rotation_between(rest_dir, directions[..., c, :]), g_parent)
        else:
            rest = offsets[kids[j]]
            rest = rest / rest.norm(dim=-1, keepdim=True)
            target = directions[..., kids[j], :]
            target = target / target.norm(dim=-1, keepdim=True).clamp_min(eps)
            g = Q.best_rotation(rest, target)
        glob.append(g)
    return torch.stack(glob, dim=-2)


@lru_cache(maxsize=256)
def _ancestors(parents: tuple[int, ...]) -> torch.Tensor:
    num = len(parents)
    mat = torch.zeros(num, num)
    for j in range(1, num):
        k = j
        while k > 0:
            mat[j, k] = 1.0
            k = parents[k]
    return mat


def ancestor_matrix(parents: Sequence[int]) -> torch.Tensor:
    """``[J, J]`` with 1 where column ``k`` is ``j`` or an ancestor of row ``j`` (root excluded).

    Row ``j`` selects the bones on the path from the root to joint ``j``, so
    ``ancestor_matrix(parents) @ bones`` sums them (see :func:`fk_from_global`).
    """
    return _ancestors(tuple(int(p) for p in parents)).clone()


def fk_from_global(
    global_rotations: torch.Tensor,
    root_positions: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
) -> torch.Tensor:
    """Global joint positions from *global* rotations (differentiable, no loop over joints).

    Every bone vector is its rest offset rotated by the parent's global rotation
    and a joint's position is the root plus the bones on its path (PC-MRL Eq. 1),
    summed with one product by :func:`ancestor_matrix`. With ``global_rotations``
    from :func:`global_from_local` it equals the positions of
    :func:`forward_kinematics`.

    Args:
        global_rotations: ``[*B, *T, J, 4]`` global unit quaternions (w, x, y, z).
        root_positions: ``[*B, *T, 3]`` global root positions.
        offsets: ``[J, 3]`` rest offsets shared by all, or ``[*B, J, 3]`` one set per
            leading batch element (broadcast over the remaining dimensions ``*T``, e.g. frames).
        parents: Parent index per joint, ``-1`` for the root (joint 0), parents before children.

    Returns:
        ``[*B, *T, J, 3]`` global joint positions.

    Raises:
        MotionError: ``parents`` or ``offsets`` does not fit ``global_rotations``.
    """
    parents = _check_parents(parents, global_rotations.shape[-2], "fk_from_global")
    if offsets.dim() < 2 or offsets.shape[-2:] != (len(parents), 3):
        raise MotionError(
            f"fk_from_global: offsets must be [..., {len(parents)}, 3], got {list(offsets.shape)}"
        )
    if offsets.dim() > global_rotations.dim():
        raise MotionError(
            f"fk_from_global: offsets {list(offsets.shape)} have more dimensions than the "
            f"rotations {list(global_rotations.shape)}"
        )
    lead = offsets.dim() - 2
    offsets = offsets.reshape(
        *offsets.shape[:lead], *([1] * (global_rotations.dim() - offsets.dim())), len(parents), 3
    ).to(global_rotations)
    parent_idx = torch.tensor([max(p, 0) for p in parents], device=global_rotations.device)
    bones = Q.rotate(
        global_rotations[..., parent_idx, :], offsets.expand(*global_rotations.shape[:-1], 3)
    )
    ancestors = _ancestors(parents).to(global_rotations)
    return root_positions.unsqueeze(-2) + torch.einsum("jk,...kc->...jc", ancestors, bones)
