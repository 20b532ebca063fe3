"""Joint-name heuristics: the words, side and role a joint name gives.

Names are split into lowercase words at case changes, digits and separators
(:func:`name_words`); the side is read from ``left``/``right`` words and ``L``/``R``
markers (:func:`name_side`); word lists for arms, legs, the spine and the tail give
each joint its body group (:func:`infer_body_groups`, which falls back on the rest
geometry for limbs whose name gives no side). The skeleton's template
(:mod:`skelagnostic.core.template`) finds elbows, knees, twist and toe joints with
:func:`is_middle_joint`, :func:`is_twist_joint` and :func:`is_toe_joint`;
:meth:`Skeleton.mirror_map <skelagnostic.core.skeleton.Skeleton.mirror_map>` pairs
joints with :func:`counterpart_names`; the name-copy baseline
(:mod:`skelagnostic.baselines.names`) keys joints with :func:`name_words` and
:func:`name_side`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np
import torch

__all__ = [
    "counterpart_names",
    "infer_body_groups",
    "is_effector_name",
    "is_middle_joint",
    "is_toe_joint",
    "is_twist_joint",
    "name_side",
    "name_words",
]

# Name tokens. Names are split into lowercase words at case changes, digits and
# separators ("LeftUpLeg" -> ["left", "up", "leg"], "l_hand" -> ["l", "hand"]).
_ARM = {
    "shoulder",
    "arm",
    "forearm",
    "elbow",
    "wrist",
    "hand",
    "finger",
    "fingers",
    "thumb",
    "index",
    "middle",
    "ring",
    "pinky",
    "collar",
    "clavicle",
    "scapula",
    "palm",
    "carpal",
}
_LEG = {
    "hip",
    "thigh",
    "upleg",
    "leg",
    "knee",
    "calf",
    "shin",
    "ankle",
    "foot",
    "toe",
    "toes",
    "heel",
    "ball",
    "tibia",
    "femur",
}
_SPINE = {
    "hips",
    "pelvis",
    "root",
    "spine",
    "chest",
    "neck",
    "head",
    "back",
    "torso",
    "abdomen",
    "jaw",
    "skull",
    "lowerback",
    "upperback",
    "waist",
    "body",
    "lowerneck",
    "upperneck",
}
_TAIL = {"tail"}
_EFFECTOR_WORDS = ("hand", "wrist", "foot", "ankle", "toe", "head")


def name_words(name: str) -> list[str]:
    """The lowercase words of a joint name, split at case changes, digits and separators.

    A capital run before a capitalised word is a word of its own; glued lowercase
    prefixes stay glued (``"lhand"``: :func:`name_side` reads those).

    Example:
        >>> name_words("LHipJoint"), name_words("l_hand"), name_words("Spine1")
        (['l', 'hip', 'joint'], ['l', 'hand'], ['spine', '1'])
    """
    parts = re.findall(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+", name)
    return [p.lower() for p in parts]


def name_side(name: str) -> int:
    """The side a joint name gives: +1 left, -1 right, 0 none.

    Read from a ``left``/``right`` word, a separate ``l``/``r`` word at either end
    (``arm_L``, ``l_hand``), a leading ``L``/``R`` before a capital (``LHipJoint``)
    or a glued lowercase prefix before a limb word (``lhumerus``, ``rfingers``).

    Example:
        >>> name_side("LeftUpLeg"), name_side("arm_R"), name_side("lfemur"), name_side("Spine")
        (1, -1, 1, 0)
    """
    words = name_words(name)
    if not words:
        return 0
    if "left" in words:
        return 1
    if "right" in words:
        return -1
    low = name.lower()
    if re.search(r"(^|[_.\-:\s])l($|[_.\-:\s])", low) or re.match(r"^l(?=[A-Z_])", name):
        return 1
    if re.search(r"(^|[_.\-:\s])r($|[_.\-:\s])", low) or re.match(r"^r(?=[A-Z_])", name):
        return -1
    # lowercase glued prefixes such as "lhand", "rfingers", "lshoulder"
    for prefix, side in (("l", 1), ("r", -1)):
        if low.startswith(prefix) and low[1:] and any(low[1:].startswith(w) for w in _ARM | _LEG):
            return side
    return 0


def _limb(name: str) -> str | None:
    """``"arm"``, ``"leg"``, ``"spine"`` or ``"tail"`` from a name's words, else ``None``."""
    words = set(name_words(name))
    low = name.lower()
    stripped = low[1:] if low[:1] in {"l", "r"} else low
    if words & _TAIL or "tail" in low:
        return "tail"
    if words & _SPINE and not (words & _ARM) and not (words & _LEG):
        return "spine"
    if words & _ARM or any(stripped.startswith(w) for w in _ARM):
        return "arm"
    if words & _LEG or any(stripped.startswith(w) for w in _LEG):
        return "leg"
    if words & _SPINE:
        return "spine"
    return None


_ELBOW_WORDS = frozenset({"forearm", "elbow", "lowerarm"})
_KNEE_WORDS = frozenset({"knee", "calf", "shin", "lowerleg", "tibia"})
_TWIST_WORDS = frozenset({"twist", "roll"})
_TOE_WORDS = frozenset({"toe", "toes", "ball"})


def is_middle_joint(name: str, limb: str) -> bool:
    """Whether a joint name denotes the elbow (``limb="arm"``) or the knee (``"leg"``).

    Example:
        >>> is_middle_joint("LeftForeArm", "arm"), is_middle_joint("LeftLeg", "leg")
        (True, True)
        >>> is_middle_joint("LeftUpLeg", "leg")
        False
    """
    w = name_words(name)
    if set(w) & (_ELBOW_WORDS if limb == "arm" else _KNEE_WORDS):
        return True
    if limb == "arm":
        return "arm" in w and bool({"fore", "lower"} & set(w))
    # "LeftLeg" (Mixamo, CMU, MANN) is the knee; "LeftUpLeg", "UpperLeg", "LegHip" are not
    return "leg" in w and not ({"up", "upper", "thigh", "hip", "top"} & set(w))


def is_twist_joint(name: str) -> bool:
    """Whether a joint name denotes a twist or roll helper joint (``LeftForeArmRoll``)."""
    return bool(_TWIST_WORDS & set(name_words(name)))


def is_toe_joint(name: str) -> bool:
    """Whether a joint name denotes a toe (``toe``, ``toes`` or ``ball`` words)."""
    return bool(_TOE_WORDS & set(name_words(name)))


def is_effector_name(name: str) -> bool:
    """Whether a joint name holds a hand, wrist, foot, ankle, toe or head word (any case).

    Example:
        >>> is_effector_name("LeftToeBase"), is_effector_name("LeftUpLeg")
        (True, False)
    """
    low = name.lower()
    return any(w in low for w in _EFFECTOR_WORDS)


def counterpart_names(name: str) -> set[str]:
    """The names the left/right counterpart of a joint could have (candidates to look up).

    Side markers are swapped: ``Left``/``Right`` (any case as written), a leading
    ``L``/``R`` (or ``l``/``r``), and ``_L``/``.L``/``-L`` suffixes or ``L_``-style
    prefixes. Every rule that applies gives a candidate, so some candidates are
    no joint's name (``"ReftArm"``); a caller keeps the ones its skeleton has.

    Example:
        >>> sorted(counterpart_names("LeftArm")), sorted(counterpart_names("arm_l"))
        (['ReftArm', 'RightArm'], ['arm_r'])
    """
    out = set()
    for a, b in (("Left", "Right"), ("left", "right"), ("LEFT", "RIGHT")):
        if a in name:
            out.add(name.replace(a, b))
        if b in name:
            out.add(name.replace(b, a))
    for a, b in (("L", "R"), ("l", "r")):
        if name.startswith(a):
            out.add(b + name[1:])
        if name.startswith(b):
            out.add(a + name[1:])
        for sep in ("_", ".", "-"):
            if name.endswith(sep + a):
                out.add(name[:-1] + b)
            if name.endswith(sep + b):
                out.add(name[:-1] + a)
            if name.startswith(a + sep):
                out.add(b + name[1:])
            if name.startswith(b + sep):
                out.add(a + name[1:])
    return out


def infer_body_groups(
    joint_names: Sequence[str],
    parents: Sequence[int],
    offsets: np.ndarray | torch.Tensor | None = None,
    lateral_axis: int = 0,
) -> list[str]:
    """Assign each joint a body group from its name, its parent and the rest geometry.

    Rules, in order: the root is ``spine``; a name with limb words (arm, hand,
    shoulder, leg, knee, foot, ...) and a side (``Left``, ``L_``, ``lhand``, ...)
    gives ``left_arm`` / ``right_arm`` / ``left_leg`` / ``right_leg``; ``tail``
    words give ``tail``; spine words (spine, chest, neck, head, ...) give
    ``spine``; a limb name without a side takes its parent's side, or, failing
    that, the sign of the rest offset along ``lateral_axis`` (+ is left);
    anything else inherits its parent's group.

    Args:
        joint_names: Joint names.
        parents: Parent indices (root -1, parents before children).
        offsets: ``[J, 3]`` rest offsets, used for the side of unnamed limbs.
        lateral_axis: Axis index whose positive direction is the character's left.

    Returns:
        One group name per joint, each in :data:`~skelagnostic.core.skeleton.BODY_GROUPS`.
    """
    num = len(joint_names)
    groups: list[str] = ["other"] * num
    pos = None
    if offsets is not None:
        off = np.asarray(offsets, dtype=np.float64)
        pos = np.zeros((num, 3))
        for j, p in enumerate(parents):
            pos[j] = off[j] if p < 0 else pos[p] + off[j]
        pos = pos - pos[0]
    for j, (name, p) in enumerate(zip(joint_names, parents, strict=True)):
        if p < 0:
            groups[j] = "spine"
            continue
        limb = _limb(name)
        parent_group = groups[p]
        if limb in {"arm", "leg"}:
            side = name_side(name)
            if side == 0 and parent_group.startswith(("left_", "right_")):
                side = 1 if parent_group.startswith("left_") else -1
            if side == 0 and pos is not None:
                lat = pos[j, lateral_axis]
                side = 1 if lat > 1e-9 else (-1 if lat < -1e-9 else 0)
            groups[j] = ("left_" if side > 0 else "right_") + limb if side else "other"
        elif limb == "tail":
            groups[j] = "tail"
        elif limb == "spine" and parent_group in {"spine", "other"}:
            groups[j] = "spine"
        else:
            groups[j] = parent_group
    return groups
