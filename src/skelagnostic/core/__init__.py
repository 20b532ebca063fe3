"""The motion core: skeletons, motions, quaternions and forward kinematics (numpy + torch only)."""

from skelagnostic.core.kinematics import forward_kinematics
from skelagnostic.core.motion import UNITS, Motion, reroot
from skelagnostic.core.skeleton import BODY_GROUPS, Skeleton, infer_body_groups

__all__ = [
    "BODY_GROUPS",
    "UNITS",
    "Motion",
    "Skeleton",
    "forward_kinematics",
    "infer_body_groups",
    "reroot",
]
