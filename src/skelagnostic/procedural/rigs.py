"""The rigs of the procedural motion: four skeletons and the role of each joint.

Every joint is ``(name, parent, offset in cm, role)``; roles (``l_hip``,
``spine0``, ``tail1``, ...) tell :mod:`skelagnostic.procedural.gaits` which joint
to animate. Centimetres, Y up, facing +Z, left +X.
"""

from __future__ import annotations

import torch

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError

# (name, parent, offset in cm, role). Roles drive the animation; joints without
# a role (fingers, zero-length helpers) keep their rest rotation.
_Spec = list[tuple[str, str | None, tuple[float, float, float], str | None]]


def _mirror(spec: _Spec, prefixes: tuple[tuple[str, str], ...] = (("Left", "Right"),)) -> _Spec:
    """The right-side copy of a left limb: names renamed by prefix, X negated, roles l* -> r*."""

    def rename(name: str | None) -> str | None:
        if name is None:
            return None
        for left, right in prefixes:
            if name.startswith(left):
                return right + name[len(left) :]
        return name

    return [
        (
            str(rename(name)),
            rename(parent),
            (-off[0], off[1], off[2]),
            None if role is None else "r" + role[1:],
        )
        for name, parent, off, role in spec
    ]


_B22_LEFT_LEG: _Spec = [
    ("LeftUpLeg", "Hips", (9.0, -5.0, 0.0), "l_hip"),
    ("LeftLeg", "LeftUpLeg", (0.0, -42.0, 0.0), "l_knee"),
    ("LeftFoot", "LeftLeg", (0.0, -42.0, 0.0), "l_ankle"),
    ("LeftToe", "LeftFoot", (0.0, -6.0, 13.0), "l_toe"),
]


_B22_LEFT_ARM: _Spec = [
    ("LeftShoulder", "Spine2", (3.0, 11.0, 0.0), "l_clavicle"),
    ("LeftArm", "LeftShoulder", (15.0, 0.0, 0.0), "l_shoulder"),
    ("LeftForeArm", "LeftArm", (28.0, 0.0, 0.0), "l_elbow"),
    ("LeftHand", "LeftForeArm", (26.0, 0.0, 0.0), "l_wrist"),
]


_BIPED22: _Spec = [
    ("Hips", None, (0.0, 95.0, 0.0), "root"),
    *_B22_LEFT_LEG,
    *_mirror(_B22_LEFT_LEG),
    ("Spine", "Hips", (0.0, 10.0, 0.0), "spine0"),
    ("Spine1", "Spine", (0.0, 12.0, 0.0), "spine1"),
    ("Spine2", "Spine1", (0.0, 12.0, 0.0), "spine2"),
    ("Neck", "Spine2", (0.0, 16.0, 0.0), "neck"),
    ("Head", "Neck", (0.0, 10.0, 0.0), "head"),
    *_B22_LEFT_ARM,
    *_mirror(_B22_LEFT_ARM),
]


_B31_LEFT_LEG: _Spec = [
    ("LHipJoint", "Hips", (0.0, 0.0, 0.0), None),
    ("LeftUpLeg", "LHipJoint", (9.5, -6.0, 1.0), "l_hip"),
    ("LeftLeg", "LeftUpLeg", (0.0, -43.0, 0.0), "l_knee"),
    ("LeftFoot", "LeftLeg", (0.0, -41.0, 0.0), "l_ankle"),
    ("LeftToeBase", "LeftFoot", (0.0, -5.0, 13.5), "l_toe"),
]


_B31_LEFT_ARM: _Spec = [
    ("LeftShoulder", "Spine1", (3.5, 10.0, 0.0), "l_clavicle"),
    ("LeftArm", "LeftShoulder", (16.0, 0.0, 0.0), "l_shoulder"),
    ("LeftForeArm", "LeftArm", (27.0, 0.0, 0.0), "l_elbow"),
    ("LeftHand", "LeftForeArm", (24.0, 0.0, 0.0), "l_wrist"),
    ("LeftFingerBase", "LeftHand", (4.0, 0.0, 0.0), None),
    ("LeftHandIndex1", "LeftFingerBase", (4.0, 0.0, 0.0), None),
    ("LThumb", "LeftHand", (2.0, 0.0, 3.0), None),
]


_BIPED31: _Spec = [
    ("Hips", None, (0.0, 96.0, 0.0), "root"),
    *_B31_LEFT_LEG,
    *_mirror(_B31_LEFT_LEG, (("Left", "Right"), ("LHip", "RHip"))),
    ("LowerBack", "Hips", (0.0, 0.0, 0.0), None),
    ("Spine", "LowerBack", (0.0, 12.0, 0.0), "spine0"),
    ("Spine1", "Spine", (0.0, 12.0, 0.0), "spine1"),
    ("Neck", "Spine1", (0.0, 11.0, 0.0), "neck"),
    ("Neck1", "Neck", (0.0, 7.0, 0.0), None),
    ("Head", "Neck1", (0.0, 7.0, 0.0), "head"),
    *_B31_LEFT_ARM,
    *_mirror(_B31_LEFT_ARM, (("Left", "Right"), ("LThumb", "RThumb"))),
]


_B17_LEFT_LEG: _Spec = [
    ("LHip", "Hip", (12.0, 0.0, 0.0), "l_hip"),
    ("LKnee", "LHip", (0.0, -44.0, 0.0), "l_knee"),
    ("LFoot", "LKnee", (0.0, -44.0, 0.0), "l_ankle"),
]


_B17_LEFT_ARM: _Spec = [
    ("LShoulder", "Thorax", (16.0, 0.0, 0.0), "l_shoulder"),
    ("LElbow", "LShoulder", (27.0, 0.0, 0.0), "l_elbow"),
    ("LWrist", "LElbow", (25.0, 0.0, 0.0), "l_wrist"),
]


_BIPED17: _Spec = [
    ("Hip", None, (0.0, 87.0, 0.0), "root"),
    *_mirror(_B17_LEFT_LEG, (("L", "R"),)),
    *_B17_LEFT_LEG,
    ("Spine", "Hip", (0.0, 23.0, 0.0), "spine0"),
    ("Thorax", "Spine", (0.0, 25.0, 0.0), "spine2"),
    ("Neck", "Thorax", (0.0, 9.0, 0.0), "neck"),
    ("Head", "Neck", (0.0, 11.0, 0.0), "head"),
    *_B17_LEFT_ARM,
    *_mirror(_B17_LEFT_ARM, (("L", "R"),)),
]


_Q_LEFT_FRONT: _Spec = [
    ("LeftShoulder", "Spine1", (6.0, -4.0, 4.0), "lf_0"),
    ("LeftArm", "LeftShoulder", (0.0, -14.0, 0.0), "lf_1"),
    ("LeftForeArm", "LeftArm", (0.0, -15.0, 0.0), "lf_2"),
    ("LeftHand", "LeftForeArm", (0.0, -11.0, 3.0), "lf_3"),
]


_Q_LEFT_HIND: _Spec = [
    ("LeftUpLeg", "Hips", (6.0, -4.0, -4.0), "lh_0"),
    ("LeftLeg", "LeftUpLeg", (0.0, -17.0, 3.0), "lh_1"),
    ("LeftFoot", "LeftLeg", (0.0, -18.0, -5.0), "lh_2"),
]


_QUADRUPED: _Spec = [
    ("Hips", None, (0.0, 43.0, 0.0), "root"),
    ("Spine", "Hips", (0.0, 2.0, 18.0), "spine0"),
    ("Spine1", "Spine", (0.0, 0.0, 18.0), "spine1"),
    ("Neck", "Spine1", (0.0, 8.0, 8.0), "neck"),
    ("Head", "Neck", (0.0, 8.0, 8.0), "head"),
    *_Q_LEFT_FRONT,
    *_mirror(_Q_LEFT_FRONT),
    *_Q_LEFT_HIND,
    *_mirror(_Q_LEFT_HIND),
    ("Tail", "Hips", (0.0, 3.0, -10.0), "tail0"),
    ("Tail1", "Tail", (0.0, -3.0, -12.0), "tail1"),
]


_END_SITES = {
    "Head": (0.0, 12.0, 0.0),
    "LeftToe": (0.0, 0.0, 5.0),
    "RightToe": (0.0, 0.0, 5.0),
    "LeftHand": (8.0, 0.0, 0.0),
    "RightHand": (-8.0, 0.0, 0.0),
}


_SPECS: dict[str, _Spec] = {
    "biped22": _BIPED22,
    "biped31": _BIPED31,
    "biped17": _BIPED17,
    "quadruped": _QUADRUPED,
}


#: Skeleton kinds the generator knows.
KINDS: tuple[str, ...] = tuple(_SPECS)


def skeleton(kind: str, scale: float = 1.0) -> Skeleton:
    """The rest skeleton of a procedural kind (see :data:`KINDS`).

    Args:
        kind: ``"biped22"``, ``"biped31"``, ``"biped17"`` or ``"quadruped"``.
        scale: Multiplies every offset (body size variation).

    Raises:
        SkelagnosticError: For an unknown kind.
    """
    if kind not in _SPECS:
        raise SkelagnosticError(f"unknown procedural skeleton {kind!r}; known: {', '.join(KINDS)}")
    spec = _SPECS[kind]
    names = [s[0] for s in spec]
    index = {n: i for i, n in enumerate(names)}
    parents = [-1 if s[1] is None else index[s[1]] for s in spec]
    offsets = torch.tensor([s[2] for s in spec], dtype=torch.float64) * scale
    end_sites: dict[int, list[list[float]]] = {}
    for j, n in enumerate(names):
        if not any(p == j for p in parents):
            site = _END_SITES.get(n)
            if site is None:  # continue the last bone a little
                d = offsets[j] / offsets[j].norm().clamp_min(1e-9)
                site = tuple((d * 5.0 * scale).tolist())
            end_sites[j] = [[c * (scale if n in _END_SITES else 1.0) for c in site]]
    morphology = "quadruped" if kind == "quadruped" else "biped"
    return Skeleton(names, parents, offsets, end_sites=end_sites, name=kind, morphology=morphology)


def joint_roles(kind: str) -> dict[str, int]:
    """``role -> joint index`` of a procedural kind: the joints a gait animates.

    Joints without a role (fingers, zero-length helpers) keep their rest rotation.

    Args:
        kind: A procedural kind (see :data:`KINDS`).

    Raises:
        SkelagnosticError: For an unknown kind.

    Examples:
        >>> roles = joint_roles("quadruped")
        >>> roles["spine0"] < roles["neck"]
        True
    """
    if kind not in _SPECS:
        raise SkelagnosticError(f"unknown procedural skeleton {kind!r}; known: {', '.join(KINDS)}")
    return {s[3]: j for j, s in enumerate(_SPECS[kind]) if s[3] is not None}
