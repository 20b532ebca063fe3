"""Joint positions (world or root-local) and the inverse kinematics that decodes them."""

from __future__ import annotations

from typing import Any, ClassVar

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations.base import MotionRepresentation

_EPS = 1e-9


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def rotation_between(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Shortest-arc rotations taking directions ``u`` to directions ``v``.

    Args:
        u: ``[..., 3]`` source directions (any length; zero gives identity).
        v: ``[..., 3]`` target directions.

    Returns:
        ``[..., 4]`` unit quaternions (w, x, y, z); opposite directions turn by
        pi about an axis perpendicular to ``u``.
    """
    u, v = _unit(u), _unit(v)
    w = 1.0 + (u * v).sum(-1, keepdim=True)
    xyz = torch.linalg.cross(u, v, dim=-1)
    nonzero = (u.norm(dim=-1, keepdim=True) > 0.5) & (v.norm(dim=-1, keepdim=True) > 0.5)
    opposite = (w < 1e-7) & nonzero
    if bool(opposite.any()):
        ex = torch.zeros_like(u)
        ex[..., 0] = 1.0
        ey = torch.zeros_like(u)
        ey[..., 1] = 1.0
        helper = torch.where(u[..., :1].abs() < 0.9, ex, ey)
        axis = _unit(torch.linalg.cross(u, helper, dim=-1))
        w = torch.where(opposite, torch.zeros_like(w), w)
        xyz = torch.where(opposite, axis, xyz)
    w = torch.where(nonzero, w, torch.ones_like(w))
    xyz = torch.where(nonzero, xyz, torch.zeros_like(xyz))
    return Q.normalize(torch.cat([w, xyz], dim=-1))


def _best_rotation(rest: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Rotation R minimising sum ||R rest_k - target_k||^2 (Kabsch), ``[K,3]`` x ``[...,K,3]``."""
    h = torch.einsum("ki,...kj->...ij", rest, target)
    u, _, vh = torch.linalg.svd(h)
    v = vh.mT
    d = torch.sign(torch.linalg.det(v @ u.mT))
    d = torch.where(d == 0, torch.ones_like(d), d)
    diag = torch.ones(*d.shape, 3, dtype=rest.dtype, device=rest.device)
    diag[..., 2] = d
    return Q.from_matrix(v @ torch.diag_embed(diag) @ u.mT)


def inverse_kinematics(
    positions: torch.Tensor, skeleton: Skeleton
) -> tuple[torch.Tensor, torch.Tensor]:
    """Local rotations that point every bone of ``skeleton`` at the given joint positions.

    Joints with one child get the shortest-arc (swing) rotation from their rest
    bone direction, carried by the parent, to the target direction; joints with
    several children (hips, chest) get the rotation that best aligns all child
    directions (Kabsch). Bone twist is not observable from positions, so
    single-child joints get none; leaves keep their parent's orientation. Bone
    lengths come from ``skeleton``, only the directions from ``positions``.

    Args:
        positions: ``[..., J, 3]`` global joint positions.
        skeleton: The skeleton (rest pose = zero rotations).

    Returns:
        ``(rotations [..., J, 4] local (w, x, y, z), root_positions [..., 3])``.

    Examples:
        >>> import torch, skelagnostic as sa
        >>> from skelagnostic.representations.positions import inverse_kinematics
        >>> sk = sa.Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]])
        >>> rot, root = inverse_kinematics(torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), sk)
        >>> m = sa.Motion(sk, rot[None], root[None], fps=30)
        >>> torch.allclose(m.global_positions()[0, 2], torch.tensor([2.0, 0, 0]), atol=1e-6)
        True
    """
    parents = skeleton.parents
    offsets = skeleton.offsets.to(positions.dtype).to(positions.device)
    lengths = offsets.norm(dim=-1)
    lead = positions.shape[:-2]
    num = skeleton.num_joints
    identity = torch.zeros(*lead, 4, dtype=positions.dtype, device=positions.device)
    identity[..., 0] = 1.0
    glob: list[torch.Tensor] = []
    for j in range(num):
        p = parents[j]
        g_parent = identity if p < 0 else glob[p]
        kids = [c for c in skeleton.children(j) if lengths[c] > _EPS]
        if not kids:
            g = g_parent
        elif len(kids) == 1:
            c = kids[0]
            rest_dir = Q.rotate(g_parent, offsets[c].expand(*lead, 3))
            target = positions[..., c, :] - positions[..., j, :]
            g = Q.mul(rotation_between(rest_dir, target), g_parent)
        else:
            target = positions[..., kids, :] - positions[..., j : j + 1, :]
            g = _best_rotation(_unit(offsets[kids]), _unit(target))
        glob.append(g)
    local = local_from_global(torch.stack(glob, dim=-2), parents)
    return local, positions[..., 0, :].clone()


class GlobalPositions(MotionRepresentation):
    """Joint positions, ``[T, J, 3]`` (channels x, y, z).

    Args:
        frame: ``"world"``: global positions. ``"root"``: positions relative to
            the ground projection of the body root (:attr:`Skeleton.body_root
            <skelagnostic.Skeleton.body_root>`), rotated into the character's facing
            frame (:meth:`Motion.facing`), so they do not depend on where the
            character is or which way it faces.

    :meth:`decode` runs :func:`inverse_kinematics` (approximate: no bone twist;
    bone lengths from the skeleton). For ``frame="root"`` the decoded motion
    stands at the origin facing the canonical forward axis.
    """

    name: ClassVar[str] = "global_positions"
    channels: ClassVar[tuple[str, ...]] = ("x", "y", "z")

    def __init__(self, frame: str = "world") -> None:
        super().__init__()
        if frame not in {"world", "root"}:
            raise SkelagnosticError(f"frame must be 'world' or 'root', got {frame!r}")
        self.frame = frame

    def config(self) -> dict[str, Any]:
        """Constructor options."""
        return {"frame": self.frame}

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, J, 3]`` joint positions in the chosen frame."""
        pos = motion.global_positions()
        if self.frame == "world":
            return pos
        ground = pos[:, motion.skeleton.body_root].clone()  # the body's, not a carrier's
        ground[:, motion.skeleton.up_index] = 0.0
        return Q.rotate(Q.inv(motion.facing()).unsqueeze(1), pos - ground.unsqueeze(1))

    def decode(self, features: torch.Tensor, skeleton: Skeleton, fps: float = 30.0) -> Motion:
        """A motion whose joints follow the feature positions (see class notes)."""
        self._check_decodable(features, skeleton)
        rotations, root = inverse_kinematics(features, skeleton)
        return Motion(skeleton, rotations, root, fps)
