"""Retargeting evaluation of PC-MRL stage 1 (paper Sec. 4.4, Table 2 protocol).

For every test clip of the source dataset, the reconstruction on the target
skeleton is compared with the source motion by

* the temporal KNN distance (Eq. 5, :func:`skelagnostic.metrics.temporal_knn_distance`,
  mean per point, neighbour and frame) between 1024-point clouds drawn on the
  source motion (``X_A``) and on the result (``X_B``), K = 8, at point offsets
  sigma = 0, 0.01, 0.05, 0.1, 0.2 m;
* the end-effector error (Eq. 6, :func:`skelagnostic.metrics.end_effector_error`,
  summed over the matched hands, feet and head);

all in metres and multiplied by 100 as in Table 2, averaged over clips. Rows:
``original`` (an independently drawn cloud on the source motion itself: the
best reachable KNN value, as in the paper), ``name_copy`` (the naive baseline:
local rotations copied between joints of the same name, else of the same body
group and rank, identity otherwise; root path scaled by the height ratio) and
``pcmrl`` (the trained model).

Run it as ``python -m skelagnostic_pcmrl.evaluate --help``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import end_effector_error, temporal_knn_distance
from skelagnostic.representations import PointCloud
from skelagnostic_pcmrl.points import end_effector_pairs, infer_units

__all__ = [
    "SIGMAS",
    "evaluate_clips",
    "evaluate_pair",
    "format_table",
    "main",
    "name_copy",
    "name_copy_mapping",
]

#: Point offsets of Table 2, metres.
SIGMAS = (0.0, 0.01, 0.05, 0.1, 0.2)




def _key(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def _ranks(skeleton: Skeleton) -> dict[int, tuple[str, int]]:
    """``joint -> (body group, rank along the group by depth)`` for non-zero-length bones."""
    lengths = skeleton.bone_lengths()
    out: dict[int, tuple[str, int]] = {}
    for group in set(skeleton.body_groups):
        joints = [j for j in range(skeleton.num_joints)
                  if skeleton.body_groups[j] == group and (j == 0 or lengths[j] > 0)]
        joints.sort(key=lambda j: (skeleton.depth(j), j))
        out.update({j: (group, r) for r, j in enumerate(joints)})
    return out


def name_copy_mapping(source: Skeleton, target: Skeleton) -> dict[int, int]:
    """``target joint -> source joint`` for the naive baseline.

    Same name first (case and punctuation ignored), then, for joints left
    unmatched on both sides, same body group and rank along the group.
    """
    by_name = {_key(n): j for j, n in enumerate(source.joint_names)}
    mapping: dict[int, int] = {}
    for j, n in enumerate(target.joint_names):
        if _key(n) in by_name:
            mapping[j] = by_name[_key(n)]
    used = set(mapping.values())
    src_role = {role: j for j, role in _ranks(source).items() if j not in used}
    for j, role in _ranks(target).items():
        if j not in mapping and role in src_role:
            mapping[j] = src_role.pop(role)
    mapping[0] = 0
    return mapping


def name_copy(motion: Motion, target: Skeleton) -> Motion:
    """The naive retargeting baseline: copy local rotations by joint name / role.

    Args:
        motion: Source motion (any units; ``motion.units`` or guessed).
        target: Target skeleton (its own units, guessed from its height).

    Returns:
        A motion on ``target`` in the target's units.
    """
    src = motion.to_metres()
    units = infer_units(target)
    mapping = name_copy_mapping(src.skeleton, target)
    rot = torch.zeros(src.num_frames, target.num_joints, 4, dtype=src.rotations.dtype)
    rot[..., 0] = 1.0
    for j, s in mapping.items():
        rot[:, j] = src.rotations[:, s]
    ratio = target.height() * UNITS[units] / max(src.skeleton.height(), 1e-9)
    root = src.root_positions * ratio / UNITS[units]
    return Motion(target, rot, root, src.fps, units=units)


def evaluate_pair(
    result: Motion,
    source: Motion,
    sigmas: Sequence[float] = SIGMAS,
    num_points: int = 1024,
    k: int = 8,
    seed: int = 0,
    stride: int = 1,
) -> dict[str, float]:
    """Table 2 metrics (x100, metres) of ``result`` against ``source``.

    Args:
        result: The retargeted motion (target skeleton, any units).
        source: The source motion (same frame count and fps).
        sigmas: Point offsets.
        num_points: Points per cloud (1024).
        k: Neighbours (8).
        seed: Seed of the source clouds (the result's use ``seed + 1``).
        stride: Use every ``stride``-th frame for the metrics (1: all).

    Returns:
        ``{"knn@<sigma>": ..., "end": ...}``.

    Raises:
        SkelagnosticError: The frame counts differ.
    """
    if result.num_frames != source.num_frames:
        raise SkelagnosticError(f"evaluate: result has {result.num_frames} frames, source "
                                f"{source.num_frames}")
    res, src = result.to_metres().double(), source.to_metres().double()
    src_rot, src_pos = src.global_rotations()[::stride], src.global_positions()[::stride]
    res_rot, res_pos = res.global_rotations()[::stride], res.global_positions()[::stride]
    out: dict[str, float] = {}
    for sigma in sigmas:
        cloud = PointCloud(num_points, sigma)
        sa = cloud.sample(src.skeleton, torch.Generator().manual_seed(seed))
        sb = cloud.sample(res.skeleton, torch.Generator().manual_seed(seed + 1))
        pa = PointCloud.points(src_rot, src_pos, sa)
        pb = PointCloud.points(res_rot, res_pos, sb)
        knn = temporal_knn_distance(pb, pa, preds_groups=sb.groups, target_groups=sa.groups, k=k)
        out[f"knn@{sigma:g}"] = 100.0 * float(knn)
    pairs = end_effector_pairs(src.skeleton, res.skeleton)
    end = end_effector_error(res_pos, src_pos, preds_indices=[b for _, b in pairs],
                             target_indices=[a for a, _ in pairs])
    out["end"] = 100.0 * float(end)
    return out


def evaluate_clips(
    clips: Sequence[Motion],
    target: Skeleton,
    aligner: Any | None = None,
    baselines: bool = True,
    **options: Any,
) -> dict[str, Any]:
    """Table 2 rows averaged over clips: ``original``, ``name_copy`` and ``pcmrl`` (if given).

    Args:
        clips: Source motions.
        target: Target skeleton (its own units).
        aligner: A trained :class:`~skelagnostic_pcmrl.recon.PcmrlReconstruction`, or ``None``.
        baselines: Also compute the ``original`` and ``name_copy`` rows.
        **options: Passed to :func:`evaluate_pair` (``sigmas``, ``num_points``, ``k``,
            ``seed``, ``stride``).

    Returns:
        ``{"rows": {row: {metric: mean}}, "per_clip": [...], "options": ...}``.
    """
    per_clip = []
    for motion in clips:
        rows = {}
        if baselines or aligner is None:
            rows["original"] = evaluate_pair(motion, motion, **{
                **options, "seed": options.get("seed", 0) + 2}) | {"end": 0.0}
            rows["name_copy"] = evaluate_pair(name_copy(motion, target), motion, **options)
        if aligner is not None:
            rows["pcmrl"] = evaluate_pair(aligner.retarget(motion, target), motion, **options)
        per_clip.append({"frames": motion.num_frames, "rows": rows})
    names = list(per_clip[0]["rows"]) if per_clip else []
    metrics = list(per_clip[0]["rows"][names[0]]) if names else []
    mean = {r: {m: sum(c["rows"][r][m] for c in per_clip) / len(per_clip) for m in metrics}
            for r in names}
    return {"rows": mean, "per_clip": per_clip,
            "options": {k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}}


def format_table(result: dict[str, Any]) -> str:
    """A Markdown table of :func:`evaluate_clips` rows (values x100, metres)."""
    rows = result["rows"]
    metrics = list(next(iter(rows.values())))
    head = "| model | " + " | ".join(
        f"KNN sigma={m.split('@')[1]}" if m.startswith("knn@") else "L_end" for m in metrics
    ) + " |"
    lines = [head, "|" + "---|" * (len(metrics) + 1)]
    for name, values in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{values[m]:.4f}" for m in metrics) + " |")
    return "\n".join(lines)


def _load_clips(paths: Sequence[str], units: str | None, fps: float | None,
                max_frames: int | None) -> list[Motion]:
    from skelagnostic import read_bvh

    files: list[Path] = []
    for p in map(Path, paths):
        files.extend(sorted(p.rglob("*.bvh")) if p.is_dir() else [p])
    if not files:
        raise SkelagnosticError(f"evaluate: no BVH file in {list(paths)}")
    clips = []
    for f in files:
        m = read_bvh(f)
        m.units = infer_units(m.skeleton, units)
        if fps is not None and m.fps != fps:
            m = m.resample(fps)
        clips.append(m[:max_frames] if max_frames else m)
    return clips


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Command line: evaluate a checkpoint (and the name-copy baseline) on BVH clips."""
    parser = argparse.ArgumentParser(
        prog="python -m skelagnostic_pcmrl.evaluate",
        description="PC-MRL Table 2 protocol: temporal KNN distance at several sigmas and "
        "end-effector error (x100, metres) of a model=pcmrl checkpoint and of the naive "
        "joint-name copy.",
    )
    parser.add_argument("clips", nargs="+", help="source BVH files or directories")
    parser.add_argument("--ckpt", help="model=pcmrl checkpoint (omit: baseline only)")
    parser.add_argument("--target", help="target BVH file or procedural kind "
                        "(default: the checkpoint's target)")
    parser.add_argument("--target-units", default=None)
    parser.add_argument("--source-units", default=None)
    parser.add_argument("--fps", type=float, default=None, help="resample the clips")
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--stride", type=int, default=1, help="metric on every n-th frame")
    parser.add_argument("--sigmas", type=float, nargs="+", default=list(SIGMAS))
    parser.add_argument("--points", type=int, default=1024)
    parser.add_argument("--k", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", help="write the result to this JSON file")
    parser.add_argument("--no-baselines", action="store_true",
                        help="only the model's row (skip 'original' and 'name_copy')")
    args = parser.parse_args(argv)
    aligner = None
    if args.ckpt:
        from skelagnostic.aligners.checkpoints import load_checkpoint
        from skelagnostic_pcmrl.recon import PcmrlReconstruction

        aligner = load_checkpoint(PcmrlReconstruction, args.ckpt, option="--ckpt").eval()
    if args.target:
        from skelagnostic_pcmrl.recon_data import load_target_skeleton

        skeleton, units = load_target_skeleton(args.target, args.target_units)
        target = skeleton.scaled(1.0 / UNITS[units])
    elif aligner is not None:
        target = aligner.target_skeleton.scaled(1.0 / UNITS[aligner.target_units])
    else:
        parser.error("give --target or --ckpt")
    clips = _load_clips(args.clips, args.source_units, args.fps, args.max_frames)
    result = evaluate_clips(clips, target, aligner, not args.no_baselines,
                            sigmas=tuple(args.sigmas),
                            num_points=args.points, k=args.k, seed=args.seed, stride=args.stride)
    result["clips"] = [str(c) for c in args.clips]
    result["checkpoint"] = args.ckpt
    print(format_table(result))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":  # pragma: no cover
    main(sys.argv[1:])
