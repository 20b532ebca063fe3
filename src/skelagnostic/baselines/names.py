"""The name-copy retargeting baseline and its joint-name matching rule.

The rule (one for every evaluation):

1. A name is reduced to a *key* ``(side, core)`` by :func:`joint_key`: the part
   after the last namespace separator (``mixamorig:LeftArm`` -> ``LeftArm``) is
   split into words (``LeftUpLeg`` -> left, up, leg); the side is read as the
   skeleton's body groups read it (a ``left``/``right`` word, a separate
   ``l``/``r`` word at either end such as ``arm_L``, a leading capital
   ``L``/``R`` before a capital as in ``LHipJoint``, or a glued lower-case
   prefix before a limb word as in ``lhumerus``), and the side marker is removed;
   the remaining words, lower case and without punctuation, are the core.
2. The roots always match.
3. Any other target joint matches the source joint of the same side with the
   same core, else the one of the same side whose core is most similar
   (:class:`difflib.SequenceMatcher` ratio, at least ``cutoff``; ties go to the
   earlier source joint), else nothing (the baseline then leaves it at identity).

Several target joints may match one source joint.
"""

from __future__ import annotations

import difflib
import re

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.names import name_side, name_words
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import infer_units
from skelagnostic.errors import MotionError

__all__ = ["ROOT_RULES", "copied_motion", "joint_key", "name_copy", "name_match", "scaled_root"]

#: The root rules of the copy baselines: ``"scaled"`` (:func:`scaled_root`) or ``"source"``
#: (the source's root path unchanged, only converted to the target's units).
ROOT_RULES = ("scaled", "source")


def joint_key(name: str) -> tuple[int, str]:
    """``(side, core)`` of a joint name: +1 left, -1 right, 0 none; the core without the side.

    Examples:
        >>> joint_key("mixamorig:LeftUpLeg"), joint_key("UpLeg_L"), joint_key("lfemur")
        ((1, 'upleg'), (1, 'upleg'), (1, 'femur'))
        >>> joint_key("LHipJoint"), joint_key("RingFinger1")
        ((1, 'hipjoint'), (0, 'ringfinger1'))
    """
    base = re.split(r"[:|]", name)[-1]
    side = name_side(base)
    words = name_words(base)
    if side:
        marker = "left" if side > 0 else "right"
        letter = marker[0]
        if marker in words:
            words.remove(marker)
        elif words and words[0] == letter:
            words = words[1:]
        elif words and words[-1] == letter:
            words = words[:-1]
        elif words and words[0].startswith(letter):
            words[0] = words[0][1:]
    return side, re.sub(r"[^a-z0-9]", "", "".join(words))


def name_match(source: Skeleton, target: Skeleton, cutoff: float = 0.6) -> list[int | None]:
    """For each target joint, the source joint its name matches (see the module's rule).

    Args:
        source: Skeleton copied from.
        target: Skeleton copied to.
        cutoff: Least :class:`difflib.SequenceMatcher` ratio of a non-exact match.

    Returns:
        ``[target.num_joints]`` source indices, ``None`` where nothing matches.
    """
    src = [joint_key(n) for n in source.joint_names]
    out: list[int | None] = [0]
    for name in target.joint_names[1:]:
        side, core = joint_key(name)
        same_side = [i for i in range(1, len(src)) if src[i][0] == side]
        exact = next((i for i in same_side if src[i][1] == core), None)
        if exact is not None:
            out.append(exact)
            continue
        best, best_ratio = None, cutoff
        for i in same_side:
            ratio = difflib.SequenceMatcher(None, src[i][1], core).ratio()
            if ratio > best_ratio or (ratio == best_ratio and best is None):
                best, best_ratio = i, ratio
        out.append(best)
    return out


def name_copy(
    motion: Motion,
    target: Skeleton,
    source_units: str | None = None,
    target_units: str | None = None,
    cutoff: float = 0.6,
    root: str = "scaled",
) -> Motion:
    """Naive retargeting: copy local rotations by joint name, scale the root trajectory.

    Each target joint takes the local rotation of the source joint
    :func:`name_match` pairs it with (identity without a match). The root
    trajectory follows :func:`scaled_root` (height and displacement from the first
    frame scaled by the ratio of the skeletons' heights in metres, in the target's
    units), or with ``root="source"`` keeps the source's root path. Both rigs are
    assumed to share their rest-pose convention (identity rotations give the rest pose).

    Args:
        motion: Source motion.
        target: Target skeleton.
        source_units: Units of ``motion`` (default: ``motion.units``, else guessed from its
            height by :func:`skelagnostic.core.units.infer_units`).
        target_units: Units of ``target`` (default: guessed).
        cutoff: See :func:`name_match`.
        root: See :func:`copied_motion`.

    Returns:
        A motion on ``target`` at the source's fps, in the target's units.

    Raises:
        MotionError: ``root`` is not one of :data:`ROOT_RULES`.
    """
    rot = Q.identity(motion.num_frames, target.num_joints, dtype=motion.rotations.dtype)
    for j, i in enumerate(name_match(motion.skeleton, target, cutoff)):
        if i is not None:
            rot[:, j] = motion.rotations[:, i]
    return copied_motion(motion, target, rot, source_units, target_units, root)


def copied_motion(
    motion: Motion,
    target: Skeleton,
    local: torch.Tensor,
    source_units: str | None = None,
    target_units: str | None = None,
    root: str = "scaled",
) -> Motion:
    """The motion a copy baseline returns: ``local`` rotations on ``target`` and a root path.

    Args:
        motion: Source motion (its root path, fps and name are kept).
        target: Target skeleton.
        local: ``[T, J, 4]`` local rotations of ``target``.
        source_units: Units of ``motion`` (default: ``motion.units``, else guessed from its
            height by :func:`skelagnostic.core.units.infer_units`).
        target_units: Units of ``target`` (default: guessed).
        root: ``"scaled"`` (default): :func:`scaled_root`, the source's root height and
            displacement scaled by the height ratio; ``"source"``: the source's root
            path itself (the same positions in metres, expressed in the target's units),
            what a comparison with the source's own positions favours.

    Returns:
        A motion on ``target`` at the source's fps, in the target's units.

    Raises:
        MotionError: ``root`` is not one of :data:`ROOT_RULES`.
    """
    if root not in ROOT_RULES:
        raise MotionError(
            f"copy baseline: root={root!r} is not a root rule; expected one of {ROOT_RULES}"
        )
    src_unit = infer_units(motion.skeleton, source_units or motion.units)
    dst_unit = infer_units(target, target_units)
    if root == "scaled":
        path = scaled_root(motion, target, src_unit, dst_unit)
    else:
        path = (motion.root_positions * (UNITS[src_unit] / UNITS[dst_unit])).to(
            motion.rotations.dtype
        )
    return Motion(
        target,
        local,
        path,
        motion.fps,
        name=motion.name,
        units=dst_unit,
    )


def scaled_root(
    motion: Motion, target: Skeleton, source_units: str, target_units: str
) -> torch.Tensor:
    """The root rule of the copy baselines: ``motion``'s root path scaled, in ``target_units``.

    With ``ratio`` the target's height over the source's
    (:meth:`~skelagnostic.core.skeleton.Skeleton.height`, both in metres):

    * the root's height (its coordinate along the source's up axis, the ground
      being at 0) is multiplied by ``ratio``;
    * its horizontal displacement from the first frame is multiplied by ``ratio``,
      so the copy starts where the source starts (on the ground) and covers
      ``ratio`` times its distance.

    Args:
        motion: Source motion.
        target: Target skeleton.
        source_units: Units of ``motion``.
        target_units: Units of ``target``.

    Returns:
        ``[T, 3]`` root positions in ``target_units``, in ``motion``'s dtype.

    Example:
        >>> import torch, skelagnostic as sa
        >>> sk = sa.Skeleton(["hips", "head"], [-1, 0], [[0, 1, 0], [0, 1, 0]])
        >>> root = torch.tensor([[5.0, 1, 3], [6, 1, 3]])
        >>> m = sa.Motion(sk, torch.tensor([1.0, 0, 0, 0]).expand(2, 2, 4), root, fps=30)
        >>> scaled_root(m, sk.scaled(2.0), "m", "m").tolist()
        [[5.0, 2.0, 3.0], [7.0, 2.0, 3.0]]
    """
    src_m = motion.skeleton.height() * UNITS[source_units]
    dst_m = target.height() * UNITS[target_units]
    ratio = dst_m / max(src_m, 1e-9)
    root = motion.root_positions
    start = root[:1].clone()
    start[:, motion.skeleton.up_index] = 0.0
    return ((start + ratio * (root - start)) * (UNITS[source_units] / UNITS[target_units])).to(
        motion.rotations.dtype
    )
