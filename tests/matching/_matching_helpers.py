"""Small databases for the matching tests."""

from __future__ import annotations

import math

import torch

FPS = 30.0


def cycle_clip(
    hz: float, frames: int, dims: int = 4, phase0: float = 0.0
) -> dict[str, torch.Tensor]:
    """A clip going round one ellipse at a constant frequency (exact, no noise)."""
    phase = 2 * math.pi * (phase0 + hz * torch.arange(frames, dtype=torch.float64) / FPS)
    axes = torch.linspace(0.5, 1.5, dims, dtype=torch.float64)
    manifold = torch.cat(
        [phase.sin()[:, None] * axes[None, :2], phase.cos()[:, None] * axes[None, 2:]], 1
    )
    pose = torch.stack([phase.sin(), phase.cos(), (2 * phase).sin()], 1)
    return {
        "manifold": manifold.float(),
        "pose": pose.float(),
        "frequency": torch.full((frames, 1), hz),
    }


def random_clips(
    num_clips: int, frames: tuple[int, int], seed: int, dims: int = 3, pose_dims: int = 5
) -> list[dict[str, torch.Tensor]]:
    """Random smooth-ish clips with random positive frequencies."""
    gen = torch.Generator().manual_seed(seed)
    clips = []
    for _ in range(num_clips):
        n = int(torch.randint(frames[0], frames[1] + 1, (1,), generator=gen))
        walk = torch.cumsum(torch.randn(n, dims + pose_dims, generator=gen), 0) * 0.3
        hz = 1.0 + 3.0 * torch.rand(n, 1, generator=gen)
        clips.append({"manifold": walk[:, :dims], "pose": walk[:, dims:], "frequency": hz})
    return clips
