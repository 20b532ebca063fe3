"""Synthetic phase-manifold databases for the matching benchmarks.

Every clip walks around the ellipses of a small amplitude codebook (the shape of
a VQ-PAE phase manifold, WalkTheDog Eq. 1): per frame a frequency (Hz) that
drifts smoothly around a per-clip base, a phase integrated from it, an amplitude
code that changes every few seconds, the manifold point
``A0[code] sin(2 pi phase) + A1[code] cos(2 pi phase)`` and a pose descriptor
that is a fixed random function of code and phase, both with a little noise.
"""

from __future__ import annotations

import math

import torch


def synthetic_features(
    num_frames: int,
    num_clips: int,
    *,
    fps: float = 60.0,
    manifold_dims: int = 10,
    pose_dims: int = 30,
    codes: int = 32,
    seed: int = 0,
    codebook_seed: int = 1234,
) -> tuple[dict[str, torch.Tensor], list[int]]:
    """Per-frame features ``manifold``, ``pose``, ``frequency`` and the clip lengths.

    Clips with the same ``codebook_seed`` share one manifold (so a query generated
    with another ``seed`` finds semantically matching windows).
    """
    book = torch.Generator().manual_seed(codebook_seed)
    amplitude = torch.randn(codes, 2, manifold_dims, generator=book)
    amplitude *= torch.rand(codes, 1, 1, generator=book) * 1.8 + 0.2
    pose_map = torch.randn(codes, 4, pose_dims, generator=book) / 2

    gen = torch.Generator().manual_seed(seed)
    base = num_frames // num_clips
    lengths = [base] * num_clips
    lengths[-1] += num_frames - base * num_clips
    clip_of = torch.repeat_interleave(torch.arange(num_clips), torch.tensor(lengths))
    starts = torch.zeros(num_clips, dtype=torch.int64)
    starts[1:] = torch.cumsum(torch.tensor(lengths), 0)[:-1]
    local = torch.arange(num_frames) - starts[clip_of]
    seconds = local.double() / fps

    base_hz = (torch.rand(num_clips, generator=gen, dtype=torch.float64) * 2.2 + 0.8)[clip_of]
    drift_hz = torch.rand(num_clips, generator=gen, dtype=torch.float64)[clip_of] * 0.3 + 0.05
    drift_phase = torch.rand(num_clips, generator=gen, dtype=torch.float64)[clip_of] * 2 * math.pi
    frequency = base_hz * (1 + 0.15 * torch.sin(2 * math.pi * drift_hz * seconds + drift_phase))

    steps = frequency / fps
    total = torch.cumsum(steps, 0)
    clip_first = (total - steps)[starts]
    offset = torch.rand(num_clips, generator=gen, dtype=torch.float64)
    phase = (total - steps - clip_first[clip_of] + offset[clip_of]) * 2 * math.pi

    segment = (local // int(3 * fps)) + clip_of * (base // int(3 * fps) + 2)
    code = torch.randint(codes, (int(segment.max()) + 1,), generator=gen)[segment]
    sin, cos = torch.sin(phase).float(), torch.cos(phase).float()
    manifold = amplitude[code, 0] * sin[:, None] + amplitude[code, 1] * cos[:, None]
    manifold += 0.02 * torch.randn(num_frames, manifold_dims, generator=gen)
    harmonics = torch.stack([sin, cos, torch.sin(2 * phase).float(), torch.cos(2 * phase).float()])
    pose = 0.05 * torch.randn(num_frames, pose_dims, generator=gen)
    for c in range(codes):  # one code at a time keeps the peak memory low
        rows = (code == c).nonzero()[:, 0]
        pose[rows] += harmonics[:, rows].T @ pose_map[c]
    features = {"manifold": manifold, "pose": pose, "frequency": frequency.float()[:, None]}
    return features, lengths
