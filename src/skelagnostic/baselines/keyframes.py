"""Keyframe interpolation baseline of LaFAN1 (Harvey et al. 2020) and PC-MRL Table 1.

Between two keyframes the root position is linearly interpolated (LERP) and
every joint's local rotation spherically (SLERP, shorter arc); frames after
the last key hold it.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion

__all__ = ["key_brackets", "lerp_keys", "lerp_slerp", "slerp_keys"]


def key_brackets(keys: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Previous key, next key and the linear weight of every frame.

    Args:
        keys: ``[B, T]`` boolean keyframe mask; frame 0 must be a key.

    Returns:
        ``(prev [B, T], next [B, T], w [B, T])`` with ``w`` in [0, 1] (0 on keys);
        frames after the last key use the last key on both sides (weight 0).

    Raises:
        ValueError: ``keys`` is not ``[B, T]`` or frame 0 is not a key.
    """
    if keys.dim() != 2:
        raise ValueError(f"keys must be [B, T], got shape {tuple(keys.shape)}")
    if not bool(keys[:, 0].all()):
        raise ValueError("keys: frame 0 must be a keyframe of every window")
    num_t = keys.shape[-1]
    frames = torch.arange(num_t, device=keys.device).expand_as(keys)
    marked = torch.where(keys, frames, torch.full_like(frames, -1))
    prev = torch.cummax(marked, dim=-1).values
    after = torch.where(keys, frames, torch.full_like(frames, num_t))
    nxt = torch.flip(torch.cummin(torch.flip(after, [-1]), dim=-1).values, [-1])
    nxt = torch.where(nxt >= num_t, prev, nxt)
    span = (nxt - prev).clamp_min(1)
    w = torch.where(
        nxt > prev,
        (frames - prev).double() / span.double(),
        torch.zeros_like(span, dtype=torch.float64),
    )
    return prev, nxt, w


def _gather_t(x: Tensor, index: Tensor) -> Tensor:
    """``x[b, index[b, t]]`` for ``x`` of shape ``[B, T, ...]``."""
    shape = index.shape + x.shape[2:]
    idx = index.reshape(*index.shape, *([1] * (x.dim() - 2))).expand(shape)
    return torch.gather(x, 1, idx)


def lerp_keys(x: Tensor, keys: Tensor) -> Tensor:
    """Linear interpolation of ``[B, T, ...]`` values between keyframes (only keys are read)."""
    prev, nxt, w = key_brackets(keys)
    w = w.to(x.dtype).reshape(*w.shape, *([1] * (x.dim() - 2)))
    return torch.lerp(_gather_t(x, prev), _gather_t(x, nxt), w)


def slerp_keys(q: Tensor, keys: Tensor) -> Tensor:
    """SLERP of ``[B, T, J, 4]`` quaternions (w, x, y, z) between keyframes (only keys are read)."""
    prev, nxt, w = key_brackets(keys)
    return Q.slerp(_gather_t(q, prev), _gather_t(q, nxt), w.to(q.dtype)[..., None])


def lerp_slerp(motion: Motion, keyframes: Sequence[int]) -> Motion:
    """The LERP baseline: root LERP and local-rotation SLERP between keyframes.

    Args:
        motion: The motion (only its keyframes are read).
        keyframes: Frame indices; the first must be 0.

    Returns:
        The interpolated motion (same skeleton, fps, name and units).

    Raises:
        ValueError: A keyframe is out of range or frame 0 is not one.
    """
    keys = torch.zeros(1, motion.num_frames, dtype=torch.bool)
    bad = [k for k in keyframes if not 0 <= int(k) < motion.num_frames]
    if bad:
        raise ValueError(f"keyframes {bad} are outside the motion's {motion.num_frames} frames")
    keys[0, list(keyframes)] = True
    root = lerp_keys(motion.root_positions[None], keys)[0]
    local = slerp_keys(motion.rotations[None], keys)[0]
    return Motion(motion.skeleton, local, root, motion.fps, name=motion.name, units=motion.units)
