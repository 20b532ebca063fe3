"""Joint positions (world or root-local) and the inverse kinematics that decodes them."""

from __future__ import annotations

from typing import Any, ClassVar

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import global_rotations_from_directions, local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations.base import MotionRepresentation

_EPS = 1e-9


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
    directions = positions - positions[..., [max(p, 0) for p in parents], :]
    glob = global_rotations_from_directions(directions, offsets, parents, eps=_EPS)
    local = local_from_global(glob, parents)
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
