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

__all__ = [
    "gather_frames",
    "key_brackets",
    "lerp_keys",
    "lerp_slerp",
    "slerp_keys",
    "surrounding_keys",
]


def surrounding_keys(keys: Tensor) -> tuple[Tensor, Tensor]:
    """Index of the key at or before, and at or after, every frame (``-1`` / ``T`` if none).

    Written as a masked max/min over a ``[T, T]`` comparison instead of
    ``cummax``/``cummin``, which ONNX has no operator for, so networks that
    interpolate inside their graph (PC-MRL stage 2) export.

    Args:
        keys: ``[B, T]`` boolean keyframe mask.

    Returns:
        ``(prev [B, T], next [B, T])`` long frame indices.
    """
    num_t = keys.shape[-1]
    frames = torch.arange(num_t, device=keys.device)
    key_s = keys[:, None, :]  # [B, t, s]: is frame s a key
    before = (frames[None, :] <= frames[:, None]) & key_s  # key s at or before t
    after = (frames[None, :] >= frames[:, None]) & key_s  # key s at or after t
    prev = torch.where(before, frames, torch.full_like(frames, -1)).amax(dim=-1)
    nxt = torch.where(after, frames, torch.full_like(frames, num_t)).amin(dim=-1)
    return prev, nxt


def key_brackets(keys: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Previous key, next key and the linear weight of every frame.

    Args:
        keys: ``[B, T]`` boolean keyframe mask; frame 0 must be a key (not checked, so
            the function traces into an exported graph).

    Returns:
        ``(prev [B, T], next [B, T], w [B, T])`` with ``w`` (float32) in [0, 1], 0 on keys;
        frames after the last key use the last key on both sides (weight 0).
    """
    num_t = keys.shape[-1]
    frames = torch.arange(num_t, device=keys.device).expand_as(keys)
    prev, nxt = surrounding_keys(keys)
    nxt = torch.where(nxt >= num_t, prev, nxt)
    prev = prev.clamp_min(0)
    span = (nxt - prev).clamp_min(1)
    w = torch.where(
        nxt > prev,
        (frames - prev).float() / span.float(),
        torch.zeros_like(span, dtype=torch.float32),
    )
    return prev, nxt, w


def gather_frames(x: Tensor, index: Tensor) -> Tensor:
    """``x[b, index[b, t]]`` for ``x`` of shape ``[B, T, ...]`` and ``index`` ``[B, T']``."""
    shape = index.shape + x.shape[2:]
    idx = index.reshape(*index.shape, *([1] * (x.dim() - 2))).expand(shape)
    return torch.gather(x, 1, idx)


def lerp_keys(x: Tensor, keys: Tensor) -> Tensor:
    """Linear interpolation of ``[B, T, ...]`` values between keyframes (only keys are read)."""
    prev, nxt, w = key_brackets(keys)
    w = w.to(x.dtype).reshape(*w.shape, *([1] * (x.dim() - 2)))
    return torch.lerp(gather_frames(x, prev), gather_frames(x, nxt), w)


def slerp_keys(q: Tensor, keys: Tensor) -> Tensor:
    """SLERP of ``[B, T, J, 4]`` quaternions (w, x, y, z) between keyframes (only keys are read)."""
    prev, nxt, w = key_brackets(keys)
    return Q.slerp(gather_frames(q, prev), gather_frames(q, nxt), w.to(q.dtype)[..., None])


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
    if 0 not in [int(k) for k in keyframes]:
        raise ValueError("keyframes: frame 0 must be a keyframe")
    keys[0, list(keyframes)] = True
    root = lerp_keys(motion.root_positions[None], keys)[0]
    local = slerp_keys(motion.rotations[None], keys)[0]
    return Motion(motion.skeleton, local, root, motion.fps, name=motion.name, units=motion.units)
