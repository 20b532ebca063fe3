"""``vqpae.manifold``: the shared phase manifold of held-out clips, per clip and per character.

``skelagnostic evaluate model=vqpae ckpt_path=...`` (:func:`manifold_protocol`)
embeds every held-out clip with the VQ-PAE of its character and reports, per clip:

* ``shared_code_share``: the share of the clip's frames whose code is used by
  every character's held-out clips (the paper's Table 2 "embeddings on a shared
  component", per clip), beside ``chance``: the share a code drawn uniformly
  from the codebook would reach (shared codes / K);
* ``phase_r2``: the R^2 of a line through the unwrapped phase over time (a
  periodic motion advances its phase steadily), model only;
* ``pose_mpjpe_cm``: when the average-pose MLPs are trained, the error of the
  average pose decoded at each frame's manifold point (joint positions relative to
  the root, in the character's facing frame, cm), beside ``mean_pose``: the clip's
  own mean pose in that frame (:func:`skelagnostic.baselines.mean_pose`);
  ``pose_mpjpe_locomotion_cm``: the same on its locomotion frames
  (:func:`skelagnostic.analysis.locomotion_frames`).

``extra`` holds the paper's Table 2 and Table 1 per character
(:mod:`~skelagnostic_vqpae.protocols.tables`), the codebook size K (``num_codes``),
codebook usage and overlap, the frequency head against the feet's touch-down rate
(:func:`~skelagnostic_vqpae.protocols.rhythm.frequency_head_figures`), per-character
means, and phase linearity and frequency error on held-out procedural gaits
(:func:`~skelagnostic_vqpae.protocols.procedural.procedural_gaits`); the plot
``manifold.png`` is the phase manifold (Fig. 1) with the held-out frames. The paper
measures Table 1 on the training data: ``evaluate split=train`` runs the protocol on
the run's training clips (the report says so), where ``extra.table1`` is that figure.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from skelagnostic.analysis import LOCOMOTION_SPAN, LOCOMOTION_SPEED
from skelagnostic.evaluation import MODEL, Evaluation, HeldOut, mean_rows, track
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip, plot_manifold
from skelagnostic_vqpae.protocols.procedural import procedural_gaits
from skelagnostic_vqpae.protocols.rhythm import (
    RHYTHM_RUN_SECONDS,
    RHYTHM_TOLERANCE,
    frequency_head_figures,
)
from skelagnostic_vqpae.protocols.tables import (
    ORACLE_PHASE_BINS,
    code_overlap,
    phase_line,
    phase_oracle_errors,
    pose_errors,
    table1,
    table2,
    training_codes,
)

__all__ = ["manifold_protocol"]

#: Metrics of :func:`manifold_protocol` when the average-pose MLPs are trained.
POSE_METRICS = {
    "pose_mpjpe_cm": "MPJPE of the decoded average pose in the root's facing frame, relative "
    "to the root joint, cm, lower is better",
    "pose_mpjpe_locomotion_cm": "the same on the clip's locomotion frames only (root speed >= "
    f"{LOCOMOTION_SPEED:g} skeleton heights/s), cm, lower is better",
}


def manifold_protocol(
    aligner: Any, held: HeldOut, out_dir: Path, procedural_seeds: int = 2
) -> Evaluation:
    """``vqpae.manifold``: Tables 1 and 2 per character, phase linearity, procedural gaits.

    Args:
        aligner: A trained :class:`~skelagnostic_vqpae.training.VqpaeModel`.
        held: The run's held-out clips.
        out_dir: Where ``manifold.png`` goes.
        procedural_seeds: Held-out procedural clips per gait and character
            (:func:`~skelagnostic_vqpae.protocols.procedural.procedural_gaits`; 0: none).

    Returns:
        Per-clip rows (``character``, ``frames``, ``locomotion_frames``; metrics
        ``shared_code_share``, ``phase_r2``, ``pose_mpjpe_cm``,
        ``pose_mpjpe_locomotion_cm``) and ``extra``: ``overlap``
        (:func:`~skelagnostic_vqpae.protocols.tables.code_overlap`), ``table2``,
        ``table1`` (:mod:`~skelagnostic_vqpae.protocols.tables`), ``per_character``
        (character -> method -> metric -> mean of its clips), ``locomotion_rule``,
        ``frequency_head`` and ``procedural``.
    """
    num_codes = int(aligner.hparams.num_codes)
    embeddings = [embed_clip(aligner, clip) for clip in track(held.clips, "held-out clips")]
    by_character: dict[str, list[ClipEmbedding]] = {}
    for emb in embeddings:
        by_character.setdefault(emb.dataset, []).append(emb)
    codes = {n: torch.cat([e.code for e in embs]) for n, embs in by_character.items()}
    trained = training_codes(aligner, held.datamodule) if held.datamodule is not None else None
    if not trained or not set(trained) >= set(codes):
        trained = None  # the data module's training split is not the characters' data
    table = table2(codes, trained)
    specs = aligner.hparams["datasets"] or {}
    authors = [n for n in aligner.dataset_names if (specs.get(n) or {}).get("pose_features")]
    pose_ready = not authors and all(bool(c.pose_fitted) for c in aligner.characters)
    notes = _notes(held, num_codes, list(by_character), table, trained is not None)
    if authors:
        notes.append(
            f"pose_mpjpe_cm omitted: the phase decoders of {', '.join(authors)} (an authors' "
            "run) predict their exporter's features, not joint positions"
        )
    elif not pose_ready:
        notes.append(
            "pose_mpjpe_cm omitted: the average-pose MLPs are not trained (model.pose_mlp=none)"
        )
    rows, errors = _clip_rows(aligner, held, embeddings, table["shared_codes"], pose_ready)
    plot_manifold(aligner, by_character, out=out_dir / "manifold.png")
    metrics = {
        "shared_code_share": "share of frames on codes every character uses, higher is better",
        "phase_r2": "R^2 of a line through the unwrapped phase, higher is better",
    }
    extra: dict[str, Any] = {
        "num_codes": num_codes,
        "overlap": code_overlap(codes, num_codes),
        "table2": table,
        "per_character": {
            name: mean_rows([r for r in rows if r["character"] == name]) for name in by_character
        },
    }
    if pose_ready:
        metrics.update(POSE_METRICS)
        extra["table1"] = table1(errors)
        extra["locomotion_rule"] = {
            "min_speed_heights_per_s": LOCOMOTION_SPEED,
            "span_seconds": LOCOMOTION_SPAN,
            "rule": "frames whose root travels at least min_speed_heights_per_s skeleton "
            "heights per second horizontally, over a centred span of span_seconds",
        }
        notes.append(
            "Table 1 phase_oracle: per clip, the mean pose of its locomotion frames in each "
            f"1/{ORACLE_PHASE_BINS} cycle of the gait phase measured from the feet "
            "(touch-down to touch-down); it reads the evaluated clips' truth (a reference, not "
            "a method): what the true phase adds to the clip's mean pose; it knows the phase "
            "but not the code, so it is no bound (a model can be below it)"
        )
    extra["frequency_head"] = frequency_head_figures(held.clips, embeddings)
    notes.append(
        "frequency_head: per character, the share of its locomotion clips (a run of at least "
        f"{RHYTHM_RUN_SECONDS:g} s of locomotion frames) whose frequency head (median over the "
        f"runs) lies within {100 * RHYTHM_TOLERANCE:g} % of the feet's touch-down rate (median, "
        "touch-downs per second and foot); procedural feet dip more than once per stride, so "
        "on procedural clips the touch-down rate is not the stride frequency"
    )
    extra["procedural"] = procedural_gaits(aligner, held, procedural_seeds)
    if extra["procedural"].get("note"):
        notes.append(extra["procedural"]["note"])
    return Evaluation(metrics, rows, extra=extra, plots=["manifold.png"], notes=notes)


def _notes(
    held: HeldOut, num_codes: int, characters: list[str], table: dict[str, Any], trained: bool
) -> list[str]:
    """The report's first notes: the evaluated clips, the Table 2 variants, the shared codes."""
    shared = table["shared_codes"]
    return [
        f"evaluated clips: the {held.name}; codebook size K = {num_codes} (extra.num_codes)",
        "codes_shared_training / frame_share_training (Table 2 over the training set, the "
        "paper's figure, as the authors' test_vq.py): "
        + (
            "codes_shared_training = codes every character uses on its training windows, "
            "frame_share_training = share of each character's training windows on them, "
            "frame_share_heldout_on_training_shared = share of the evaluated frames on them "
            "(frame_share_training_shared: the same, its former name)"
            if trained
            else "omitted, the evaluated data has no training split "
            "with a dataset of every character's name"
        ),
        f"shared codes: {len(shared)} of {num_codes}, over the evaluated clips of "
        f"{', '.join(characters)}; chance = shared / K; codes shared / codes used by any "
        f"character: {table['codes_shared']} / {table['codes_used_any']}",
    ]


def _clip_rows(
    aligner: Any,
    held: HeldOut,
    embeddings: list[ClipEmbedding],
    shared: list[int],
    pose_ready: bool,
) -> tuple[list[dict[str, Any]], dict[str, list[tuple[torch.Tensor, ...]]]]:
    """One row per held-out clip, and its per-frame pose errors per character (Table 1)."""
    num_codes = int(aligner.hparams.num_codes)
    rows = []
    errors: dict[str, list[tuple[torch.Tensor, ...]]] = {}
    for clip, emb in zip(held.clips, embeddings, strict=True):
        share = float(np.isin(emb.code.numpy(), shared).mean()) if len(emb) else 0.0
        values: dict[str, dict[str, float]] = {
            MODEL: {"shared_code_share": share, "phase_r2": phase_line(emb.phase)[0]},
            "chance": {"shared_code_share": len(shared) / num_codes},
        }
        row: dict[str, Any] = {"clip": str(clip.name), "character": emb.dataset, "frames": len(emb)}
        if pose_ready:
            model_err, base_err, loco, truth, phase = pose_errors(aligner, clip, emb)
            oracle = phase_oracle_errors(truth, phase, loco)
            errors.setdefault(emb.dataset, []).append((model_err, base_err, loco, oracle))
            row["locomotion_frames"] = int(loco.sum())
            for method, err in ((MODEL, model_err), ("mean_pose", base_err)):
                values.setdefault(method, {}).update(
                    {
                        "pose_mpjpe_cm": 100 * float(err.mean()),
                        "pose_mpjpe_locomotion_cm": (
                            100 * float(err[loco].mean()) if bool(loco.any()) else math.nan
                        ),
                    }
                )
        rows.append({**row, "values": values})
    return rows, errors
