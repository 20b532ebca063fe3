"""Motion transfer between characters through frequency-scaled motion matching (Sec. 4).

The target character's clips form a :class:`~skelagnostic.matching.MotionDatabase`
with per-frame groups ``manifold`` (the VQ-PAE embedding, ``[F, d]``),
``frequency`` (``[F, 1]``, Hz) and ``pose`` (root-local joint positions over the
skeleton height: the paper's "normalized joint positions" descriptor ``J``).
The source clip's embedding (manifold + frequency, from its own VQ-PAE) is the
query of :func:`~skelagnostic.matching.frequency_scaled_motion_matching` (Alg. 1,
Eq. 9; ``lambda1`` 0.5, ``lambda2`` 1). The replayed target windows, time-warped
to the source periods, are assembled into a motion of the target skeleton: local
rotations slerped at the (fractional) source frames, each segment's root path and
heading continued from the previous segment's end.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic.matching import (
    MatchResult,
    MotionDatabase,
    frequency_scaled_motion_matching,
    motion_matching,
)
from skelagnostic.representations import GlobalPositions
from skelagnostic_vqpae.aligner import VqpaeAligner
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip

__all__ = ["TransferDatabase", "TransferResult", "build_database", "transfer"]


@dataclass
class TransferDatabase:
    """A target character's clips ready for matching.

    Attributes:
        database: The matching database (groups ``manifold``, ``frequency``, ``pose``).
        motions: The clips at the database frame rate, in database order.
        embeddings: Their per-frame embeddings.
    """

    database: MotionDatabase
    motions: list[Motion]
    embeddings: list[ClipEmbedding]


@dataclass
class TransferResult:
    """A transferred motion and how it was made.

    Attributes:
        motion: The motion on the target skeleton, at the source clip's duration.
        match: The matching result (segments, source frames).
        source: The source clip's embedding.
    """

    motion: Motion
    match: MatchResult
    source: ClipEmbedding


def build_database(aligner: VqpaeAligner, motions: Sequence[Motion],
                   names: Sequence[str] | None = None) -> TransferDatabase:
    """Embed the target character's clips and build the matching database.

    Args:
        aligner: A trained aligner that knows the clips' skeleton.
        motions: Clips of one character (topology), any frame rate.
        names: Optional clip names.

    Returns:
        The database.

    Raises:
        SkelagnosticError: No clip, or clips of different topologies.
    """
    if not motions:
        raise SkelagnosticError("build_database: motions is empty")
    datasets = {aligner.dataset_of(m.skeleton) for m in motions}
    if len(datasets) != 1:
        raise SkelagnosticError("build_database: the clips belong to different characters")
    embeddings = [embed_clip(aligner, m) for m in motions]
    fps = embeddings[0].fps
    resampled = [m if m.fps == fps else m.resample(fps) for m in motions]
    clips = []
    for m, e in zip(resampled, embeddings, strict=True):
        pose = GlobalPositions(frame="root").encode(m).float().flatten(1) / m.skeleton.height()
        clips.append({"manifold": e.manifold.float(), "frequency": e.frequency.float()[:, None],
                      "pose": pose})
    db = MotionDatabase.from_clips(clips, fps=fps, clip_names=names)
    return TransferDatabase(db, resampled, embeddings)


def transfer(
    aligner: VqpaeAligner,
    source: Motion,
    target: TransferDatabase,
    lambda1: float = 0.5,
    lambda2: float = 1.0,
    max_period_ratio: float | None = None,
    scaled: bool = True,
    replay_seconds: float = 1.0,
) -> TransferResult:
    """Transfer ``source`` onto the target character by frequency-scaled motion matching.

    With ``scaled=False`` the same query and database go through classical motion
    matching instead (:func:`~skelagnostic.matching.motion_matching`: fixed replay
    length ``replay_seconds``, no period term, no time warping), so the target
    clips play at their own rate: the baseline of the ``vqpae.transfer`` evaluation.

    Args:
        aligner: A trained aligner that knows both skeletons.
        source: The clip to transfer (e.g. a human walk).
        target: The target character's database (:func:`build_database`).
        lambda1: Weight of the start-pose term (0.5).
        lambda2: Weight of the period term (1).
        max_period_ratio: Optional cap on the period ratio (the authors' code: 2).
        scaled: Frequency-scaled matching (the paper); False: classical matching.
        replay_seconds: Replay length of classical matching (``scaled=False`` only).

    Returns:
        The transferred motion (target skeleton, database frame rate).

    Raises:
        SkelagnosticError: The source embedding's frame rate differs from the database's,
            or ``replay_seconds`` is not positive.
    """
    emb = embed_clip(aligner, source)
    if emb.fps != target.database.fps:
        raise SkelagnosticError(
            f"transfer: source embedded at {emb.fps} fps, database at {target.database.fps} fps"
        )
    query = {"manifold": emb.manifold.float(), "frequency": emb.frequency.float()[:, None]}
    if not scaled:
        if not replay_seconds > 0:
            raise SkelagnosticError(f"transfer: replay_seconds must be > 0, got {replay_seconds}")
        replay = max(1, round(replay_seconds * target.database.fps))
        match = motion_matching(target.database, query, replay, control="manifold", pose="pose",
                                lambda_pose=lambda1, output=["pose"])
        return TransferResult(_assemble(match, target), match, emb)
    match = frequency_scaled_motion_matching(
        target.database, query, control="manifold", pose="pose", frequency="frequency",
        lambda1=lambda1, lambda2=lambda2, max_period_ratio=max_period_ratio, output=["pose"])
    return TransferResult(_assemble(match, target), match, emb)


def _sample(motion: Motion, frames: Tensor) -> tuple[Tensor, Tensor]:
    """Local rotations ``[n, J, 4]`` and root positions ``[n, 3]`` at fractional frames."""
    i0 = frames.floor().long().clamp(0, motion.num_frames - 1)
    i1 = (i0 + 1).clamp(max=motion.num_frames - 1)
    w = (frames - i0.double()).to(motion.rotations.dtype)
    rot = Q.slerp(motion.rotations[i0], motion.rotations[i1], w[:, None])
    root = torch.lerp(motion.root_positions[i0], motion.root_positions[i1], w[:, None])
    return rot, root


def _assemble(match: MatchResult, target: TransferDatabase) -> Motion:
    if match.source_frames is None:
        raise SkelagnosticError("transfer: the matching result has no source frames")
    db = target.database
    skeleton = target.motions[0].skeleton
    up = skeleton.up_index
    forward = 2 if up != 2 else 1
    rotations, roots = [], []
    heading: Tensor | None = None
    ground_next: Tensor | None = None
    for seg in match.segments:
        start = int(db.clip_range(seg.clip)[0])
        frames = match.source_frames[seg.start: seg.start + seg.out_length] - start
        rot, root = _sample(target.motions[seg.clip], frames)
        seg_yaw = Q.yaw(rot[:1, 0], up=up, forward=forward)[0]
        ground = root.clone()
        ground[:, up] = 0.0
        if heading is None or ground_next is None:
            turn = Q.identity(dtype=rot.dtype)
            offset = torch.zeros(3, dtype=rot.dtype)
        else:
            turn = Q.mul(heading, Q.inv(seg_yaw))
            offset = ground_next
        rot = rot.clone()
        rot[:, 0] = Q.mul(turn.expand_as(rot[:, 0]), rot[:, 0])
        moved = Q.rotate(turn.expand(len(ground), 4), ground - ground[:1]) + offset
        moved[:, up] = root[:, up]
        rotations.append(rot)
        roots.append(moved)
        heading = Q.yaw(rot[-1:, 0], up=up, forward=forward)[0]
        step = moved[-1] - moved[-2] if len(moved) > 1 else torch.zeros_like(moved[-1])
        ground_next = moved[-1] + step
        ground_next[up] = 0.0
    return Motion(skeleton, torch.cat(rotations), torch.cat(roots), db.fps)
