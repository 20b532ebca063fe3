"""Suite ``kinematics``: forward-kinematics cost as the frame count grows.

A procedural 22-joint walk is tiled to N frames (1k .. 1M) and
``forward_kinematics`` computes all global rotations and positions in float32
and float64. Reported per size: milliseconds per call and frames per second
(higher is better). No external baseline: the point is the growth (linear in
frames; per-frame cost should fall while Python overhead is amortised).
"""

from __future__ import annotations

import torch

from benchmarks.harness import Result, timeit_median

SIZES = {
    "smoke": [1_000, 10_000],
    "default": [1_000, 10_000, 100_000, 1_000_000],
    "large": [1_000, 10_000, 100_000, 1_000_000, 4_000_000],
}


def _label(frames: int) -> str:
    return f"{frames // 1_000_000}M" if frames >= 1_000_000 else f"{frames // 1000}k"


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` and return its results."""
    import skelagnostic as sa
    from skelagnostic.core.kinematics import forward_kinematics

    base, _ = sa.procedural.generate("biped22", "walk", seconds=10, fps=100, seed=0)
    results = []
    for frames in SIZES[size]:
        reps = -(-frames // base.num_frames)
        for dtype in (torch.float32, torch.float64):
            rot = base.rotations.to(dtype).repeat(reps, 1, 1)[:frames].contiguous()
            root = base.root_positions.to(dtype).repeat(reps, 1)[:frames].contiguous()
            offsets = base.skeleton.offsets.to(dtype)
            parents = base.skeleton.parents
            repeats = 5 if frames <= 100_000 else 3
            seconds = timeit_median(
                lambda rot=rot, root=root, offsets=offsets, parents=parents: forward_kinematics(
                    rot, root, offsets, parents
                ),
                repeats,
            )
            name = f"fk_{_label(frames)}_{str(dtype).removeprefix('torch.')}"
            results.append(Result(name + "_time", "ms", seconds * 1e3))
            results.append(
                Result(name + "_throughput", "frames/s", frames / seconds, higher_is_better=True)
            )
    return results
