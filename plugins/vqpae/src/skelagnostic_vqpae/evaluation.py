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
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from skelagnostic.baselines import mean_pose
from skelagnostic.evaluation import MODEL, Evaluation, HeldOut
from skelagnostic.metrics.functional import manifold_overlap
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip, plot_manifold

__all__ = ["code_overlap", "manifold_protocol", "phase_line"]


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
    pose_ready = all(bool(c.pose_fitted) for c in aligner.characters)
    notes = [
        f"shared codes: {len(shared)} of {num_codes}, over the held-out clips of "
        f"{', '.join(by_character)}; chance = shared / K"
    ]
    if not pose_ready:
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
