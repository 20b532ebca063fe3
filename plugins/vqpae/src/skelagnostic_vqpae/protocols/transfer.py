"""``vqpae.transfer``: held-out clips of one character re-enacted by another, timed by the feet.

:func:`transfer_protocol` re-enacts held-out clips of the first character with the
second's training clips (:func:`transfer_rows`: the model's frequency-scaled motion
matching beside two classical-matching baselines) and times the outputs' feet
against the source's (:func:`skelagnostic.analysis.gait_frequency`,
:func:`skelagnostic.analysis.contact_frequency`,
:func:`~skelagnostic_vqpae.protocols.rhythm.rhythm_figures`); :func:`touchdown_bound`
shows what exact frequencies would give.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from skelagnostic.analysis import (
    acceleration,
    contact_frequency,
    gait_frequency,
    touchdown_frequency,
)
from skelagnostic.core.motion import Motion
from skelagnostic.evaluation import (
    MODEL,
    SKATE_THRESHOLD,
    Evaluation,
    EvaluationError,
    HeldOut,
    clips_of_split,
    mean_rows,
    own_foot_skate,
    track,
)
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip
from skelagnostic_vqpae.protocols.rhythm import rhythm_figures
from skelagnostic_vqpae.transfer import (
    FREQUENCY_TOLERANCE,
    HALFLIFE,
    TransferDatabase,
    build_database,
    replayed_codes,
    transfer,
    with_known_frequencies,
)

__all__ = [
    "OWN_RATE",
    "SOURCE",
    "TRANSFER_METRICS",
    "UNSCALED",
    "touchdown_bound",
    "transfer_protocol",
    "transfer_rows",
    "transition_note",
]


#: Metrics of :func:`transfer_protocol`.
TRANSFER_METRICS = {
    "frequency_error_pct": "|output gait frequency - source gait frequency| / source, %, "
    "lower is better (both measured from the feet, independently of the model)",
    "output_hz": "gait frequency of the output, Hz (forward swings of the feet per second)",
    "gait_ratio": "output gait frequency / source gait frequency (1: the source's tempo)",
    "contact_hz": "foot-contact frequency of the output, Hz (touch-downs per second and foot)",
    "contact_rhythm_error_pct": "|output contact frequency / source contact frequency - 1|, "
    "%, both touch-downs per second and foot (one per stride), lower is better (the issue's "
    "target: at most 10)",
    "contact_rhythm_within_10pct": "1 when contact_rhythm_error_pct <= 10, else 0; the mean "
    "is the share of clips meeting the target, higher is better",
    "locomotion_rhythm_error_pct": "the same as contact_rhythm_error_pct over the source's "
    "locomotion runs only (at least 3 s of root travel), where the source has a gait; %, "
    "lower is better (the issue's target: at most 10)",
    "locomotion_rhythm_within_10pct": "1 when locomotion_rhythm_error_pct <= 10, else 0; the "
    "mean is the share of clips meeting the target, higher is better",
    "contact_lock": "phase locking of the output's touch-downs to the source's stride cycle, "
    "0-1, higher is better",
    "accel_height_per_s2": "mean joint acceleration of the output over the skeleton height, "
    "1/s^2 (frame-to-frame smoothness), lower is smoother",
    "accel_max_height_per_s2": "largest per-frame joint acceleration over the skeleton height, "
    "1/s^2 (the worst jump, e.g. at a cut between replayed windows), lower is smoother",
    "foot_skate_cm_s": "mean horizontal speed of the output's feet on the frames where they "
    "are planted (contacts detected on the output itself: the target character has no ground "
    "truth), cm/s, lower is better",
    "foot_skate_ratio": f"share of those planted steps faster than {SKATE_THRESHOLD:g} skeleton "
    "heights/s, lower is better",
}

#: The reference row of :func:`transfer_rows`: the source clip's own foot skate (on its
#: own contacts), what the data itself has; not a method.
SOURCE = "source"


#: Baseline of :func:`transfer_rows`: classical motion matching (1 s replays, no time warping).
UNSCALED = "unscaled_matching"


def transition_note(halflife: float | None, frequency_tolerance: float | None) -> str:
    """How :func:`transfer_rows` splices and times its outputs, for reports."""
    splice = (
        f"every transition between replayed windows is inertialized (joint rotations and root, "
        f"halflife {halflife:g} s) in all three outputs"
        if halflife is not None
        else "replayed windows are spliced with hard cuts (no inertialization)"
    )
    periods = (
        "the frequency head's estimates"
        if frequency_tolerance is None
        else f"the frequency head's estimates, replaced by the measured phase rate where they "
        f"differ from it by more than {100 * frequency_tolerance:g} %"
    )
    return f"{splice}; matching periods: {periods}"


#: Baseline of :func:`transfer_rows`: the best-matching target stretch, played at its own rate.
OWN_RATE = "own_rate_clip"


def _source_embeddings(
    aligner: Any, sources: Sequence[Motion], embeddings: Sequence[ClipEmbedding] | None
) -> Sequence[ClipEmbedding]:
    """One embedding per source: ``embeddings`` (checked), else each source embedded here."""
    if embeddings is None:
        return [embed_clip(aligner, clip) for clip in sources]
    if len(embeddings) != len(sources):
        raise ValueError(
            f"embeddings: {len(embeddings)} given for {len(sources)} source clips (one per clip)"
        )
    return embeddings


def transfer_rows(
    aligner: Any,
    sources: Sequence[Motion],
    database: Sequence[Motion] | TransferDatabase,
    replay_seconds: float = 1.0,
    halflife: float | None = HALFLIFE,
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
    embeddings: Sequence[ClipEmbedding] | None = None,
    codes: dict[str, list[tuple[Tensor, float]]] | None = None,
) -> tuple[list[dict[str, Any]], dict[str, list[Motion]]]:
    """Transfer every source clip onto the database's character, model and baseline.

    Methods, all on the same manifold query and database
    (:func:`skelagnostic_vqpae.transfer.transfer`): :data:`MODEL` (frequency-scaled
    motion matching, the paper), :data:`UNSCALED` (classical motion matching with a
    fixed ``replay_seconds`` replay: the database plays at its own rate, re-matched
    every replay) and :data:`OWN_RATE` (classical matching with one replay as long as
    the source, or the shortest database clip: the best-matching stretch of a target
    clip played at its own rate, without cuts). All three splice their replays and
    time them the same way (:func:`transition_note`).

    Args:
        aligner: A trained aligner that knows both skeletons.
        sources: Clips of the source character (e.g. held-out human clips).
        database: Clips of the target character (e.g. its training clips), or their
            database already built with ``frequency_tolerance``
            (:func:`~skelagnostic_vqpae.transfer.build_database`).
        replay_seconds: Replay length of the baseline.
        halflife: Inertialization halflife of the transitions, seconds; None: hard
            cuts (:func:`~skelagnostic_vqpae.transfer.transfer`).
        frequency_tolerance: Period rule
            (:func:`~skelagnostic_vqpae.transfer.matching_frequency`); None: the
            frequency head's estimates.
        embeddings: The sources' embeddings (:func:`~skelagnostic_vqpae.embed.embed_clip`),
            one per source, if already computed; else each source is embedded here.
        codes: Optional, filled with ``clip id -> [(codes, fps)]`` in the order of the
            outputs: the source's per-frame codes, then per output those of the target
            frames it replays (:func:`~skelagnostic_vqpae.transfer.replayed_codes`).

    Returns:
        ``(rows, outputs)``: rows for :class:`Evaluation` with :data:`TRANSFER_METRICS`
        (plus ``source_hz`` per row), and ``clip id -> [source, model output, baseline
        output, unscaled-matching output, own-rate output]``.
    """
    target = (
        database
        if isinstance(database, TransferDatabase)
        else build_database(
            aligner,
            database,
            [str(m.name) for m in database],
            frequency_tolerance=frequency_tolerance,
        )
    )
    shortest = min(m.duration for m in target.motions)
    embeddings = _source_embeddings(aligner, sources, embeddings)
    rows, outputs = [], {}
    for i, clip in enumerate(track(sources, "transfer: held-out clips")):
        source_hz = gait_frequency(clip)
        options = {
            "halflife": halflife,
            "frequency_tolerance": frequency_tolerance,
            "embedding": embeddings[i],  # once for the three transfers
        }
        results = {
            MODEL: transfer(aligner, clip, target, **options),
            UNSCALED: transfer(
                aligner, clip, target, scaled=False, replay_seconds=replay_seconds, **options
            ),
            OWN_RATE: transfer(
                aligner,
                clip,
                target,
                scaled=False,
                replay_seconds=min(clip.duration, shortest),
                **options,
            ),
        }
        made = {method: result.motion for method, result in results.items()}
        if codes is not None:
            fps = embeddings[i].fps
            codes[str(clip.name)] = [(embeddings[i].code, fps)] + [
                (replayed_codes(result, target), fps) for result in results.values()
            ]
        values = {}
        for method, out in made.items():
            hz = gait_frequency(out)
            positions = out.global_positions()  # once for the smoothness and the skate
            mean_acc, max_acc = acceleration(out, positions)
            values[method] = {
                "frequency_error_pct": 100 * abs(hz - source_hz) / source_hz,
                "output_hz": hz,
                "gait_ratio": hz / source_hz,
                **rhythm_figures(clip, out),
                "accel_height_per_s2": mean_acc,
                "accel_max_height_per_s2": max_acc,
                **own_foot_skate(out, positions),
            }
        values[SOURCE] = own_foot_skate(clip)
        rows.append(
            {
                "clip": str(clip.name),
                "source_hz": source_hz,
                "source_contact_hz": contact_frequency(clip),
                "frames": clip.num_frames,
                "values": values,
            }
        )
        made[
            MODEL
        ].name = f"{aligner.dataset_names[aligner.dataset_of(made[MODEL].skeleton)]}: VQ-PAE"
        made[UNSCALED].name = "baseline: unscaled matching"
        made[OWN_RATE].name = "baseline: clip at own rate"
        outputs[str(clip.name)] = [clip, made[MODEL], made[UNSCALED], made[OWN_RATE]]
    return rows, outputs


def touchdown_bound(
    aligner: Any,
    sources: Sequence[Motion],
    target: TransferDatabase,
    halflife: float | None = HALFLIFE,
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
    embeddings: Sequence[ClipEmbedding] | None = None,
) -> dict[str, Any]:
    """The transfer with periods from the feet: what exact frequencies would give.

    The model's frequency-scaled matching (same manifold query, database, splicing
    and rule elsewhere), with the query's and every database clip's per-frame
    frequencies replaced by :func:`touchdown_frequency` wherever a foot's stride
    covers the frame. It uses the source's own feet, so it is a bound on what
    better frequency estimates can give the rhythm figures, not a method.

    Args:
        aligner: A trained aligner that knows both skeletons.
        sources: Clips of the source character.
        target: The target character's database, built with ``frequency_tolerance``
            (its embeddings are reused).
        halflife: Inertialization halflife of the transitions, seconds.
        frequency_tolerance: The period rule where no foot steps.
        embeddings: The sources' embeddings, one per source, if already computed; else
            each source is embedded here.

    Returns:
        ``per_clip`` (clip id -> :func:`rhythm_figures`), ``mean`` (of each figure
        over the clips, NaN skipped, as the rows' means) and ``replaced`` (share of
        the source's and the database's frames whose frequency came from the feet).
    """
    known = [touchdown_frequency(m) for m in target.motions]  # at the database's rate
    feet = with_known_frequencies(aligner, target, known, frequency_tolerance)
    fps = target.database.fps
    per_clip: dict[str, dict[str, float]] = {}
    source_frames = source_known = 0
    embeddings = _source_embeddings(aligner, sources, embeddings)
    for i, clip in enumerate(track(sources, "transfer: touch-down periods")):
        frequency = touchdown_frequency(clip if clip.fps == fps else clip.resample(fps))
        source_frames += frequency.numel()
        source_known += int(torch.isfinite(frequency).sum())
        out = transfer(
            aligner,
            clip,
            feet,
            halflife=halflife,
            frequency_tolerance=frequency_tolerance,
            frequency=frequency,
            embedding=embeddings[i],
        ).motion
        per_clip[str(clip.name)] = rhythm_figures(clip, out)
    mean = mean_rows([{"values": {"bound": f}} for f in per_clip.values()]).get("bound", {})
    db_frames = sum(f.numel() for f in known)
    return {
        "per_clip": per_clip,
        "mean": mean,
        "replaced": {
            "source": source_known / max(source_frames, 1),
            "database": sum(int(torch.isfinite(f).sum()) for f in known) / max(db_frames, 1),
        },
    }


def transfer_protocol(aligner: Any, held: HeldOut, out_dir: Path) -> Evaluation:
    """``vqpae.transfer``: held-out clips of the first character re-enacted by the second.

    The source clips are the held-out clips of the aligner's first dataset (the
    human of the procedural and ``human_dog`` data); the database is the second
    dataset's **training** clips. See :func:`transfer_rows` for the methods and
    :func:`gait_frequency` for the model-free frequency measurement.
    """
    names = list(aligner.dataset_names)
    if len(names) < 2:
        raise EvaluationError(
            f"vqpae.transfer needs two characters (datasets), the model has {names}"
        )
    sources = [c for c in held.clips if aligner.dataset_of(c.skeleton) == 0]
    if not sources:
        raise EvaluationError(f"vqpae.transfer: no held-out clip of {names[0]!r}")
    if held.datamodule is None:
        raise EvaluationError("vqpae.transfer: the held-out clips come without their data module")
    database = [
        c for c in clips_of_split(held.datamodule, "train") if aligner.dataset_of(c.skeleton) == 1
    ]
    if not database:
        raise EvaluationError(f"vqpae.transfer: no training clip of {names[1]!r} for the database")
    target = build_database(aligner, database, [str(m.name) for m in database])
    embeddings = [embed_clip(aligner, clip) for clip in sources]  # once for all four
    rows, outputs = transfer_rows(aligner, sources, target, embeddings=embeddings)
    bound = touchdown_bound(aligner, sources, target, embeddings=embeddings)

    def bounded(metric: str) -> float:
        return float(bound["mean"].get(metric, math.nan))

    first = next(iter(outputs.values()))
    from skelagnostic.viz import render_motion

    render_motion(first, out_dir / "transfer.gif", size=(200, 200))
    render_motion(first, out_dir / "transfer_sheet.png", size=(200, 200), sheet_frames=4)
    notes = [
        f"source: {len(sources)} clips of {names[0]!r} from the {held.name}; database: "
        f"{len(database)} training clips of {names[1]!r}",
        f"baseline `{UNSCALED}`: classical motion matching with the same manifold query and "
        "database, 1 s replays, no period term and no time warping (the target plays at its "
        f"own rate, re-matched every second); `{OWN_RATE}`: one replay as long as the source "
        "(at most the shortest database clip), the best-matching target stretch at its own rate",
        "gait frequency: forward swings per second of the feet's root-local positions, the "
        "same measurement for the source and the outputs; no model output is used",
        transition_note(HALFLIFE, FREQUENCY_TOLERANCE),
        "bound `extra.touchdown_periods` (not a method: it reads the source's feet): the "
        "model's matching with the query's and the database's frequencies taken from the "
        "feet's touch-downs wherever a foot steps, what exact frequency estimates would give "
        f"(locomotion rhythm error {bounded('locomotion_rhythm_error_pct'):.1f} %, whole "
        f"clips {bounded('contact_rhythm_error_pct'):.1f} %)",
        "foot skate: on the contacts detected on each output itself (the target character has "
        f"no ground truth); `{SOURCE}` is the source clip's own skate on its own contacts, a "
        "reference, not a method",
    ]
    return Evaluation(
        TRANSFER_METRICS,
        rows,
        extra={"touchdown_periods": bound},
        plots=["transfer.gif", "transfer_sheet.png"],
        notes=notes,
        outputs={clip: partial(_made, made[1]) for clip, made in outputs.items()},
    )


def _made(motion: Motion) -> Motion:
    """The motion already made (an :attr:`Evaluation.outputs` entry of a finished transfer)."""
    return motion
