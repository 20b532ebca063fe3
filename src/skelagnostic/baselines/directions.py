"""A retargeting baseline that copies bone directions, independent of rest-pose conventions.

The rotation copies (:func:`~skelagnostic.baselines.name_copy`,
:func:`~skelagnostic.baselines.primal_copy`) are only meaningful when both rigs
share their rest-pose convention: the same local rotation bends a T-posed arm
and an A-posed arm differently. This baseline copies what a rig-independent
observer sees instead, the direction of every bone in world axes:

1. :func:`direction_match`: the chains of the two primal skeletons are paired
   by :func:`~skelagnostic.baselines.primal_match`. A chain runs from its primal
   parent down to its primal joint; it is parametrised by its *rest arc length*
   (the sum of its rest bone lengths, scaled to [0, 1]). A target bone covering
   ``[a, b]`` of its chain is paired with the source chain's points at ``a`` and
   ``b`` (linear along the source bone that contains them).
2. :func:`direction_copy`: every paired target bone points, frame by frame,
   from the source's point at ``a`` to its point at ``b`` (so a target bone that
   spans two source bones takes their chord). The target's global rotations are
   solved from these directions by
   :func:`~skelagnostic.core.kinematics.global_rotations_from_directions`: the
   shortest-arc rotation for joints with one child, the best rotation of all
   child bones (Kabsch) for joints with several; bones without a partner keep
   their parent's rotation. The root path follows
   :func:`~skelagnostic.baselines.names.scaled_root` (or, with ``root="source"``,
   is the source's own root path).

Only global joint positions of the source are read and only the target's rest
offsets are used to solve, so the result does not depend on either rig's
rest-pose convention; on the source's own skeleton it reproduces the source's
global positions. Twist about a bone is not copied (directions do not carry it).
"""

from __future__ import annotations

import torch

from skelagnostic.baselines.names import copied_motion
from skelagnostic.baselines.primal import primal_match, primal_skeleton
from skelagnostic.core.kinematics import global_rotations_from_directions, local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton

__all__ = ["ChainPoint", "direction_copy", "direction_match"]

#: A point on a source chain: ``(joint a, joint b, w)`` is ``(1 - w) p_a + w p_b`` of the
#: global positions ``p`` (``a`` is ``b``'s parent, or ``a == b`` with ``w == 0``).
ChainPoint = tuple[int, int, float]

_EPS = 1e-9


def _chain_fractions(skeleton: Skeleton, chain: list[int]) -> tuple[list[int], list[float]]:
    """The chain's joints from its primal parent down and their rest arc length in [0, 1].

    The fractions are all 0 when the chain has no length.
    """
    joints = [skeleton.parents[chain[0]], *chain]
    lengths = skeleton.bone_lengths()
    arc = [0.0]
    for j in chain:
        arc.append(arc[-1] + float(lengths[j]))
    total = arc[-1]
    return joints, [a / total if total > _EPS else 0.0 for a in arc]


def _point(joints: list[int], fractions: list[float], s: float, start: bool) -> ChainPoint:
    """The point at arc-length fraction ``s`` of a chain with some length.

    At a joint the point is read on the bone below it for a ``start`` point, above it
    for an end point (the same position, but a bone copied onto itself keeps its ends).
    """
    segments = [i for i in range(len(joints) - 1) if fractions[i + 1] > fractions[i]]
    i = next(
        (i for i in segments if s < fractions[i + 1] or (not start and s == fractions[i + 1])),
        segments[-1],
    )
    w = (s - fractions[i]) / (fractions[i + 1] - fractions[i])
    return joints[i], joints[i + 1], min(max(w, 0.0), 1.0)


def direction_match(source: Skeleton, target: Skeleton) -> dict[int, tuple[ChainPoint, ChainPoint]]:
    """For each target bone, the two source chain points its direction is read between.

    Args:
        source: Skeleton copied from.
        target: Skeleton copied to.

    Returns:
        ``target joint c -> (start, end)``: the bone from ``c``'s parent to ``c``
        points from the source point ``start`` to ``end`` (see :data:`ChainPoint`).
        Bones of zero rest length, bones of unmatched chains and bones of chains
        paired with a source chain of zero length are absent.

    Example:
        >>> from skelagnostic import procedural
        >>> sk = procedural.skeleton("biped22")
        >>> match = direction_match(sk, sk)
        >>> all(match[c] == ((sk.parents[c], c, 0.0), (sk.parents[c], c, 1.0)) for c in match)
        True
    """
    src_chains, dst_chains = primal_skeleton(source), primal_skeleton(target)
    lengths = target.bone_lengths()
    out: dict[int, tuple[ChainPoint, ChainPoint]] = {}
    for t, s in primal_match(source, target).items():
        if t == 0:
            continue
        src_joints, src_frac = _chain_fractions(source, src_chains[s])
        dst_joints, dst_frac = _chain_fractions(target, dst_chains[t])
        if src_frac[-1] == 0.0 or dst_frac[-1] == 0.0:
            continue
        for k, c in enumerate(dst_joints[1:]):
            if float(lengths[c]) > _EPS:
                out[c] = (
                    _point(src_joints, src_frac, dst_frac[k], start=True),
                    _point(src_joints, src_frac, dst_frac[k + 1], start=False),
                )
    return out


def _at(positions: torch.Tensor, point: ChainPoint) -> torch.Tensor:
    a, b, w = point
    return torch.lerp(positions[..., a, :], positions[..., b, :], w)


def direction_copy(
    motion: Motion,
    target: Skeleton,
    source_units: str | None = None,
    target_units: str | None = None,
    root: str = "scaled",
) -> Motion:
    """Retarget by pointing every target bone along its paired source chain (module rule).

    Args:
        motion: Source motion.
        target: Target skeleton.
        source_units: Units of ``motion`` (default: ``motion.units``, else guessed).
        target_units: Units of ``target`` (default: guessed).
        root: ``"scaled"`` (:func:`~skelagnostic.baselines.scaled_root`, default) or
            ``"source"`` (the source's root path unscaled); see
            :func:`~skelagnostic.baselines.names.copied_motion`.

    Returns:
        A motion on ``target`` at the source's fps, in the target's units.

    Raises:
        MotionError: ``root`` is not ``"scaled"`` or ``"source"``.

    Example:
        >>> from skelagnostic import procedural
        >>> m = procedural.generate("biped22", "walk", seconds=0.5)[0]
        >>> out = direction_copy(m, procedural.skeleton("biped17"), "cm", "cm")
        >>> out.num_frames == m.num_frames, out.skeleton.num_joints
        (True, 17)
    """
    positions = motion.global_positions()
    directions = positions.new_zeros(motion.num_frames, target.num_joints, 3)
    known = [False] * target.num_joints
    for c, (start, end) in direction_match(motion.skeleton, target).items():
        directions[:, c] = _at(positions, end) - _at(positions, start)
        known[c] = True
    glob = global_rotations_from_directions(directions, target.offsets, target.parents, known)
    local = local_from_global(glob, target.parents)
    return copied_motion(motion, target, local, source_units, target_units, root)
