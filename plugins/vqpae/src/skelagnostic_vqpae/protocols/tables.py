"""The paper's Tables 1 and 2 (WalkTheDog): average-pose error and shared codes, per character.

:func:`table2` counts the frames on codes every character uses (over the held-out
clips and, as the paper does, over the training windows: :func:`training_codes`);
:func:`table1` compares the average pose decoded at each frame's manifold point
(:func:`pose_errors`) with the clip's own mean pose and with
:func:`phase_oracle_errors`, the average pose of the true gait phase. Phase linearity
(:func:`phase_line`) and codebook overlap (:func:`code_overlap`) complete the
``vqpae.manifold`` protocol (:mod:`skelagnostic_vqpae.protocols.manifold`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from skelagnostic.analysis import gait_phase, locomotion_frames
from skelagnostic.baselines import mean_pose
from skelagnostic.evaluation import MODEL, track
from skelagnostic.metrics.functional import manifold_overlap
from skelagnostic.representations import GlobalPositions
from skelagnostic_vqpae.embed import ClipEmbedding

__all__ = [
    "ORACLE_PHASE_BINS",
    "code_overlap",
    "phase_line",
    "phase_oracle_errors",
    "pose_errors",
    "table1",
    "table2",
    "training_codes",
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


def pose_errors(aligner: Any, clip: Any, emb: ClipEmbedding) -> tuple[torch.Tensor, ...]:
    """Per-frame joint error (m) of the decoded average pose and of the clip's mean pose.

    Both poses are compared in the character's root frame (positions relative to the
    root joint, turned into the facing frame: the frame the average-pose MLP predicts),
    so the error does not count where the character walks or which way it faces.

    Returns:
        ``(model [F], mean_pose [F], locomotion [F] bool, truth [F, J, 3] (m),
        gait phase [F] (:func:`gait_phase`, NaN where undefined))`` on the frames
        both cover.
    """
    from skelagnostic.aligners import Latent

    decoded = aligner.decode(Latent(emb.manifold, emb.fps), clip.skeleton)
    decoded.units = clip.units  # the pose MLP speaks the units of its training clips
    truth_motion, decoded = clip.to_metres(), decoded.to_metres()
    if truth_motion.fps != emb.fps:
        truth_motion = truth_motion.resample(emb.fps)
    frames = min(len(emb), truth_motion.num_frames)
    local = GlobalPositions(frame="root")
    truth = local.encode(truth_motion)[:frames].double()
    truth = truth - truth[:, :1]
    pred = local.encode(decoded)[:frames].double()
    pred = pred - pred[:, :1]
    return (
        (pred - truth).norm(dim=-1).mean(-1),
        (mean_pose(truth) - truth).norm(dim=-1).mean(-1),
        locomotion_frames(truth_motion)[:frames],
        truth,
        torch.from_numpy(gait_phase(truth_motion)[:frames]),
    )


#: Phase bins of :func:`phase_oracle_errors` (1/16 cycle: finer bins change its error by
#: under 1 % on the LaFAN1 and MANN dog clips, docs/reports/vqpae.md section 23).
ORACLE_PHASE_BINS = 16


def phase_oracle_errors(
    pose: torch.Tensor, phase: torch.Tensor, mask: torch.Tensor, bins: int = ORACLE_PHASE_BINS
) -> torch.Tensor:
    """Per-frame error (m) of the best average pose of a clip's true gait phase.

    Table 1 decodes one average pose per manifold point and compares it with the
    clip's own mean pose. A perfect phase manifold would read the stride's phase
    (:func:`gait_phase`) exactly; the pose that best stands for the frames at one
    phase of the clip is then their mean. This oracle takes that mean over the
    evaluated frames themselves (held-out truth a model never sees), one per phase bin
    of the clip: it knows what the mean-pose baseline knows (the clip) plus the true
    phase, so it shows how far knowing the phase alone can bring an average pose. It
    does not know the code (the amplitude: which motion the frame belongs to), which
    the model's average pose also reads, so it is a reference, not a bound: a model
    can be below it.

    Args:
        pose: ``[F, J, 3]`` joint positions (root frame, root at the origin).
        phase: ``[F]`` gait phase in cycles (NaN where undefined).
        mask: ``[F]`` bool, the frames evaluated (e.g. locomotion).
        bins: Phase bins per cycle.

    Returns:
        ``[F]`` mean joint distance to the average pose of the frame's bin; NaN on
        frames outside the mask or without a phase.

    Example:
        >>> pose = torch.tensor([[[0.0, 0, 0]], [[2.0, 0, 0]], [[1.0, 0, 0]]]).double()
        >>> phase = torch.tensor([0.1, 0.15, 0.7]).double()
        >>> phase_oracle_errors(pose, phase, torch.ones(3, dtype=torch.bool), bins=2)
        tensor([1., 1., 0.], dtype=torch.float64)
    """
    ok = mask & phase.isfinite()
    key = torch.floor(phase.nan_to_num(0.0) * bins).long().clamp(0, bins - 1)
    err = torch.full((pose.shape[0],), math.nan, dtype=pose.dtype)
    for k in key[ok].unique().tolist():
        sel = ok & (key == k)
        err[sel] = (pose[sel] - pose[sel].mean(0)).norm(dim=-1).mean(-1)
    return err


def training_codes(aligner: Any, datamodule: Any) -> dict[str, torch.Tensor]:
    """Code of every training window of every character (no shuffling, no gradient).

    Args:
        aligner: A trained :class:`~skelagnostic_vqpae.training.VqpaeModel`.
        datamodule: Its set-up :class:`~skelagnostic_vqpae.data.VqpaeDataModule`.

    Returns:
        ``character -> [N]`` codes, one per training window; datasets the aligner
        has no VQ-PAE for (another run's data) are left out.
    """
    out: dict[str, torch.Tensor] = {}
    with torch.no_grad():
        for name, loader in datamodule.loaders("train", shuffle=False).items():
            if name not in aligner.dataset_names:
                continue
            k = aligner.dataset_names.index(name)
            codes = [
                aligner.encode_dataset(k, b["features"].to(aligner.device)).code.cpu()
                for b in track(loader, f"{name}: codes of the training windows")
            ]
            if codes:
                out[name] = torch.cat(codes)
    return out


def table2(
    codes: Mapping[str, torch.Tensor], training: Mapping[str, torch.Tensor] | None = None
) -> dict[str, Any]:
    """WalkTheDog Table 2 per character, from the code of every frame of its clips.

    Args:
        codes: ``character -> [F]`` code of every frame of its (held-out) clips.
        training: Optional ``character -> [N]`` codes of its training windows. The
            paper's Table 2 calls a component (code) shared when both datasets' embeddings
            lie on it, and counts the embeddings of the dataset (the training set, as
            the authors' ``test_vq.py``); with this argument the codes every character
            uses on its training windows are that set, ``frame_share_training`` is the
            paper's figure and ``frame_share_heldout_on_training_shared`` the share of
            the held-out frames on the same codes.

    Returns:
        ``characters``; ``codes_used`` (character -> number of distinct codes its
        frames use); ``codes_shared``: codes used by every character, and
        ``shared_codes``: their ids, ascending;
        ``codes_used_any``: codes used by any character; ``shared_of_used``:
        ``codes_shared / codes_used_any`` (the issue's "codes used that are shared",
        target >= 0.75); ``shared_of_own`` (character -> ``codes_shared`` / its
        ``codes_used``); ``frame_share`` (character -> share of its frames on a
        shared code; it grows with the number of evaluated clips, since more clips
        share more codes); ``frames`` per character. With ``training``:
        ``codes_shared_training`` (codes every character uses on its training
        windows) and ``shared_codes_training`` (their ids), ``frame_share_training``
        (character -> share of its training windows on one of those: the paper's
        Table 2) and ``frames_training``, ``frame_share_heldout_on_training_shared``
        (character -> share of its evaluated frames on one of those: the shared codes
        are fixed by the training set, so the figure does not grow with the number of
        evaluated clips) and ``frame_share_training_shared``, the same figure under
        the name of the entries committed before it was added.

    Example:
        >>> out = table2({"human": torch.tensor([0, 0, 1, 2]), "dog": torch.tensor([1, 1, 3])})
        >>> out["codes_shared"], out["shared_of_used"], out["frame_share"]
        (1, 0.25, {'human': 0.25, 'dog': 0.6666666666666666})
    """
    used = {name: set(c.tolist()) for name, c in codes.items()}
    shared = set.intersection(*used.values()) if used else set()
    union = set.union(*used.values()) if used else set()
    out: dict[str, Any] = {
        "characters": list(codes),
        "codes_used": {name: len(u) for name, u in used.items()},
        "codes_shared": len(shared),
        "shared_codes": sorted(shared),
        "codes_used_any": len(union),
        "shared_of_used": len(shared) / len(union) if union else math.nan,
        "shared_of_own": {
            name: len(shared) / len(u) if u else math.nan for name, u in used.items()
        },
        "frame_share": {
            name: float(np.isin(c.numpy(), sorted(shared)).mean()) if len(c) else math.nan
            for name, c in codes.items()
        },
        "frames": {name: len(c) for name, c in codes.items()},
    }
    if training is not None:
        trained = sorted(set.intersection(*(set(c.tolist()) for c in training.values())))

        def on_trained(c: torch.Tensor) -> float:
            return float(np.isin(c.numpy(), trained).mean()) if len(c) else math.nan

        held_share = {name: on_trained(c) for name, c in codes.items()}
        out.update(
            {
                "codes_shared_training": len(trained),
                "shared_codes_training": trained,
                "frame_share_training": {name: on_trained(c) for name, c in training.items()},
                "frames_training": {name: len(c) for name, c in training.items()},
                "frame_share_heldout_on_training_shared": held_share,
                "frame_share_training_shared": dict(held_share),
            }
        )
    return out


def table1(errors: Mapping[str, Sequence[tuple[torch.Tensor, ...]]]) -> dict[str, Any]:
    """WalkTheDog Table 1 per character: per-frame average-pose error, cm, beside the mean pose.

    Args:
        errors: ``character -> [(model [F], mean_pose [F], locomotion [F])]`` per clip,
            per-frame errors in metres (:func:`pose_errors`); an optional fourth
            tensor ``oracle [F]`` holds :func:`phase_oracle_errors` (NaN where the
            oracle has no figure).

    Returns:
        ``character -> {"all": ..., "locomotion": ...}``, each ``{"model": cm,
        "mean_pose": cm, "ratio": model / mean_pose, "frames": n}``: the mean over every
        frame of the character's clips, and over its locomotion frames
        (:func:`locomotion_frames`; NaN figures when it has none). With oracle errors,
        ``locomotion`` also holds ``phase_oracle`` (cm), ``phased_ratio`` (``{"model":
        model / mean pose, "phase_oracle": oracle / mean pose}``) and
        ``phase_oracle_frames``, all over the locomotion frames with a gait phase.
    """
    out: dict[str, Any] = {}
    for name, clips in errors.items():
        model = torch.cat([c[0] for c in clips])
        base = torch.cat([c[1] for c in clips])
        loco = torch.cat([c[2] for c in clips])
        out[name] = {}
        for subset, mask in (("all", torch.ones_like(loco)), ("locomotion", loco)):
            n = int(mask.sum())
            m = 100 * float(model[mask].mean()) if n else math.nan
            b = 100 * float(base[mask].mean()) if n else math.nan
            out[name][subset] = {
                "model": m,
                "mean_pose": b,
                "ratio": m / b if n and b > 0 else math.nan,
                "frames": n,
            }
        if all(len(c) > 3 for c in clips):
            oracle = torch.cat([c[3] for c in clips])
            phased = loco & oracle.isfinite()
            n = int(phased.sum())
            o = 100 * float(oracle[phased].mean()) if n else math.nan
            b = 100 * float(base[phased].mean()) if n else math.nan
            m = 100 * float(model[phased].mean()) if n else math.nan
            out[name]["locomotion"].update(
                {
                    "phase_oracle": o,
                    "phased_ratio": {
                        MODEL: m / b if n and b > 0 else math.nan,
                        "phase_oracle": o / b if n and b > 0 else math.nan,
                    },
                    "phase_oracle_frames": n,
                }
            )
    return out
