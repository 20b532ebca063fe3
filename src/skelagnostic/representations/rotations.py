"""Rotation-based representations: root-local velocities, local quaternions and FOQ."""

from __future__ import annotations

from typing import ClassVar

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import MotionError, NotInvertibleError
from skelagnostic.representations.base import MotionRepresentation


class RootLocalVelocities(MotionRepresentation):
    """Joint velocities in the character's facing frame, ``[T, J, 3]`` (vx, vy, vz).

    Units per second, from :meth:`Motion.root_local_velocities` (backward
    differences; the first frame repeats the second). This is the VQ-PAE input.
    Not invertible: the root trajectory and the pose offset are lost.
    """

    name: ClassVar[str] = "root_local_velocities"
    channels: ClassVar[tuple[str, ...]] = ("vx", "vy", "vz")

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, J, 3]`` root-local joint velocities."""
        return motion.root_local_velocities()


class LocalQuaternions(MotionRepresentation):
    """Local joint transforms, ``[T, J, 7]``: (qw, qx, qy, qz, tx, ty, tz).

    Channels 0-3: the local rotation, with sign flips removed along time
    (:func:`~skelagnostic.core.quaternion.continuity`). Channels 4-6: the
    local translation: the root's global position for the root, the rest offset
    (or the animated translation) for the other joints. Exactly invertible:
    :meth:`decode` uses the quaternions and the root translation (the other
    joints' translations come from the skeleton).
    """

    name: ClassVar[str] = "local_quaternions"
    channels: ClassVar[tuple[str, ...]] = ("qw", "qx", "qy", "qz", "tx", "ty", "tz")

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, J, 7]`` local quaternions and translations."""
        rot = Q.continuity(motion.rotations, dim=-3)
        if motion.translations is not None:
            trans = motion.translations.clone()
        else:
            offsets = motion.skeleton.offsets.to(rot.dtype).to(rot.device)
            trans = offsets.expand(motion.num_frames, -1, -1).clone()
        trans[:, 0] = motion.root_positions
        return torch.cat([rot, trans], dim=-1)

    def decode(self, features: torch.Tensor, skeleton: Skeleton, fps: float = 30.0) -> Motion:
        """The motion with these local rotations and root trajectory."""
        self._check_decodable(features, skeleton)
        return Motion(skeleton, features[..., :4], features[:, 0, 4:], fps)


class FirstFrameOffsetQuaternions(MotionRepresentation):
    """First-frame offset quaternions (FOQ, PC-MRL Sec. 3.3), ``[T, J, 7]``.

    Channels 0-3: ``FOQ_t = q_t * q_0^-1`` for each joint's *global* rotation
    ``q_t`` (w, x, y, z), so frame 0 is the identity and a constant roll of a
    bone cancels out (roll invariant). Channels 4-6: global joint positions.
    Decoding needs one known pose: pass ``reference`` (a motion whose first
    frame gives ``q_0``, or ``[J, 4]`` global rotations) to :meth:`decode`.
    """

    name: ClassVar[str] = "foq"
    channels: ClassVar[tuple[str, ...]] = ("qw", "qx", "qy", "qz", "x", "y", "z")
    window_dependent: ClassVar[bool] = True

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, J, 7]`` FOQ and global positions."""
        grot, gpos = motion.global_rotations(), motion.global_positions()
        foq = Q.continuity(Q.mul(grot, Q.inv(grot[:1])), dim=-3)
        return torch.cat([foq, gpos], dim=-1)

    def decode(
        self,
        features: torch.Tensor,
        skeleton: Skeleton,
        fps: float = 30.0,
        reference: Motion | torch.Tensor | None = None,
    ) -> Motion:
        """Rebuild the motion given the global rotations ``q_0`` of its first frame.

        Args:
            features: ``[T, J, 7]`` FOQ features.
            skeleton: The skeleton.
            fps: Frame rate of the result.
            reference: A motion on ``skeleton`` (its first frame is used) or
                ``[J, 4]`` global rotations.

        Raises:
            NotInvertibleError: ``reference`` is missing.
            MotionError: ``reference`` does not fit ``skeleton``.
        """
        self._check_decodable(features, skeleton)
        if reference is None:
            raise NotInvertibleError(
                "FOQ features are relative to the first frame: pass reference= (a Motion or "
                "[J, 4] global rotations of the first frame) to decode them"
            )
        q0 = reference.global_rotations()[0] if isinstance(reference, Motion) else reference
        if q0.shape != (skeleton.num_joints, 4):
            raise MotionError(
                f"reference must give [{skeleton.num_joints}, 4] global rotations, "
                f"got {list(q0.shape)}"
            )
        grot = Q.mul(features[..., :4], q0.to(features.dtype).to(features.device))
        local = local_from_global(grot, skeleton.parents)
        return Motion(skeleton, local, features[:, 0, 4:], fps)
