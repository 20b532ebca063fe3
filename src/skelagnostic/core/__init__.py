"""The motion core: skeletons, motions, quaternions and forward kinematics (numpy + torch only)."""

from skelagnostic.core.kinematics import forward_kinematics
from skelagnostic.core.motion import UNITS, Motion, reroot
from skelagnostic.core.names import infer_body_groups
from skelagnostic.core.skeleton import BODY_GROUPS, Skeleton

__all__ = [
    "BODY_GROUPS",
    "UNITS",
    "Motion",
    "Skeleton",
    "forward_kinematics",
    "infer_body_groups",
    "reroot",
]
