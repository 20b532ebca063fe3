"""How smooth a clip is: joint acceleration relative to the skeleton height, for any rig."""

from __future__ import annotations

import math

import torch

from skelagnostic.core.motion import Motion

__all__ = ["acceleration"]


def acceleration(motion: Motion, positions: torch.Tensor | None = None) -> tuple[float, float]:
    """Mean and largest per-frame joint acceleration over the skeleton height, 1/s^2.

    The second difference of the global joint positions, times ``fps^2``; its norm
    averaged over the joints of each frame, divided by the skeleton height; then the
    mean and the maximum over the frames (lower is smoother; a cut between replayed
    windows shows as a large maximum).

    Args:
        motion: The clip.
        positions: Its global positions ``[T, J, 3]``, when the caller has them
            (default: forward kinematics here).

    Returns:
        ``(mean, max)``, NaN for clips shorter than 3 frames.
    """
    pos = (motion.global_positions() if positions is None else positions).double()
    if len(pos) < 3:
        return math.nan, math.nan
    per_frame = (pos[2:] - 2 * pos[1:-1] + pos[:-2]).norm(dim=-1).mean(-1) * motion.fps**2
    per_frame = per_frame / max(motion.skeleton.height(), 1e-9)
    return float(per_frame.mean()), float(per_frame.max())
