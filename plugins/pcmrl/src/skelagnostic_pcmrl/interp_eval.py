"""PC-MRL Table 1 protocol: L2P / L2Q / NPSS at keyframe gaps 5, 15, 30 (Sec. 4.3).

Every held-out clip is cut into windows of 128 frames (every ``stride`` frames);
in each window a key is placed every ``gap`` frames plus on the last frame, and
each method fills the other frames:

* ``LERP``: the baseline of the paper, linear interpolation of the root position
  and spherical linear interpolation (SLERP) of every joint's local rotation
  between the surrounding keys, then forward kinematics;
* ``PC-MRL``: :meth:`InterpolationAligner.interpolate
  <skelagnostic_pcmrl.interp.InterpolationAligner.interpolate>`.

Metrics (:mod:`skelagnostic.metrics`): L2P on global positions, horizontally
centred on the window's mean root position and z-normalised per channel with
statistics of the training windows (or, when none are given, of the evaluated
windows; the JSON says which); L2Q on global quaternions; both averaged over
the generated (non-key) frames. NPSS on global quaternions over the whole
window with the squared-magnitude spectrum (``power="abs"``, as CITL/PC-MRL).

Run ``python -m skelagnostic_pcmrl.interp_eval --help``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import l2p, l2q, npss
from skelagnostic_pcmrl.interp import lerp_keys, slerp_keys
from skelagnostic_pcmrl.interp_data import gap_keys

__all__ = [
    "GAPS",
    "evaluate",
    "format_table",
    "lerp_slerp",
    "load_motions",
    "main",
    "position_stats",
    "windows",
]

log = logging.getLogger(__name__)

#: Keyframe gaps of Table 1.
GAPS = (5, 15, 30)

Interpolator = Callable[[Motion, Sequence[int]], Motion]


def lerp_slerp(motion: Motion, keyframes: Sequence[int]) -> Motion:
    """The LERP baseline: root LERP and local-rotation SLERP between keyframes.

    Args:
        motion: The motion (only its keyframes are read).
        keyframes: Increasing frame indices, the first 0 and the last the final frame.

    Returns:
        The interpolated motion (same skeleton, fps, name and units).
    """
    keys = torch.zeros(1, motion.num_frames, dtype=torch.bool)
    keys[0, list(keyframes)] = True
    rot = Q.continuity(motion.rotations, dim=-3)[None]
    root = lerp_keys(motion.root_positions[None], keys)[0]
    local = slerp_keys(rot, keys)[0]
    return Motion(motion.skeleton, local, root, motion.fps, name=motion.name, units=motion.units)


def windows(motions: Sequence[Motion], window: int, stride: int) -> list[Motion]:
    """Windows of ``window`` frames every ``stride`` frames (shorter clips are skipped)."""
    out = []
    for motion in motions:
        for start in range(0, motion.num_frames - window + 1, stride):
            out.append(motion[start:start + window])
    return out


def _centred_positions(motion: Motion) -> torch.Tensor:
    """``[T, J, 3]`` global positions minus the window's mean horizontal root position."""
    pos = motion.global_positions()
    up = motion.skeleton.up_index
    centre = motion.root_positions.mean(dim=0).clone()
    centre[up] = 0.0
    return pos - centre


def position_stats(motions: Sequence[Motion]) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-channel mean and std (``[J*3]``, floored at 1e-3) of centred global positions."""
    if not motions:
        raise SkelagnosticError("position_stats: no windows to compute statistics from")
    flat = torch.cat([_centred_positions(m.double()).flatten(1) for m in motions])
    return flat.mean(dim=0), flat.std(dim=0).clamp_min(1e-3)


def evaluate(
    methods: dict[str, Interpolator],
    motions: Sequence[Motion],
    window: int = 128,
    stride: int = 64,
    gaps: Sequence[int] = GAPS,
    stats: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> dict[str, Any]:
    """Run the Table 1 protocol.

    Args:
        methods: Name -> ``interpolate(motion, keyframes)`` callable.
        motions: Held-out clips (all on one skeleton hierarchy), in the training units.
        window: Window length (128 in the paper).
        stride: Frames between window starts.
        gaps: Keyframe gaps.
        stats: L2P normalisation ``(mean, std)`` from training windows
            (:func:`position_stats`); ``None`` uses the evaluated windows.

    Returns:
        ``{"protocol": {...}, "results": {method: {gap: {"l2p", "l2q", "npss"}}}}``.

    Raises:
        SkelagnosticError: No clip is long enough for one window.
    """
    wins = windows(motions, window, stride)
    if not wins:
        raise SkelagnosticError(f"evaluate: no clip has {window} frames")
    stats_source = "training windows"
    if stats is None:
        stats, stats_source = position_stats(wins), "evaluated windows"
    mean, std = stats
    target_pos = torch.stack([_centred_positions(w.double()) for w in wins])
    target_rot = torch.stack([w.double().global_rotations() for w in wins])
    results: dict[str, dict[str, dict[str, float]]] = {}
    for name, method in methods.items():
        results[name] = {}
        for gap in gaps:
            key_mask = gap_keys(window, gap)
            keys = key_mask.nonzero().squeeze(1).tolist()
            preds = [method(w, keys).double() for w in wins]
            pred_pos = torch.stack([_centred_positions_like(p, w) for p, w in zip(preds, wins,
                                                                                  strict=True)])
            pred_rot = torch.stack([p.global_rotations() for p in preds])
            mask = (~key_mask).expand(len(wins), -1)
            results[name][str(gap)] = {
                "l2p": float(l2p(pred_pos, target_pos, mean, std, mask=mask)),
                "l2q": float(l2q(pred_rot, target_rot, mask=mask)),
                "npss": float(npss(pred_rot, target_rot, "abs")),
            }
    return {
        "protocol": {
            "window": window, "stride": stride, "gaps": list(gaps), "windows": len(wins),
            "clips": [m.name for m in motions if m.num_frames >= window],
            "l2p_stats": stats_source, "l2p_l2q_frames": "non-key frames",
            "npss": "whole window, power=abs", "fps": wins[0].fps,
        },
        "results": results,
    }


def _centred_positions_like(pred: Motion, target: Motion) -> torch.Tensor:
    """``pred``'s global positions centred with ``target``'s horizontal root mean."""
    pos = pred.global_positions()
    up = target.skeleton.up_index
    centre = target.double().root_positions.mean(dim=0).clone()
    centre[up] = 0.0
    return pos - centre


def format_table(report: dict[str, Any]) -> str:
    """A Markdown table in the layout of the paper's Table 1."""
    gaps = report["protocol"]["gaps"]
    head = "| Method | " + " | ".join(f"{m} {g}" for m in ("L2P", "L2Q", "NPSS") for g in gaps)
    lines = [head + " |", "|---" * (1 + 3 * len(gaps)) + "|"]
    for name, per_gap in report["results"].items():
        cells = [f"{per_gap[str(g)][m]:.4f}" for m in ("l2p", "l2q", "npss") for g in gaps]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def load_motions(paths: Sequence[str | Path], fps: float, units: str | None) -> list[Motion]:
    """Read BVH files (or directories of them), convert to metres and resample to ``fps``."""
    from skelagnostic.data.sources import BVHSource

    source = BVHSource(paths=list(paths), units=units)
    out = []
    for ref in source.clips():
        motion = source.load(ref)
        if motion.fps != fps:
            motion = motion.resample(fps)
        motion.name = Path(ref.id).name
        out.append(motion)
    return out


def _procedural(kind: str, clips: int, fps: float, seed: int, seconds: float) -> list[Motion]:
    from skelagnostic.data.sources import ProceduralSource

    source = ProceduralSource(kinds=(kind,), gaits=("walk", "run"), clips_per_gait=clips,
                              seconds=seconds, seed=seed, name="procedural_eval")
    out = []
    for ref in source.clips():
        motion = source.load(ref)
        if motion.fps != fps:
            motion = motion.resample(fps)
        motion.name = ref.id
        out.append(motion)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: evaluate a checkpoint (and LERP) and write JSON + a Markdown table."""
    parser = argparse.ArgumentParser(
        prog="python -m skelagnostic_pcmrl.interp_eval",
        description="PC-MRL Table 1 protocol (L2P/L2Q/NPSS at keyframe gaps) vs LERP/SLERP.",
    )
    parser.add_argument("--ckpt", help="pcmrl_interp checkpoint (omit for LERP only)")
    parser.add_argument("--data", nargs="*", default=[], help="held-out BVH files/directories")
    parser.add_argument("--units", default=None, help="units of the BVH files (e.g. cmu, cm)")
    parser.add_argument("--train-data", nargs="*", default=[],
                        help="training BVH files for the L2P statistics (default: test windows)")
    parser.add_argument("--procedural", type=int, default=0,
                        help="also/instead evaluate N procedural clips per gait (walk, run)")
    parser.add_argument("--procedural-kind", default="biped31")
    parser.add_argument("--procedural-seed", type=int, default=777,
                        help="seed of the procedural test clips (keep it apart from training)")
    parser.add_argument("--procedural-seconds", type=float, default=8.0)
    parser.add_argument("--fps", type=float, default=None,
                        help="frame rate (default: the checkpoint's, else 30)")
    parser.add_argument("--window", type=int, default=128)
    parser.add_argument("--stride", type=int, default=64)
    parser.add_argument("--gaps", type=int, nargs="+", default=list(GAPS))
    parser.add_argument("--out", required=True, help="output JSON path (.md table next to it)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    methods: dict[str, Interpolator] = {"LERP": lerp_slerp}
    fps = args.fps
    if args.ckpt:
        from skelagnostic.aligners.checkpoints import load_checkpoint
        from skelagnostic_pcmrl.interp import InterpolationAligner

        model = load_checkpoint(InterpolationAligner, args.ckpt, option="--ckpt").eval()
        methods["PC-MRL"] = model.interpolate
        fps = fps or model.hparams.fps
    fps = float(fps or 30.0)
    report: dict[str, Any] = {}
    sets: list[tuple[str, list[Motion], list[Motion]]] = []
    if args.data:
        train = load_motions(args.train_data, fps, args.units) if args.train_data else []
        sets.append(("bvh", load_motions(args.data, fps, args.units), train))
    if args.procedural:
        sets.append(("procedural", _procedural(args.procedural_kind, args.procedural, fps,
                                               args.procedural_seed,
                                               args.procedural_seconds), []))
    if not sets:
        parser.error("give --data and/or --procedural")
    tables = []
    for label, motions, train in sets:
        stats = position_stats(windows(train, args.window, args.stride)) if train else None
        result = evaluate(methods, motions, args.window, args.stride, args.gaps, stats)
        report[label] = result
        tables.append(f"### {label} ({result['protocol']['windows']} windows of "
                      f"{args.window} frames at {fps:g} fps)\n\n{format_table(result)}")
        log.info("%s\n%s", label, format_table(result))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2))
    out.with_suffix(".md").write_text("\n\n".join(tables) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
