"""Motion representations: a :class:`~skelagnostic.Motion` as a ``[T, N, C]`` feature tensor.

==========================  =============================  ==========  =========================
class                       registry name                  layout      decode
==========================  =============================  ==========  =========================
GlobalPositions             ``global_positions``           [T, J, 3]   inverse kinematics
RootLocalVelocities         ``root_local_velocities``      [T, J, 3]   NotInvertibleError
LocalQuaternions            ``local_quaternions``          [T, J, 7]   exact
LocalRotations6D            ``local_rot6d``                [T, J, 9]   exact (Gram-Schmidt)
LocalAxisAngle              ``local_axis_angle``           [T, J, 6]   exact
FirstFrameOffsetQuaternions ``foq``                        [T, J, 7]   exact, given one pose
PointCloud                  ``point_cloud``                [T, P, 8]   NotInvertibleError
==========================  =============================  ==========  =========================

Examples:
    >>> import torch, skelagnostic as sa
    >>> from skelagnostic.representations import LocalQuaternions
    >>> sk = sa.Skeleton(["hips", "spine"], [-1, 0], [[0, 1, 0], [0, 0.5, 0]])
    >>> m = sa.Motion(sk, torch.tensor([[1.0, 0, 0, 0]]).expand(4, 2, 4), torch.zeros(4, 3), fps=30)
    >>> rep = LocalQuaternions()
    >>> rep.encode(m).shape
    torch.Size([4, 2, 7])
    >>> torch.allclose(rep.decode(rep.encode(m), sk).global_positions(), m.global_positions())
    True
"""

from skelagnostic.core.quaternion import rotation_between
from skelagnostic.representations.base import MotionRepresentation
from skelagnostic.representations.pointcloud import POINT_GROUPS, PointCloud, PointSamples
from skelagnostic.representations.positions import GlobalPositions, inverse_kinematics
from skelagnostic.representations.rotations import (
    FirstFrameOffsetQuaternions,
    LocalAxisAngle,
    LocalQuaternions,
    LocalRotations6D,
    RootLocalVelocities,
)

#: The built-in representations, as registered by the built-in plugin.
BUILTIN_REPRESENTATIONS: tuple[type[MotionRepresentation], ...] = (
    GlobalPositions,
    RootLocalVelocities,
    LocalQuaternions,
    LocalRotations6D,
    LocalAxisAngle,
    FirstFrameOffsetQuaternions,
    PointCloud,
)

__all__ = [
    "BUILTIN_REPRESENTATIONS",
    "POINT_GROUPS",
    "FirstFrameOffsetQuaternions",
    "GlobalPositions",
    "LocalAxisAngle",
    "LocalQuaternions",
    "LocalRotations6D",
    "MotionRepresentation",
    "PointCloud",
    "PointSamples",
    "RootLocalVelocities",
    "inverse_kinematics",
    "rotation_between",
]
