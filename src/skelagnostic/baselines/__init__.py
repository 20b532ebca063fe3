"""Non-learned baselines every evaluation reports beside a model's figures.

* :mod:`~skelagnostic.baselines.names`: :func:`name_match` and :func:`name_copy`, the naive
  retargeter that copies local rotations between joints of corresponding names;
* :mod:`~skelagnostic.baselines.primal`: :func:`primal_copy`, a retargeter that pairs joints
  through the skeletons' primal graphs (Aberman et al. 2020) instead of names;
* :mod:`~skelagnostic.baselines.directions`: :func:`direction_copy`, a retargeter that
  points every target bone along its paired source chain (bone directions, no rest-pose
  convention), and :func:`direction_match`, its pairing;
* :mod:`~skelagnostic.baselines.pose`: :func:`mean_pose` and :func:`mean_pose_on_trajectory`;
* :mod:`~skelagnostic.baselines.keyframes`: :func:`lerp_slerp`, the LaFAN1 interpolation
  baseline (LERP of the root, SLERP of local rotations between keyframes).

Core layer: numpy and torch only (no lightning, hydra or pluggy).
"""

from skelagnostic.baselines.directions import direction_copy, direction_match
from skelagnostic.baselines.keyframes import key_brackets, lerp_keys, lerp_slerp, slerp_keys
from skelagnostic.baselines.names import ROOT_RULES, joint_key, name_copy, name_match, scaled_root
from skelagnostic.baselines.pose import mean_pose, mean_pose_on_trajectory
from skelagnostic.baselines.primal import primal_copy, primal_match, primal_skeleton

__all__ = [
    "ROOT_RULES",
    "direction_copy",
    "direction_match",
    "joint_key",
    "key_brackets",
    "lerp_keys",
    "lerp_slerp",
    "mean_pose",
    "mean_pose_on_trajectory",
    "name_copy",
    "name_match",
    "primal_copy",
    "primal_match",
    "primal_skeleton",
    "scaled_root",
    "slerp_keys",
]
