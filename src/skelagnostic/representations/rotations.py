"""Rotation-based representations: root-local velocities, local rotations and FOQ.

Local rotations come as quaternions, 6D (two matrix columns) or axis-angle vectors.
"""

from __future__ import annotations

from abc import abstractmethod
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


class _LocalRotations(MotionRepresentation):
    """Local joint rotations in one parameterisation, then local translations (tx, ty, tz).

    Subclasses set :attr:`channels` (the rotation's channels first) and the two
    conversions from and to (w, x, y, z) quaternions. The translations are the
    root's global position for the root, the rest offset (or the animated
    translation) for the other joints; :meth:`decode` uses the rotations and the
    root translation (the other joints' translations come from the skeleton).
    """

    @abstractmethod
    def _from_quaternions(self, q: torch.Tensor) -> torch.Tensor:
        """``[..., R]`` rotation channels of continuity-fixed ``[..., 4]`` quaternions."""

    @abstractmethod
    def _to_quaternions(self, r: torch.Tensor) -> torch.Tensor:
        """``[..., 4]`` (w, x, y, z) quaternions of ``[..., R]`` rotation channels."""

    def encode(self, motion: Motion) -> torch.Tensor:
        """``[T, J, R + 3]`` local rotations and translations."""
        rot = self._from_quaternions(Q.continuity(motion.rotations, dim=-3))
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
        split = len(self.channels) - 3
        return Motion(
            skeleton, self._to_quaternions(features[..., :split]), features[:, 0, split:], fps
        )


class LocalQuaternions(_LocalRotations):
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

    def _from_quaternions(self, q: torch.Tensor) -> torch.Tensor:
        return q

    def _to_quaternions(self, r: torch.Tensor) -> torch.Tensor:
        return r


class LocalRotations6D(_LocalRotations):
    """Local joint transforms with 6D rotations (Zhou et al. 2019), ``[T, J, 9]``.

    Channels 0-5: the first two columns of the local rotation matrix ``m``,
    column after column: (m00, m10, m20, m01, m11, m21)
    (:func:`~skelagnostic.core.quaternion.to_rot6d`); continuous over all
    rotations, which makes it a good network output. Channels 6-8: the local
    translation, as in :class:`LocalQuaternions`. :meth:`decode` orthonormalises
    the two columns (Gram-Schmidt, ``roma.special_gramschmidt``), so any
    features whose columns are not parallel decode to a motion; exact for
    encoded features.
    """

    name: ClassVar[str] = "local_rot6d"
    channels: ClassVar[tuple[str, ...]] = (
        "m00", "m10", "m20", "m01", "m11", "m21", "tx", "ty", "tz",
    )  # fmt: skip

    def _from_quaternions(self, q: torch.Tensor) -> torch.Tensor:
        return Q.to_rot6d(q)

    def _to_quaternions(self, r: torch.Tensor) -> torch.Tensor:
        return Q.from_rot6d(r)


class LocalAxisAngle(_LocalRotations):
    """Local joint transforms with axis-angle rotations, ``[T, J, 6]``: (rx, ry, rz, tx, ty, tz).

    Channels 0-2: the rotation vector (unit axis times the angle in radians,
    the angle in ``[0, pi]``; :func:`~skelagnostic.core.quaternion.to_rotvec`).
    Near a half turn the vector flips to the opposite axis between frames.
    Channels 3-5: the local translation, as in :class:`LocalQuaternions`.
    Exactly invertible.
    """

    name: ClassVar[str] = "local_axis_angle"
    channels: ClassVar[tuple[str, ...]] = ("rx", "ry", "rz", "tx", "ty", "tz")

    def _from_quaternions(self, q: torch.Tensor) -> torch.Tensor:
        return Q.to_rotvec(q)

    def _to_quaternions(self, r: torch.Tensor) -> torch.Tensor:
        return Q.from_rotvec(r)


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
