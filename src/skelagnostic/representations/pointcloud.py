"""Temporally consistent point clouds with body groups (PC-MRL skeleton obfuscation)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError, SkeletonError
from skelagnostic.representations.base import MotionRepresentation

#: The body groups of the one-hot code; joints in other groups (tail, other) count as spine.
POINT_GROUPS = ("spine", "left_arm", "right_arm", "left_leg", "right_leg")


@dataclass(frozen=True)
class PointSamples:
    """Where each point sits on the skeleton; sampled once, reused for every frame.

    Attributes:
        joints: ``[P]`` head joint of each point's bone (the point follows its global rotation).
        local: ``[P, 3]`` point position in the head joint's frame.
        groups: ``[P]`` index into :data:`POINT_GROUPS`.
    """

    joints: torch.Tensor
    local: torch.Tensor
    groups: torch.Tensor


class PointCloud(MotionRepresentation):
    """Points attached to the bones, ``[T, P, 8]``: (x, y, z, one-hot of 5 body groups).

    Each point picks a bone with probability proportional to its length, a
    position ``alpha ~ U[0, 1]`` along it plus a Gaussian offset of standard
    deviation ``sigma`` in the bone's local frame, then follows the bone's
    global rotation (PC-MRL Eq. 3), so the same points are tracked in every
    frame. The one-hot code is the bone's body group (:data:`POINT_GROUPS`;
    tail and other joints count as spine) and is left out of normalisation.
    Not invertible (the skeleton is deliberately hidden).

    Args:
        num_points: Points per cloud (PC-MRL: 256 source, 1024 target).
        sigma: Offset standard deviation in the data's length units (PC-MRL:
            0.05 with motion in metres).
        seed: Seed of the sampling; the same skeleton gets the same points.
    """

    name: ClassVar[str] = "point_cloud"
    channels: ClassVar[tuple[str, ...]] = ("x", "y", "z", *POINT_GROUPS)
    unnormalized_channels: ClassVar[tuple[int, ...]] = (3, 4, 5, 6, 7)

    def __init__(self, num_points: int = 256, sigma: float = 0.05, seed: int = 0) -> None:
        super().__init__()
        if num_points < 1:
            raise SkelagnosticError(f"num_points must be positive, got {num_points}")
        if sigma < 0:
            raise SkelagnosticError(f"sigma must be non-negative, got {sigma}")
        self.num_points = int(num_points)
        self.sigma = float(sigma)
        self.seed = int(seed)

    def config(self) -> dict[str, Any]:
        """Constructor options."""
        return {"num_points": self.num_points, "sigma": self.sigma, "seed": self.seed}

    def num_elements(self, skeleton: Skeleton) -> int:
        """``P``, the number of points."""
        return self.num_points

    def sample(self, skeleton: Skeleton, generator: torch.Generator | None = None) -> PointSamples:
        """Draw the points of ``skeleton`` (seeded by ``seed`` unless a generator is given).

        Raises:
            SkeletonError: The skeleton has no bone of non-zero length.
        """
        if generator is None:
            generator = torch.Generator().manual_seed(self.seed)
        offsets = skeleton.offsets.double()
        bones = skeleton.bones()
        heads = torch.tensor([p for p, _ in bones], dtype=torch.long)
        tails = torch.tensor([c for _, c in bones], dtype=torch.long)
        lengths = offsets[tails].norm(dim=-1) if bones else torch.zeros(0)
        if not bones or float(lengths.sum()) <= 0:
            raise SkeletonError(f"{skeleton!r} has no bone of non-zero length to sample points on")
        pick = torch.multinomial(lengths, self.num_points, replacement=True, generator=generator)
        alpha = torch.rand(self.num_points, 1, generator=generator, dtype=torch.float64)
        noise = torch.randn(self.num_points, 3, generator=generator, dtype=torch.float64)
        local = alpha * offsets[tails[pick]] + self.sigma * noise
        group_of = {g: i for i, g in enumerate(POINT_GROUPS)}
        joint_group = torch.tensor([group_of.get(g, 0) for g in skeleton.body_groups])
        return PointSamples(heads[pick], local, joint_group[tails[pick]])

    @staticmethod
    def points(
        global_rotations: torch.Tensor, global_positions: torch.Tensor, samples: PointSamples
    ) -> torch.Tensor:
        """Point positions ``[..., P, 3]`` for a pose; differentiable in both inputs.

        Args:
            global_rotations: ``[..., J, 4]`` global joint rotations (w, x, y, z).
            global_positions: ``[..., J, 3]`` global joint positions.
            samples: Output of :meth:`sample`.
        """
        rot = global_rotations[..., samples.joints, :]
        local = samples.local.to(global_positions.dtype).to(global_positions.device)
        return global_positions[..., samples.joints, :] + Q.rotate(
            rot, local.expand_as(global_positions[..., samples.joints, :])
        )

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, P, 8]`` point positions and one-hot body groups."""
        samples = self.sample(motion.skeleton)
        pts = self.points(motion.global_rotations(), motion.global_positions(), samples)
        onehot = torch.nn.functional.one_hot(samples.groups, len(POINT_GROUPS)).to(pts.dtype)
        return torch.cat([pts, onehot.expand(motion.num_frames, -1, -1)], dim=-1)
