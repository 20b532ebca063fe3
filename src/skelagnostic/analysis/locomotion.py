"""Which frames of a clip travel over the ground: locomotion frames and runs, for any rig.

The rule reads only the root's horizontal path and the skeleton height
(:meth:`~skelagnostic.core.skeleton.Skeleton.height`), so it needs neither joint names
nor clip names and means the same for a human and a dog.
"""

from __future__ import annotations

import numpy as np
import torch

from skelagnostic.core.motion import Motion

__all__ = [
    "LOCOMOTION_RUN_SECONDS",
    "LOCOMOTION_SPAN",
    "LOCOMOTION_SPEED",
    "locomotion_frames",
    "locomotion_runs",
]

#: Locomotion rule of :func:`locomotion_frames`: root speed over the skeleton height, 1/s.
LOCOMOTION_SPEED = 0.25

#: Span (seconds) over which :func:`locomotion_frames` measures the root's displacement.
LOCOMOTION_SPAN = 0.5

#: Shortest run of locomotion frames (s) :func:`locomotion_runs` keeps: a few strides.
LOCOMOTION_RUN_SECONDS = 3.0


def locomotion_frames(
    motion: Motion, threshold: float = LOCOMOTION_SPEED, span: float = LOCOMOTION_SPAN
) -> torch.Tensor:
    """Which frames of a clip are locomotion: the character travels over the ground.

    A frame is locomotion when its root's horizontal displacement over a centred
    ``span`` (seconds), divided by that span and by the skeleton height
    (:meth:`~skelagnostic.core.skeleton.Skeleton.height`), reaches ``threshold``
    heights per second. The rule needs neither joint names nor clip names: a
    standing or idling character stays below it (the MANN dog's idle clip: a median
    of 0.006 heights/s), a walking human (1.2 m/s over 1.6 m: 0.75/s) or dog
    (0.84 m/s over 0.43 m: 2/s) is far above it; a quarter of the height per second
    is a slow stroll.

    Args:
        motion: A clip.
        threshold: Smallest speed, in skeleton heights per second.
        span: Seconds over which the displacement is measured (at least one frame).

    Returns:
        ``[F]`` boolean tensor.
    """
    up = motion.skeleton.up_index
    flat = [a for a in range(3) if a != up]
    root = motion.root_positions.double()[:, flat]
    frames = root.shape[0]
    half = max(1, round(span * motion.fps / 2))
    idx = torch.arange(frames)
    ahead, behind = (idx + half).clamp(max=frames - 1), (idx - half).clamp(min=0)
    elapsed = (ahead - behind).double().clamp(min=1) / motion.fps
    speed = (root[ahead] - root[behind]).norm(dim=-1) / elapsed
    return speed >= threshold * max(motion.skeleton.height(), 1e-9)


def locomotion_runs(
    motion: Motion, min_seconds: float = LOCOMOTION_RUN_SECONDS
) -> list[tuple[int, int]]:
    """``(start, end)`` frames (end excluded) of each run of locomotion frames.

    Runs of :func:`locomotion_frames` shorter than ``min_seconds`` are left out.

    Example:
        >>> from skelagnostic import procedural
        >>> walk, _ = procedural.generate("biped22", "walk", seconds=4.0, fps=30, seed=1)
        >>> locomotion_runs(walk), locomotion_runs(walk, min_seconds=5.0)
        ([(0, 121)], [])
    """
    edges = np.diff(np.r_[0, locomotion_frames(motion).numpy().astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [
        (int(a), int(b))
        for a, b in zip(starts, ends, strict=True)
        if (b - a) / motion.fps >= min_seconds
    ]
