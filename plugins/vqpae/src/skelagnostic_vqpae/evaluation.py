"""VQ-PAE evaluations: the ``vqpae.manifold`` protocol and the functions behind it.

``skelagnostic evaluate model=vqpae ckpt_path=...`` (protocol ``vqpae.manifold``,
:func:`manifold_protocol`) embeds every held-out clip with the VQ-PAE of its
character and reports, per clip:

* ``shared_code_share``: the share of the clip's frames whose code is used by
  every character's held-out clips (the paper's Table 2 "embeddings on a shared
  component", per clip), beside ``chance``: the share a code drawn uniformly
  from the codebook would reach (shared codes / K);
* ``phase_r2``: the R^2 of a line through the unwrapped phase over time (a
  periodic motion advances its phase steadily), model only;
* ``pose_mpjpe_cm``: when the average-pose MLPs are trained, the error of the
  average pose decoded at each frame's manifold point (root-relative joint
  positions, cm), beside ``mean_pose``: the clip's own mean root-relative pose
  (:func:`skelagnostic.baselines.mean_pose`).

``extra`` holds codebook usage and overlap over the held-out characters
(:func:`code_overlap`, WalkTheDog Table 2); the plot ``manifold.png`` is the
phase manifold (Fig. 1) with the held-out frames.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from skelagnostic.baselines import mean_pose
from skelagnostic.core.motion import Motion
from skelagnostic.evaluation import MODEL, Evaluation, EvaluationError, HeldOut, clips_of_split
from skelagnostic.metrics.functional import manifold_overlap
from skelagnostic.representations import GlobalPositions
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip, plot_manifold
from skelagnostic_vqpae.transfer import FREQUENCY_TOLERANCE, HALFLIFE, build_database, transfer

__all__ = [
    "OWN_RATE",
    "TRANSFER_METRICS",
    "UNSCALED",
    "acceleration",
    "code_overlap",
    "foot_joints",
    "gait_frequency",
    "manifold_protocol",
    "phase_line",
    "transfer_protocol",
    "transfer_rows",
    "transition_note",
]


def phase_line(phase: torch.Tensor) -> tuple[float, float]:
    """``(R^2, slope in cycles per frame)`` of a least-squares line through the unwrapped phase.

    Args:
        phase: ``[F]`` phase in cycles.

    Example:
        >>> r2, slope = phase_line(torch.tensor([0.0, 0.25, -0.5, -0.25, 0.0]))
        >>> round(r2, 6), round(slope, 6)
        (1.0, 0.25)
    """
    unwrapped = np.unwrap(phase.double().numpy() * 2 * math.pi) / (2 * math.pi)
    t = np.arange(len(unwrapped), dtype=np.float64)
    slope, intercept = np.polyfit(t, unwrapped, 1)
    residual = unwrapped - (slope * t + intercept)
    return float(1 - residual.var() / max(unwrapped.var(), 1e-12)), float(slope)


def code_overlap(codes: Mapping[str, torch.Tensor], num_codes: int) -> dict[str, Any]:
    """Codebook usage and overlap (WalkTheDog Table 2) of per-character frame codes.

    Args:
        codes: ``character -> [F]`` code of every frame of its clips.
        num_codes: Codebook size.

    Returns:
        :func:`~skelagnostic.metrics.functional.manifold_overlap`'s ``usage``,
        ``overlap`` and ``per_dataset`` (in the order of ``codes``), plus
        ``characters`` and ``codes_used`` per character.
    """
    overlap = manifold_overlap(list(codes.values()), num_codes)
    return {
        **{k: (v.tolist() if torch.is_tensor(v) else v) for k, v in overlap.items()},
        "characters": list(codes),
        "codes_used": [int(c.unique().numel()) for c in codes.values()],
    }


def _pose_error(aligner: Any, clip: Any, emb: ClipEmbedding) -> dict[str, dict[str, float]]:
    """Root-relative MPJPE (cm) of the decoded average pose and of the mean-pose baseline."""
    from skelagnostic.aligners import Latent

    decoded = aligner.decode(Latent(emb.manifold, emb.fps), clip.skeleton)
    decoded.units = clip.units  # the pose MLP speaks the units of its training clips
    truth_motion, decoded = clip.to_metres(), decoded.to_metres()
    if truth_motion.fps != emb.fps:
        truth_motion = truth_motion.resample(emb.fps)
    frames = min(len(emb), truth_motion.num_frames)
    truth = truth_motion.global_positions()[:frames].double()
    truth = truth - truth[:, :1]
    pred = decoded.global_positions()[:frames].double()
    pred = pred - pred[:, :1]
    return {
        MODEL: {"pose_mpjpe_cm": 100 * float((pred - truth).norm(dim=-1).mean())},
        "mean_pose": {"pose_mpjpe_cm": 100 * float((mean_pose(truth) - truth).norm(dim=-1).mean())},
    }


def manifold_protocol(aligner: Any, held: HeldOut, out_dir: Path) -> Evaluation:
    """``vqpae.manifold``: shared codes, phase linearity and pose error of held-out clips."""
    num_codes = int(aligner.hparams.num_codes)
    embeddings = [embed_clip(aligner, clip) for clip in held.clips]
    by_character: dict[str, list[ClipEmbedding]] = {}
    for emb in embeddings:
        by_character.setdefault(emb.dataset, []).append(emb)
    codes = {n: torch.cat([e.code for e in embs]) for n, embs in by_character.items()}
    overlap = code_overlap(codes, num_codes)
    shared = set.intersection(*(set(c.tolist()) for c in codes.values()))
    specs = aligner.hparams["datasets"] or {}
    authors = [n for n in aligner.dataset_names if (specs.get(n) or {}).get("pose_features")]
    pose_ready = not authors and all(bool(c.pose_fitted) for c in aligner.characters)
    notes = [
        f"shared codes: {len(shared)} of {num_codes}, over the held-out clips of "
        f"{', '.join(by_character)}; chance = shared / K"
    ]
    if authors:
        notes.append(
            f"pose_mpjpe_cm omitted: the phase decoders of {', '.join(authors)} (an authors' "
            "run) predict their exporter's features, not joint positions"
        )
    elif not pose_ready:
        notes.append(
            "pose_mpjpe_cm omitted: the average-pose MLPs are not trained (model.pose_mlp=none)"
        )
    rows = []
    for clip, emb in zip(held.clips, embeddings, strict=True):
        share = float(np.isin(emb.code.numpy(), sorted(shared)).mean()) if len(emb) else 0.0
        values: dict[str, dict[str, float]] = {
            MODEL: {"shared_code_share": share, "phase_r2": phase_line(emb.phase)[0]},
            "chance": {"shared_code_share": len(shared) / num_codes},
        }
        if pose_ready:
            for method, figures in _pose_error(aligner, clip, emb).items():
                values.setdefault(method, {}).update(figures)
        rows.append(
            {"clip": str(clip.name), "character": emb.dataset, "frames": len(emb), "values": values}
        )
    plot_manifold(aligner, by_character, out=out_dir / "manifold.png")
    metrics = {
        "shared_code_share": "share of frames on codes every character uses, higher is better",
        "phase_r2": "R^2 of a line through the unwrapped phase, higher is better",
    }
    if pose_ready:
        metrics["pose_mpjpe_cm"] = (
            "root-relative MPJPE of the decoded average pose, cm, lower is better"
        )
    return Evaluation(
        metrics, rows, extra={"overlap": overlap}, plots=["manifold.png"], notes=notes
    )


# --- vqpae.transfer ---------------------------------------------------------------------------

#: Metrics of :func:`transfer_protocol`.
TRANSFER_METRICS = {
    "frequency_error_pct": "|output gait frequency - source gait frequency| / source, %, "
    "lower is better (both measured from the feet, independently of the model)",
    "output_hz": "gait frequency of the output, Hz (forward swings of the feet per second)",
    "accel_height_per_s2": "mean joint acceleration of the output over the skeleton height, "
    "1/s^2 (frame-to-frame smoothness), lower is smoother",
    "accel_max_height_per_s2": "largest per-frame joint acceleration over the skeleton height, "
    "1/s^2 (the worst jump, e.g. at a cut between replayed windows), lower is smoother",
}

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


def foot_joints(motion: Motion, max_height: float = 0.35) -> list[int]:
    """The end effectors that stay near the ground: the feet (or toes) of a character.

    Args:
        motion: A clip.
        max_height: Largest mean height over the ground, as a share of the skeleton height
            (a quadruped's height is that of its shoulders and hips, its head held level:
            the MANN dog's ankle joints move about 11 cm above the ground, 26 % of 43 cm).

    Returns:
        Joint indices: every end effector whose mean height above the root's ground
        projection is below ``max_height`` of the skeleton height, else the two lowest.
    """
    skeleton = motion.skeleton
    ends = skeleton.end_effectors()
    heights = GlobalPositions(frame="root").encode(motion)[:, ends, skeleton.up_index].mean(0)
    scale = max(skeleton.height(), 1e-9)
    feet = [j for j, h in zip(ends, heights.tolist(), strict=True) if h < max_height * scale]
    if feet:
        return feet
    return [ends[k] for k in heights.argsort()[:2].tolist()]


def gait_frequency(motion: Motion, hysteresis: float = 0.25) -> float:
    """Gait (stride) frequency in Hz, measured from the feet alone.

    Each foot (:func:`foot_joints`) swings forward once per stride: its horizontal
    position in the character's root frame
    (:class:`~skelagnostic.representations.GlobalPositions` ``frame="root"``),
    projected on its main (fore-aft) direction, crosses its mean upwards once per
    cycle. The crossings are found with hysteresis (the signal must go below
    ``-hysteresis`` and above ``+hysteresis`` standard deviations) and timed to a
    fraction of a frame; the frequency is the number of forward swings per
    second between each foot's first and last swing (summed over the feet):
    how many strides the motion makes, whatever replays or cuts it is made of.
    Nothing of any model is used.

    Args:
        motion: A clip of a few strides.
        hysteresis: Half-width of the dead band, in standard deviations.

    Returns:
        The frequency in Hz, or NaN when no foot completes two forward swings.

    Example:
        >>> from skelagnostic import procedural
        >>> clip, info = procedural.generate("quadruped", "trot", seconds=6.0, fps=60, seed=3)
        >>> abs(gait_frequency(clip) / info["frequency"] - 1) < 0.02
        True
    """
    feet = foot_joints(motion)
    up = motion.skeleton.up_index
    flat = [a for a in range(3) if a != up]
    positions = GlobalPositions(frame="root").encode(motion).double().numpy()
    strides, span = 0, 0.0
    for foot in feet:
        x = positions[:, foot, flat]
        x = x - x.mean(0, keepdims=True)
        _, _, axes = np.linalg.svd(x, full_matrices=False)
        signal = x @ axes[0]
        std = float(signal.std())
        if std <= 1e-9:
            continue
        crossings, armed = [], False
        for t in range(1, len(signal)):
            if signal[t] < -hysteresis * std:
                armed = True
            elif armed and signal[t - 1] < 0 <= signal[t]:
                crossings.append(t - 1 + signal[t - 1] / (signal[t - 1] - signal[t]))
                armed = False
        if len(crossings) >= 2:
            strides += len(crossings) - 1
            span += crossings[-1] - crossings[0]
    if strides == 0 or span <= 0:
        return math.nan
    return float(motion.fps * strides / span)


def acceleration(motion: Motion) -> tuple[float, float]:
    """Mean and largest per-frame joint acceleration over the skeleton height, 1/s^2.

    The second difference of the global joint positions, times ``fps^2``; its norm
    averaged over the joints of each frame, divided by the skeleton height; then the
    mean and the maximum over the frames (lower is smoother; a cut between replayed
    windows shows as a large maximum).

    Returns:
        ``(mean, max)``, NaN for clips shorter than 3 frames.
    """
    pos = motion.global_positions().double()
    if len(pos) < 3:
        return math.nan, math.nan
    per_frame = (pos[2:] - 2 * pos[1:-1] + pos[:-2]).norm(dim=-1).mean(-1) * motion.fps**2
    per_frame = per_frame / max(motion.skeleton.height(), 1e-9)
    return float(per_frame.mean()), float(per_frame.max())


def transfer_rows(
    aligner: Any,
    sources: Sequence[Motion],
    database: Sequence[Motion],
    replay_seconds: float = 1.0,
    halflife: float | None = HALFLIFE,
    frequency_tolerance: float | None = FREQUENCY_TOLERANCE,
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
        database: Clips of the target character (e.g. its training clips).
        replay_seconds: Replay length of the baseline.
        halflife: Inertialization halflife of the transitions, seconds; None: hard
            cuts (:func:`~skelagnostic_vqpae.transfer.transfer`).
        frequency_tolerance: Period rule
            (:func:`~skelagnostic_vqpae.transfer.matching_frequency`); None: the
            frequency head's estimates.

    Returns:
        ``(rows, outputs)``: rows for :class:`Evaluation` with :data:`TRANSFER_METRICS`
        (plus ``source_hz`` per row), and ``clip id -> [source, model output, baseline
        output, unscaled-matching output, own-rate output]``.
    """
    target = build_database(
        aligner, database, [str(m.name) for m in database], frequency_tolerance=frequency_tolerance
    )
    shortest = min(m.duration for m in target.motions)
    rows, outputs = [], {}
    for clip in sources:
        source_hz = gait_frequency(clip)
        options = {"halflife": halflife, "frequency_tolerance": frequency_tolerance}
        made = {
            MODEL: transfer(aligner, clip, target, **options).motion,
            UNSCALED: transfer(
                aligner, clip, target, scaled=False, replay_seconds=replay_seconds, **options
            ).motion,
            OWN_RATE: transfer(
                aligner,
                clip,
                target,
                scaled=False,
                replay_seconds=min(clip.duration, shortest),
                **options,
            ).motion,
        }
        values = {}
        for method, out in made.items():
            hz = gait_frequency(out)
            mean_acc, max_acc = acceleration(out)
            values[method] = {
                "frequency_error_pct": 100 * abs(hz - source_hz) / source_hz,
                "output_hz": hz,
                "accel_height_per_s2": mean_acc,
                "accel_max_height_per_s2": max_acc,
            }
        rows.append(
            {
                "clip": str(clip.name),
                "source_hz": source_hz,
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
    rows, outputs = transfer_rows(aligner, sources, database)
    first = next(iter(outputs.values()))
    from skelagnostic.viz import render_motion

    render_motion(first, out_dir / "transfer.gif", size=(200, 200))
    render_motion(first, out_dir / "transfer_sheet.png", size=(200, 200), sheet_frames=4)
    notes = [
        f"source: {len(sources)} held-out ({held.split}) clips of {names[0]!r}; database: "
        f"{len(database)} training clips of {names[1]!r}",
        f"baseline `{UNSCALED}`: classical motion matching with the same manifold query and "
        "database, 1 s replays, no period term and no time warping (the target plays at its "
        f"own rate, re-matched every second); `{OWN_RATE}`: one replay as long as the source "
        "(at most the shortest database clip), the best-matching target stretch at its own rate",
        "gait frequency: forward swings per second of the feet's root-local positions, the "
        "same measurement for the source and the outputs; no model output is used",
        transition_note(HALFLIFE, FREQUENCY_TOLERANCE),
    ]
    return Evaluation(
        TRANSFER_METRICS, rows, plots=["transfer.gif", "transfer_sheet.png"], notes=notes
    )
