"""Foot rhythm figures: a transfer's touch-downs against its source's, the frequency head's.

:func:`rhythm_figures` times a transfer's touch-downs against its source's;
:func:`frequency_head_figures` compares the frequency head with the feet's rate.

Both sides are measured from the feet alone (:mod:`skelagnostic.analysis`), so no
figure reads the model's own estimates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import torch

from skelagnostic.analysis import (
    LOCOMOTION_RUN_SECONDS,
    contact_lock,
    locomotion_runs,
    motion_onsets,
    onset_rate,
    rate_in_runs,
    touchdown_frequency,
)
from skelagnostic.core.motion import Motion
from skelagnostic_vqpae.embed import ClipEmbedding

__all__ = ["RHYTHM_RUN_SECONDS", "RHYTHM_TOLERANCE", "frequency_head_figures", "rhythm_figures"]


#: The issue's target for :data:`TRANSFER_METRICS` ``contact_rhythm_within_10pct``.
RHYTHM_TOLERANCE = 0.10


#: Shortest run of locomotion frames (s) over which :func:`rhythm_figures` compares the
#: rhythms (:func:`locomotion_runs`): a few strides.
RHYTHM_RUN_SECONDS = LOCOMOTION_RUN_SECONDS


def frequency_head_figures(
    clips: Sequence[Motion],
    embeddings: Sequence[ClipEmbedding],
    reference: Callable[[Motion], torch.Tensor] = touchdown_frequency,
    tolerance: float = RHYTHM_TOLERANCE,
) -> dict[str, Any]:
    """The frequency head against the feet: per character, the share of locomotion clips it reads.

    A clip is a locomotion clip when it has a run of locomotion frames
    (:func:`locomotion_runs`, at least :data:`RHYTHM_RUN_SECONDS`). Over the frames of
    its runs where ``reference`` has a value, the head's estimate is the median of the
    embedding's per-frame frequency and the feet's rate the median of ``reference``
    (default :func:`touchdown_frequency`: touch-downs per second and foot, one per
    stride on captured motion); the clip's error is ``|head / feet - 1|``. Procedural
    feet are not grounded (they dip more than once per stride), so on procedural
    clips the touch-down rate is not the stride frequency: the default suits
    captured motion.

    Args:
        clips: The evaluated clips.
        embeddings: Their embeddings (:func:`~skelagnostic_vqpae.embed.embed_clip`), one
            per clip.
        reference: Per-frame frequency (Hz, NaN where unknown) of a clip at the
            embedding's frame rate.
        tolerance: Largest relative error that counts as reading the rate.

    Returns:
        ``tolerance_pct``; ``characters``: character -> ``{"clips": locomotion clips
        with a figure, "within": those within the tolerance, "share_within": within /
        clips (NaN without clips), "without_touchdowns": locomotion clips where the
        reference has no value}``; ``per_clip``: clip -> ``{"character", "head_hz",
        "touchdown_hz", "error_pct", "within"}``.
    """
    if len(embeddings) != len(clips):
        raise ValueError(f"embeddings: {len(embeddings)} given for {len(clips)} clips")
    characters: dict[str, dict[str, Any]] = {}
    per_clip: dict[str, dict[str, Any]] = {}
    for clip, emb in zip(clips, embeddings, strict=True):
        motion = clip if clip.fps == emb.fps else clip.resample(emb.fps)
        runs = locomotion_runs(motion)
        if not runs:
            continue
        counts = characters.setdefault(
            emb.dataset, {"clips": 0, "within": 0, "without_touchdowns": 0}
        )
        frames = min(len(emb), motion.num_frames)
        mask = torch.zeros(frames, dtype=torch.bool)
        for start, end in runs:
            mask[start : min(end, frames)] = True
        feet = reference(motion)[:frames].double()
        mask &= feet.isfinite()
        if not bool(mask.any()):
            counts["without_touchdowns"] += 1
            continue
        head = float(emb.frequency[:frames].double()[mask].median())
        rate = float(feet[mask].median())
        error = abs(head / rate - 1)
        within = error <= tolerance
        counts["clips"] += 1
        counts["within"] += int(within)
        per_clip[str(clip.name)] = {
            "character": emb.dataset,
            "head_hz": head,
            "touchdown_hz": rate,
            "error_pct": 100 * error,
            "within": within,
        }
    for counts in characters.values():
        n = counts["clips"]
        counts["share_within"] = counts["within"] / n if n else math.nan
    return {"tolerance_pct": 100 * tolerance, "characters": characters, "per_clip": per_clip}


def rhythm_figures(source: Motion, output: Motion) -> dict[str, float]:
    """Foot-contact timing of a transfer's output against its source (same time axis).

    Both sides are measured by the same rule (:func:`motion_onsets`), so the source's
    gait frequency here is its contact frequency: touch-downs per second and foot,
    one per stride on either character.

    Args:
        source: The source clip.
        output: The transferred clip (played over the same time as ``source``).

    Returns:
        ``contact_hz`` (:func:`contact_frequency` of the output),
        ``contact_rhythm_error_pct`` (``|contact_hz / source contact_hz - 1|``, %),
        ``contact_rhythm_within_10pct`` (1.0 when that error is at most
        :data:`RHYTHM_TOLERANCE`, else 0.0; NaN when either side has no rhythm) and
        ``contact_lock`` (:func:`contact_lock` of the output's touch-downs in the
        source's cycle), and ``locomotion_rhythm_error_pct`` /
        ``locomotion_rhythm_within_10pct``: the same comparison over the source's
        :func:`locomotion_runs` only (touch-downs inside them per second and foot, on
        both sides, over the time both clips cover; NaN when the source has none),
        where the source has a gait to follow (a fall or a get-up lifts feet without
        one).
    """
    src_onsets, out_onsets = motion_onsets(source), motion_onsets(output)
    source_hz = onset_rate(src_onsets, source.fps)
    contact_hz = onset_rate(out_onsets, output.fps)
    error = abs(contact_hz / source_hz - 1) if source_hz > 0 else math.nan
    scale = output.fps / source.fps  # the output's frames on the source's time axis
    span = min(source.num_frames, output.num_frames / scale)  # the time both cover
    runs = [(a, min(b, span)) for a, b in locomotion_runs(source) if a < span]
    src_run = rate_in_runs(src_onsets, runs, source.fps)
    out_run = rate_in_runs(out_onsets, [(a * scale, b * scale) for a, b in runs], output.fps)
    run_error = abs(out_run / src_run - 1) if src_run > 0 else math.nan

    def within(e: float) -> float:
        return math.nan if math.isnan(e) else float(e <= RHYTHM_TOLERANCE)

    return {
        "contact_hz": contact_hz,
        "contact_rhythm_error_pct": 100 * error,
        "contact_rhythm_within_10pct": within(error),
        "contact_lock": contact_lock(src_onsets, [o / scale for o in out_onsets]),
        "locomotion_rhythm_error_pct": 100 * run_error,
        "locomotion_rhythm_within_10pct": within(run_error),
    }
