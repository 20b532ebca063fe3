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
  average pose decoded at each frame's manifold point (joint positions relative to
  the root, in the character's facing frame, cm), beside ``mean_pose``: the clip's
  own mean pose in that frame (:func:`skelagnostic.baselines.mean_pose`);
  ``pose_mpjpe_locomotion_cm``: the same on its locomotion frames
  (:func:`locomotion_frames`).

``extra`` holds the paper's Table 2 (:func:`table2`; its shared codes once taken
from the held-out clips, once from the training windows, as the paper's
"embeddings in the dataset" are) and Table 1 (:func:`table1`, beside the reference
of :func:`phase_oracle_errors`: the average pose of a clip's true gait phase, which
knows the phase but not the code, so it is no bound) per character, the codebook
size K (``num_codes``), codebook usage and overlap (:func:`code_overlap`), the frequency
head against the feet's touch-down rate (:func:`frequency_head_figures`), per-character
means, and phase linearity and frequency error on held-out procedural gaits
(:func:`procedural_gaits`); the plot ``manifold.png`` is the phase manifold
(Fig. 1) with the held-out frames. The paper measures Table 1 on the training data:
``evaluate split=train`` runs the protocol on the run's training clips (the report
says so), where ``extra.table1`` is that figure.

``vqpae.transfer`` (:func:`transfer_protocol`) re-enacts held-out clips of the
first character with the second's training clips and times the outputs' feet
against the source's (:func:`gait_frequency`, :func:`contact_frequency`,
:func:`rhythm_figures`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from skelagnostic.analysis import (
    LOCOMOTION_RUN_SECONDS,
    LOCOMOTION_SPAN,
    LOCOMOTION_SPEED,
    acceleration,
    contact_frequency,
    contact_lock,
    gait_frequency,
    gait_phase,
    locomotion_frames,
    locomotion_runs,
    motion_onsets,
    onset_rate,
    rate_in_runs,
    touchdown_frequency,
)
from skelagnostic.baselines import mean_pose
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.evaluation import (
    MODEL,
    Evaluation,
    EvaluationError,
    HeldOut,
    clips_of_split,
    mean_rows,
    track,
)
from skelagnostic.metrics.functional import manifold_overlap
from skelagnostic.representations import GlobalPositions
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip, plot_manifold
from skelagnostic_vqpae.transfer import (
    FREQUENCY_TOLERANCE,
    HALFLIFE,
    TransferDatabase,
    build_database,
    transfer,
    with_known_frequencies,
)

__all__ = [
    "ORACLE_PHASE_BINS",
    "OWN_RATE",
    "PROCEDURAL_SECONDS",
    "PROCEDURAL_SEED",
    "RHYTHM_RUN_SECONDS",
    "RHYTHM_TOLERANCE",
    "TRANSFER_METRICS",
    "UNSCALED",
    "code_overlap",
    "frequency_head_figures",
    "manifold_protocol",
    "phase_line",
    "phase_oracle_errors",
    "procedural_gaits",
    "procedural_kind",
    "rhythm_figures",
    "table1",
    "table2",
    "training_codes",
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


def _pose_errors(aligner: Any, clip: Any, emb: ClipEmbedding) -> tuple[torch.Tensor, ...]:
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
        aligner: A trained :class:`~skelagnostic_vqpae.aligner.VqpaeAligner`.
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
            per-frame errors in metres (:func:`_pose_errors`); an optional fourth
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


#: Smallest seed of :func:`procedural_gaits`' clips (higher when a training source reaches it).
PROCEDURAL_SEED = 1000

#: Duration (seconds) of each held-out procedural gait.
PROCEDURAL_SECONDS = 6.0


def procedural_kind(skeleton: Skeleton, tolerance: float = 0.02) -> str | None:
    """The :mod:`skelagnostic.procedural` kind whose rig ``skeleton`` is, if any.

    The generator animates only its own skeletons (:data:`skelagnostic.procedural.KINDS`):
    a rig is one of them when it has the same joints and parents and the same rest
    offsets up to scale (every offset over the skeleton height within ``tolerance``).
    A real rig with the same joint names (LaFAN1 and ``biped22``) has other rest
    offsets, so the generator's joint angles would not play on it.

    Args:
        skeleton: A character's skeleton.
        tolerance: Largest difference of an offset coordinate, in skeleton heights.

    Returns:
        The kind, or None.
    """
    from skelagnostic import procedural

    height = max(skeleton.height(), 1e-9)
    for kind in procedural.KINDS:
        ref = procedural.skeleton(kind)
        if list(ref.joint_names) != list(skeleton.joint_names) or list(ref.parents) != list(
            skeleton.parents
        ):
            continue
        diff = ref.offsets.double() / ref.height() - skeleton.offsets.double() / height
        if float(diff.abs().max()) <= tolerance:
            return kind
    return None


def _first_unseen_seed(datamodule: Any) -> int:
    """A seed above every seed the run's procedural training sources used."""
    from skelagnostic.data import ProceduralSource

    first = PROCEDURAL_SEED
    for source in getattr(datamodule, "sources", None) or []:
        if isinstance(source, ProceduralSource):
            first = max(first, source.seed + len(source.clips()))
    return first


def procedural_gaits(aligner: Any, held: HeldOut, seeds_per_gait: int = 2) -> dict[str, Any]:
    """Phase linearity and frequency error on held-out procedural gaits, per character.

    For every character whose rig is a procedural kind (:func:`procedural_kind`),
    ``seeds_per_gait`` clips of each of its morphology's gaits except ``idle``,
    :data:`PROCEDURAL_SECONDS` long at the character's frame rate, with seeds from
    :data:`PROCEDURAL_SEED` upwards, above every seed a procedural training source of
    the run used (a seed sets the body size, stride frequency and turning, so these
    clips were never seen). The model sees them in metres, as it saw its training
    clips (:meth:`VqpaeAligner.encode`). Per clip, on the
    frames whose window lies inside the clip: the median of the frequency head
    against the generator's stride frequency, the rate at which the phase advances
    (slope of :func:`phase_line`) against the same, and the phase's R^2.

    Args:
        aligner: A trained aligner.
        held: The run's held-out clips (for its data module's training sources).
        seeds_per_gait: Clips per gait and character; 0: none.

    Returns:
        ``characters`` (name -> kind or None), ``seeds``, ``seconds``, ``clips``
        (rows with ``character``, ``kind``, ``gait``, ``seed``, ``true_hz``,
        ``predicted_hz``, ``frequency_error_pct``, ``phase_hz``,
        ``phase_rate_error_pct``, ``phase_r2``), ``mean`` (of the numeric row
        figures) and ``note`` (why characters have no clip, or None).
    """
    from skelagnostic import procedural

    specs = aligner.hparams["datasets"] or {}
    kinds: dict[str, str | None] = {}
    for name in aligner.dataset_names:
        sk = (specs.get(name) or {}).get("skeleton")
        kinds[name] = procedural_kind(Skeleton.from_dict(sk)) if sk else None
    seed = _first_unseen_seed(held.datamodule) if seeds_per_gait > 0 else PROCEDURAL_SEED
    rows: list[dict[str, Any]] = []
    for name, kind in kinds.items():
        if kind is None or seeds_per_gait <= 0:
            continue
        spec = specs[name]
        fps, half = float(spec["fps"]), int(spec["window"]) // 2
        morphology = "quadruped" if kind == "quadruped" else "biped"
        for gait in procedural.GAITS[morphology]:
            if gait == "idle":
                continue
            for _ in range(seeds_per_gait):
                motion, info = procedural.generate(
                    kind, gait, seconds=PROCEDURAL_SECONDS, fps=fps, seed=seed
                )
                emb = embed_clip(aligner, motion)
                inner = slice(half, max(len(emb) - half, half + 2))
                truth = float(info["frequency"])
                predicted = float(emb.frequency[inner].median())
                r2, slope = phase_line(emb.phase[inner])
                phase_hz = abs(slope) * emb.fps
                rows.append(
                    {
                        "clip": str(motion.name),
                        "character": name,
                        "kind": kind,
                        "gait": gait,
                        "seed": seed,
                        "true_hz": truth,
                        "predicted_hz": predicted,
                        "frequency_error_pct": 100 * abs(predicted - truth) / truth,
                        "phase_hz": phase_hz,
                        "phase_rate_error_pct": 100 * abs(phase_hz - truth) / truth,
                        "phase_r2": r2,
                    }
                )
                seed += 1
    figures = ("frequency_error_pct", "phase_rate_error_pct", "phase_r2")
    absent = [n for n, k in kinds.items() if k is None]
    note = None
    if absent and seeds_per_gait > 0:
        note = (
            f"no procedural gaits for {', '.join(absent)}: their rigs are not a procedural "
            "kind's (skelagnostic.procedural animates only its own skeletons), so no clip of "
            "known gait frequency exists on them; phase linearity on held-out procedural gaits "
            "needs a model trained on procedural characters"
        )
    return {
        "characters": kinds,
        "seeds": sorted({r["seed"] for r in rows}),
        "seconds": PROCEDURAL_SECONDS,
        "clips": rows,
        "mean": {f: float(np.mean([r[f] for r in rows])) for f in figures} if rows else {},
        "note": note,
    }


def manifold_protocol(
    aligner: Any, held: HeldOut, out_dir: Path, procedural_seeds: int = 2
) -> Evaluation:
    """``vqpae.manifold``: Tables 1 and 2 per character, phase linearity, procedural gaits.

    Args:
        aligner: A trained :class:`~skelagnostic_vqpae.aligner.VqpaeAligner`.
        held: The run's held-out clips.
        out_dir: Where ``manifold.png`` goes.
        procedural_seeds: Held-out procedural clips per gait and character
            (:func:`procedural_gaits`; 0: none).

    Returns:
        Per-clip rows (``character``, ``frames``, ``locomotion_frames``; metrics
        ``shared_code_share``, ``phase_r2``, ``pose_mpjpe_cm``,
        ``pose_mpjpe_locomotion_cm``) and ``extra``: ``overlap``
        (:func:`code_overlap`), ``table2`` (:func:`table2`), ``table1``
        (:func:`table1`), ``per_character`` (character -> method -> metric -> mean
        of its clips), ``locomotion_rule`` and ``procedural``
        (:func:`procedural_gaits`).
    """
    num_codes = int(aligner.hparams.num_codes)
    embeddings = [embed_clip(aligner, clip) for clip in track(held.clips, "held-out clips")]
    by_character: dict[str, list[ClipEmbedding]] = {}
    for emb in embeddings:
        by_character.setdefault(emb.dataset, []).append(emb)
    codes = {n: torch.cat([e.code for e in embs]) for n, embs in by_character.items()}
    overlap = code_overlap(codes, num_codes)
    trained = training_codes(aligner, held.datamodule) if held.datamodule is not None else None
    if not trained or not set(trained) >= set(codes):
        trained = None  # the data module's training split is not the characters' data
    table = table2(codes, trained)
    shared = table["shared_codes"]
    specs = aligner.hparams["datasets"] or {}
    authors = [n for n in aligner.dataset_names if (specs.get(n) or {}).get("pose_features")]
    pose_ready = not authors and all(bool(c.pose_fitted) for c in aligner.characters)
    notes = [
        f"evaluated clips: the {held.name}; codebook size K = {num_codes} (extra.num_codes)",
        "codes_shared_training / frame_share_training (Table 2 over the training set, the "
        "paper's figure, as the authors' test_vq.py): "
        + (
            "codes_shared_training = codes every character uses on its training windows, "
            "frame_share_training = share of each character's training windows on them, "
            "frame_share_heldout_on_training_shared = share of the evaluated frames on them "
            "(frame_share_training_shared: the same, its former name)"
            if trained is not None
            else "omitted, the evaluated data has no training split "
            "with a dataset of every character's name"
        ),
        f"shared codes: {len(shared)} of {num_codes}, over the evaluated clips of "
        f"{', '.join(by_character)}; chance = shared / K; codes shared / codes used by any "
        f"character: {table['codes_shared']} / {table['codes_used_any']}",
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
    errors: dict[str, list[tuple[torch.Tensor, ...]]] = {}
    for clip, emb in zip(held.clips, embeddings, strict=True):
        share = float(np.isin(emb.code.numpy(), shared).mean()) if len(emb) else 0.0
        values: dict[str, dict[str, float]] = {
            MODEL: {"shared_code_share": share, "phase_r2": phase_line(emb.phase)[0]},
            "chance": {"shared_code_share": len(shared) / num_codes},
        }
        row: dict[str, Any] = {"clip": str(clip.name), "character": emb.dataset, "frames": len(emb)}
        if pose_ready:
            model_err, base_err, loco, truth, phase = _pose_errors(aligner, clip, emb)
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
    plot_manifold(aligner, by_character, out=out_dir / "manifold.png")
    metrics = {
        "shared_code_share": "share of frames on codes every character uses, higher is better",
        "phase_r2": "R^2 of a line through the unwrapped phase, higher is better",
    }
    extra: dict[str, Any] = {
        "num_codes": num_codes,
        "overlap": overlap,
        "table2": table,
        "per_character": {
            name: mean_rows([r for r in rows if r["character"] == name]) for name in by_character
        },
    }
    if pose_ready:
        metrics["pose_mpjpe_cm"] = (
            "MPJPE of the decoded average pose in the root's facing frame, relative to the "
            "root joint, cm, lower is better"
        )
        metrics["pose_mpjpe_locomotion_cm"] = (
            "the same on the clip's locomotion frames only (root speed >= "
            f"{LOCOMOTION_SPEED:g} skeleton heights/s), cm, lower is better"
        )
        extra["table1"] = table1(errors)
        notes.append(
            "Table 1 phase_oracle: per clip, the mean pose of its locomotion frames in each "
            f"1/{ORACLE_PHASE_BINS} cycle of the gait phase measured from the feet "
            "(touch-down to touch-down); it reads the evaluated clips' truth (a reference, not "
            "a method): what the true phase adds to the clip's mean pose; it knows the phase "
            "but not the code, so it is no bound (a model can be below it)"
        )
        extra["locomotion_rule"] = {
            "min_speed_heights_per_s": LOCOMOTION_SPEED,
            "span_seconds": LOCOMOTION_SPAN,
            "rule": "frames whose root travels at least min_speed_heights_per_s skeleton "
            "heights per second horizontally, over a centred span of span_seconds",
        }
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


# --- vqpae.transfer ---------------------------------------------------------------------------

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
                "gait_ratio": hz / source_hz,
                **rhythm_figures(clip, out),
                "accel_height_per_s2": mean_acc,
                "accel_max_height_per_s2": max_acc,
            }
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
    ]
    return Evaluation(
        TRANSFER_METRICS,
        rows,
        extra={"touchdown_periods": bound},
        plots=["transfer.gif", "transfer_sheet.png"],
        notes=notes,
    )
