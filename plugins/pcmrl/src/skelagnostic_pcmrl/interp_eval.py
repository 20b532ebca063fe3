"""PC-MRL Table 1 protocol: L2P / L2Q / NPSS at keyframe gaps 5, 15, 30 (Sec. 4.3).

Every held-out clip is cut into windows of 128 frames (every ``stride`` frames);
in each window a key is placed every ``gap`` frames plus on the last frame, and
each method fills the other frames:

* ``LERP``: the baseline of the paper, linear interpolation of the root position
  and spherical linear interpolation (SLERP) of every joint's local rotation
  between the surrounding keys, then forward kinematics
  (:func:`skelagnostic.baselines.lerp_slerp`);
* ``PC-MRL``: :meth:`PcmrlInterpAligner.interpolate
  <skelagnostic_pcmrl.interp.PcmrlInterpAligner.interpolate>`.

Metrics (:mod:`skelagnostic.metrics`): L2P on global positions, horizontally
centred on the window's mean root position and z-normalised per channel with
statistics of the training windows (or, when none are given, of the evaluated
windows; the JSON says which); L2Q on global quaternions; both averaged over
the generated (non-key) frames. NPSS on global quaternions over the whole
window with the squared-magnitude spectrum (``power="abs"``, as CITL/PC-MRL).

``skelagnostic evaluate`` runs it on a run's held-out clips as protocol
``pcmrl.interpolation`` (:func:`skelagnostic_pcmrl.evaluation.interpolation_protocol`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import l2p, l2q, npss
from skelagnostic_pcmrl.interp_data import gap_keys

__all__ = [
    "GAPS",
    "evaluate",
    "format_table",
    "position_stats",
    "windows",
]

#: Keyframe gaps of Table 1.
GAPS = (5, 15, 30)

Interpolator = Callable[[Motion, Sequence[int]], Motion]


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
