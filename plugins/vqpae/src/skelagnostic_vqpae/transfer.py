"""Motion transfer between characters through frequency-scaled motion matching (Sec. 4).

The target character's clips form a :class:`~skelagnostic.matching.MotionDatabase`
with per-frame groups ``manifold`` (the VQ-PAE embedding, ``[F, d]``),
``frequency`` (``[F, 1]``, Hz) and ``pose`` (root-local joint positions over the
skeleton height: the paper's "normalized joint positions" descriptor ``J``).
The source clip's embedding (manifold + frequency, from its own VQ-PAE) is the
query of :func:`~skelagnostic.matching.frequency_scaled_motion_matching` (Alg. 1,
Eq. 9; ``lambda1`` 0.5, ``lambda2`` 1). The replayed target windows, time-warped
to the source periods, are assembled into a motion of the target skeleton by
:func:`~skelagnostic.matching.assemble_motion`: local rotations slerped at the
(fractional) source frames, each segment's root path and heading continued from
where the previous segment would have gone, and every transition inertialized
(joint rotations and root position, critically damped offsets of halflife
:data:`HALFLIFE`), as the paper does at each transition.

Periods for matching come from the frequency head, except where it disagrees with
the phase the same embedding measures: :func:`matching_frequency` replaces the
head's estimate by the measured phase rate (the unwrapped pivot-phase advance
over the VQ-PAE window centred on the frame) where the two differ by more than
:data:`FREQUENCY_TOLERANCE` of the measured rate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic.matching import (
    MatchResult,
    MotionDatabase,
    assemble_motion,
    frequency_scaled_motion_matching,
    motion_matching,
)
from skelagnostic.representations import GlobalPositions
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip
from skelagnostic_vqpae.training import VqpaeModel

__all__ = [
    "FREQUENCY_TOLERANCE",
    "HALFLIFE",
    "TransferDatabase",
    "TransferResult",
    "build_database",
    "matching_frequency",
    "phase_rate",
    "replayed_codes",
    "transfer",
    "with_known_frequencies",
]

#: Inertialization halflife of the transitions, seconds. The paper inertializes every
#: transition without giving a value and the authors' offline matching script has no
#: blending; 0.1 s is the default of Holden's motion-matching code (Bollo's spring) and
#: of :func:`~skelagnostic.matching.frequency_scaled_motion_matching`.
HALFLIFE = 0.1

#: Largest relative difference ``|f_head - f_phase| / f_phase`` between the frequency
#: head and the measured phase rate for which the head's estimate is kept.
FREQUENCY_TOLERANCE = 0.05


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


def phase_rate(phase: Tensor, fps: float, window: int) -> Tensor:
    """Measured phase rate per frame, Hz: the pivot phase's advance over a window.

    The per-frame differences of ``phase`` are wrapped to ``[-1/2, 1/2)`` cycles and
    summed (the unwrapped phase), and the advance over the ``window`` frames centred
    on each frame (cut at the clip's ends) is divided by the window's duration. The
    wrapping is unambiguous while the phase advances less than half a cycle per
    frame (below ``fps / 2`` Hz).

    Args:
        phase: ``[F]`` pivot phase of every frame, in cycles.
        fps: Frame rate.
        window: Frames of the measuring window (the VQ-PAE's window; >= 2).

    Returns:
        ``[F]`` float64 rates in Hz (0 for a single frame).

    Example:
        >>> phase = torch.remainder(torch.arange(12) * 0.3 + 0.5, 1.0) - 0.5  # 6 Hz at 20 fps
        >>> [round(r, 6) for r in phase_rate(phase, 20.0, 5)[[0, 6]].tolist()]
        [6.0, 6.0]
    """
    if window < 2:
        raise SkelagnosticError(f"phase_rate: window must be >= 2 frames, got {window}")
    phase = phase.double().reshape(-1)
    frames = phase.numel()
    if frames < 2:
        return torch.zeros(frames, dtype=torch.float64)
    step = phase.diff()
    step = step - torch.round(step)
    unwrapped = torch.cat([phase.new_zeros(1), step.cumsum(0)])
    index = torch.arange(frames)
    lo = (index - window // 2).clamp(min=0)
    hi = (lo + window - 1).clamp(max=frames - 1)
    lo = (hi - (window - 1)).clamp(min=0)
    return (unwrapped[hi] - unwrapped[lo]) * fps / (hi - lo).double()


def matching_frequency(
    embedding: ClipEmbedding, window: int, tolerance: float | None = FREQUENCY_TOLERANCE
) -> tuple[Tensor, Tensor]:
    """Per-frame frequencies for the matching periods: the head's, or the measured phase rate.

    Rule: with ``f_head`` the frequency head's estimate and ``f_phase`` the
    :func:`phase_rate` over the VQ-PAE window, a frame uses ``f_phase`` where
    ``f_phase > 0`` and ``|f_head - f_phase| > tolerance * f_phase``, else ``f_head``.
    The phase is what the manifold query and database are made of, so where the
    head contradicts it, periods cut from the head would not span one cycle of the
    matched features; a phase that stands still or runs backwards (no cycle to
    measure, e.g. idling) keeps the head's estimate.

    Args:
        embedding: A clip's embedding.
        window: Frames of the measuring window (the VQ-PAE's window).
        tolerance: Relative tolerance (> 0); None keeps the head's estimate everywhere
            (the paper's periods).

    Returns:
        ``(frequency [F] float32 Hz, replaced [F] bool)``: the frequencies and where
        the measured rate replaced the head's estimate.

    Raises:
        SkelagnosticError: A non-positive tolerance or a window shorter than 2 frames.
    """
    head = embedding.frequency.float()
    if tolerance is None:
        return head, torch.zeros(head.shape, dtype=torch.bool)
    if not tolerance > 0:
        raise SkelagnosticError(f"frequency_tolerance: must be > 0 (or None), got {tolerance}")
    measured = phase_rate(embedding.phase, embedding.fps, window)
    replaced = (measured > 0) & ((head.double() - measured).abs() > tolerance * measured)
    return torch.where(replaced, measured.float(), head), replaced


def _known(rule: Tensor, known: Tensor | None, field: str) -> Tensor:
    """``rule`` with the finite frames of ``known`` (Hz, same length) put in."""
    if known is None:
        return rule
    known = torch.as_tensor(known, dtype=rule.dtype).reshape(-1)
    if known.numel() != rule.numel():
        raise SkelagnosticError(
            f"{field}: {known.numel()} frames, the clip's embedding has {rule.numel()} "
            "(give one value per frame at the model's frame rate)"
        )
    if bool((known <= 0).any() | torch.isinf(known).any()):
        raise SkelagnosticError(f"{field}: frequencies must be positive and finite (NaN: unknown)")
    return torch.where(torch.isnan(known), rule, known)


def _window(aligner: VqpaeModel, motion: Motion) -> int:
    """Frames of the VQ-PAE window of ``motion``'s character."""
    return int(aligner.characters[aligner.dataset_of(motion.skeleton)].pae.window)


def build_database(
    aligner: VqpaeModel,
    motions: Sequence[Motion],
    names: Sequence[str] | None = None,
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
    frequencies: Sequence[Tensor | None] | None = None,
) -> TransferDatabase:
    """Embed the target character's clips and build the matching database.

    The ``frequency`` group holds :func:`matching_frequency` (the head's estimate,
    or the measured phase rate where they disagree by more than
    ``frequency_tolerance``), or the frequencies given in ``frequencies``.

    Args:
        aligner: A trained aligner that knows the clips' skeleton.
        motions: Clips of one character (topology), any frame rate.
        names: Optional clip names.
        frequency_tolerance: See :func:`matching_frequency`; None: the head's
            estimates as they are.
        frequencies: Optional known frequencies per clip (Hz, one value per frame
            at the model's frame rate, e.g. from contact annotations; None for a
            clip, or NaN for a frame, keeps the rule's value there).

    Returns:
        The database.

    Raises:
        SkelagnosticError: No clip, clips of different topologies, or ``frequencies``
            whose count or lengths do not match the clips.
    """
    if not motions:
        raise SkelagnosticError("build_database: motions is empty")
    datasets = {aligner.dataset_of(m.skeleton) for m in motions}
    if len(datasets) != 1:
        raise SkelagnosticError("build_database: the clips belong to different characters")
    embeddings = [embed_clip(aligner, m) for m in motions]
    fps = embeddings[0].fps
    resampled = [m if m.fps == fps else m.resample(fps) for m in motions]
    return _assemble(aligner, resampled, embeddings, names, frequency_tolerance, frequencies)


def with_known_frequencies(
    aligner: VqpaeModel,
    target: TransferDatabase,
    frequencies: Sequence[Tensor | None],
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
) -> TransferDatabase:
    """``target`` again with known frequencies, without embedding its clips again.

    The same database as :func:`build_database` with ``frequencies`` would give for
    ``target``'s clips (one ``[F]`` Hz tensor or None per clip, at the database's
    frame rate; NaN keeps the rule's value).

    Raises:
        SkelagnosticError: ``frequencies`` whose count or lengths do not match the clips.
    """
    return _assemble(
        aligner,
        target.motions,
        target.embeddings,
        target.database.clip_names,
        frequency_tolerance,
        frequencies,
    )


def _assemble(
    aligner: VqpaeModel,
    motions: Sequence[Motion],
    embeddings: Sequence[ClipEmbedding],
    names: Sequence[str] | None,
    frequency_tolerance: float | None,
    frequencies: Sequence[Tensor | None] | None,
) -> TransferDatabase:
    """The database of embedded clips (``motions`` at the embeddings' frame rate)."""
    if frequencies is not None and len(frequencies) != len(motions):
        raise SkelagnosticError(
            f"build_database: {len(frequencies)} frequency tracks for {len(motions)} clips"
        )
    window = _window(aligner, motions[0])
    known = frequencies if frequencies is not None else [None] * len(motions)
    clips = []
    for i, (m, e) in enumerate(zip(motions, embeddings, strict=True)):
        pose = GlobalPositions(frame="root").encode(m).float().flatten(1) / m.skeleton.height()
        frequency, _ = matching_frequency(e, window, frequency_tolerance)
        frequency = _known(frequency, known[i], f"build_database: frequencies[{i}]")
        clips.append(
            {"manifold": e.manifold.float(), "frequency": frequency[:, None], "pose": pose}
        )
    db = MotionDatabase.from_clips(clips, fps=embeddings[0].fps, clip_names=names)
    return TransferDatabase(db, list(motions), list(embeddings))


def transfer(
    aligner: VqpaeModel,
    source: Motion,
    target: TransferDatabase,
    lambda1: float = 0.5,
    lambda2: float = 1.0,
    max_period_ratio: float | None = None,
    scaled: bool = True,
    replay_seconds: float = 1.0,
    halflife: float | None = HALFLIFE,
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
    frequency: Tensor | None = None,
    embedding: ClipEmbedding | None = None,
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
        halflife: Inertialization halflife of the transitions, seconds (joint
            rotations and root position); None splices the replayed frames with
            hard cuts (the root path is still continued).
        frequency_tolerance: Rule of the source's periods (:func:`matching_frequency`);
            None: the frequency head's estimates (the paper). The database's
            periods follow the rule it was built with (:func:`build_database`).
        frequency: Optional known frequencies of the source (Hz, one per frame at
            the model's frame rate; NaN keeps the rule's value), as
            :func:`build_database`'s ``frequencies``.
        embedding: ``source``'s embedding if it is already computed
            (:func:`~skelagnostic_vqpae.embed.embed_clip` of the same aligner and clip),
            to transfer one clip several ways without embedding it each time.

    Returns:
        The transferred motion (target skeleton, database frame rate).

    Raises:
        SkelagnosticError: The source embedding's frame rate differs from the database's,
            ``embedding`` belongs to another character than ``source``, or
            ``replay_seconds``, ``halflife`` or ``frequency_tolerance`` is not positive.
    """
    if embedding is None:
        emb = embed_clip(aligner, source)
    else:
        own = aligner.dataset_names[aligner.dataset_of(source.skeleton)]
        if embedding.dataset != own:
            raise SkelagnosticError(
                f"transfer: embedding is of character {embedding.dataset!r}, the source "
                f"clip of {own!r}"
            )
        emb = embedding
    if emb.fps != target.database.fps:
        raise SkelagnosticError(
            f"transfer: source embedded at {emb.fps} fps, database at {target.database.fps} fps"
        )
    if halflife is not None and not halflife > 0:
        raise SkelagnosticError(f"transfer: halflife must be > 0 seconds (or None), got {halflife}")
    rule, _ = matching_frequency(emb, _window(aligner, source), frequency_tolerance)
    frequency = _known(rule, frequency, "transfer: frequency")
    query = {"manifold": emb.manifold.float(), "frequency": frequency[:, None]}
    if not scaled:
        if not replay_seconds > 0:
            raise SkelagnosticError(f"transfer: replay_seconds must be > 0, got {replay_seconds}")
        replay = max(1, round(replay_seconds * target.database.fps))
        match = motion_matching(
            target.database,
            query,
            replay,
            control="manifold",
            pose="pose",
            lambda_pose=lambda1,
            output=["pose"],
            halflife=halflife,
        )
    else:
        match = frequency_scaled_motion_matching(
            target.database,
            query,
            control="manifold",
            pose="pose",
            frequency="frequency",
            lambda1=lambda1,
            lambda2=lambda2,
            max_period_ratio=max_period_ratio,
            output=["pose"],
            halflife=halflife,
        )
    motion = assemble_motion(target.motions, match, target.database, halflife=halflife)
    return TransferResult(motion, match, emb)


def replayed_codes(result: TransferResult, target: TransferDatabase) -> Tensor:
    """Per frame of a transfer's match, the code of the target frame it replays.

    Each matched segment's database frames are stretched (nearest frame) over its
    output frames, so the result has the match's frame rate (the source embedding's).

    Args:
        result: A :func:`transfer` result.
        target: The database it was matched against.

    Returns:
        ``[F]`` codebook indices, ``F`` the match's output frames.
    """
    segments = result.match.segments
    frames = max((s.start + s.out_length for s in segments), default=0)
    codes = torch.zeros(frames, dtype=torch.long)
    for s in segments:
        clip = target.embeddings[s.clip].code
        step = torch.arange(s.out_length) * s.length // max(s.out_length, 1)
        codes[s.start : s.start + s.out_length] = clip[(s.frame + step).clamp(max=len(clip) - 1)]
    return codes


def transfer_clips(
    aligner: VqpaeModel, motion: Motion, targets: Sequence[Motion]
) -> tuple[Motion, list[int]]:
    """The work of :meth:`VqpaeAligner.transfer <skelagnostic_vqpae.aligner.VqpaeAligner.transfer>`.

    The targets become a database (:func:`build_database`) that :func:`transfer`
    queries with ``motion``.

    Returns:
        ``(motion on the targets' skeleton, frames where a new matched window starts)``.
    """
    result = transfer(aligner, motion, build_database(aligner, list(targets)))
    return result.motion, [seg.start for seg in result.match.segments[1:]]
