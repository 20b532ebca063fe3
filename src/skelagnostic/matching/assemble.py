"""Assemble the output :class:`~skelagnostic.Motion` of a matching run from the source clips.

Each output frame is taken from the database clip and (fractional) frame that
:attr:`MatchResult.source_frames` names: local rotations are slerped, root
positions interpolated linearly. Every segment is re-anchored where the previous
one would have continued: its root trajectory is rotated about the up axis (by
the change of the root's heading) and translated on the ground so it starts at
the previous segment's continuation; heights stay as in the source. The
remaining jumps (pose, root velocity) are inertialized: rotations with the
offset as a rotation vector, ``exp(x(t)) * q(t)`` (Holden's quaternion
inertialization), root positions as vectors.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import torch

from skelagnostic.matching._errors import MatchingError
from skelagnostic.matching.database import MotionDatabase
from skelagnostic.matching.inertialization import inertialize, inertialize_rotations
from skelagnostic.matching.matching import MatchResult

if TYPE_CHECKING:
    from skelagnostic.core.motion import Motion


def assemble_motion(
    motions: Sequence[Motion],
    result: MatchResult,
    database: MotionDatabase,
    *,
    halflife: float | None = 0.1,
) -> Motion:
    """The output motion of a matching run, built from the database's source clips.

    Args:
        motions: One :class:`~skelagnostic.Motion` per database clip, in database
            order, with the clip's frame count, the database frame rate and one
            skeleton topology (the first motion's skeleton is used for the output).
        result: A :class:`MatchResult` of :func:`motion_matching` or
            :func:`frequency_scaled_motion_matching` on ``database``.
        database: The database the result was matched in.
        halflife: Inertialization halflife in seconds; None for hard cuts (the
            root trajectory is still re-anchored at every transition).

    Returns:
        A motion with one frame per output frame of ``result``.

    Raises:
        MatchingError: If the motions do not line up with the database clips, or
            the result carries no source frames.
    """
    from skelagnostic.core import quaternion as Q
    from skelagnostic.core.motion import Motion

    if len(motions) != database.num_clips:
        raise MatchingError(
            f"motions: got {len(motions)} motions for {database.num_clips} database clips"
        )
    skeleton = motions[0].skeleton
    for c, motion in enumerate(motions):
        start, stop = database.clip_range(c)
        if motion.num_frames != stop - start:
            raise MatchingError(
                f"motions[{c}]: has {motion.num_frames} frames, database clip {c} has "
                f"{stop - start}"
            )
        if abs(motion.fps - database.fps) > 1e-6:
            raise MatchingError(f"motions[{c}]: fps {motion.fps} != database fps {database.fps}")
        if not motion.skeleton.same_topology(skeleton):
            raise MatchingError(f"motions[{c}]: skeleton topology differs from motions[0]")
    if result.source_frames is None or not result.segments:
        raise MatchingError("result: carries no segments/source frames")
    if halflife is not None and not halflife > 0:
        raise MatchingError(f"halflife: must be > 0 seconds (or None), got {halflife}")

    up = skeleton.up_index
    forward = 2 if up != 2 else 1
    dtype = motions[0].rotations.dtype
    dt = 1.0 / database.fps

    def sample(clip: int, local: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = motions[clip]
        local = local.clamp(0, motion.num_frames - 1)
        i0 = local.floor().long()
        i1 = (i0 + 1).clamp(max=motion.num_frames - 1)
        alpha = (local - i0).to(dtype)
        rot = Q.slerp(motion.rotations[i0], motion.rotations[i1], alpha[:, None])
        root = torch.lerp(motion.root_positions[i0], motion.root_positions[i1], alpha[:, None])
        return rot, root

    rot_parts, root_parts, rot_conts, root_conts = [], [], [], []
    anchor_pos: torch.Tensor | None = None
    anchor_heading: torch.Tensor | None = None
    for seg in result.segments:
        offset = float(database.clip_starts[seg.clip])
        local = result.source_frames[seg.start : seg.start + seg.out_length] - offset
        step = seg.length / seg.out_length
        cont_local = seg.frame + seg.length + torch.tensor([0.0, step], dtype=torch.float64)
        rot, root = sample(seg.clip, torch.cat([local, cont_local]))
        if anchor_pos is not None and anchor_heading is not None:
            heading = Q.yaw(rot[0, 0], up=up, forward=forward)
            align = Q.mul(anchor_heading, Q.inv(heading))
            moved = Q.rotate(align.expand(root.shape[0], 4), root - root[0])
            moved = moved + anchor_pos
            moved[:, up] = root[:, up]
            root = moved
            rot = rot.clone()
            rot[:, 0] = Q.mul(align.expand(rot.shape[0], 4), rot[:, 0])
        # where this segment would continue: the next segment is anchored there
        anchor_pos = root[-2]
        anchor_heading = Q.yaw(rot[-2, 0], up=up, forward=forward)
        count = seg.out_length
        rot_parts.append(rot[:count])
        root_parts.append(root[:count])
        rot_conts.append(rot[count:])
        root_conts.append(root[count:])
    if halflife is None:
        rotations, roots = torch.cat(rot_parts), torch.cat(root_parts)
    else:
        rotations = inertialize_rotations(rot_parts, rot_conts, dt, halflife)
        roots = inertialize(root_parts, root_conts, dt, halflife)
    return Motion(skeleton, rotations, roots, database.fps, name="motion matching")
