"""PC-MRL stage 2: keyframe helpers and the per-window features of the interpolation model.

Keyframe brackets and LERP/SLERP between keys, the heading of a window, the
per-joint input features (:func:`window_features`, Sec. 3.4), the LERP/SLERP
baseline and the sign-invariant quaternion loss. The network is in
:mod:`~skelagnostic_pcmrl.interp.network`, the aligner in
:mod:`~skelagnostic_pcmrl.interp.aligner`; :mod:`~skelagnostic_pcmrl.interp`
re-exports all three.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.baselines.keyframes import (
    gather_frames,
    key_brackets,
    lerp_keys,
    slerp_keys,
    surrounding_keys,
)
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global, global_from_local, local_from_global
from skelagnostic_pcmrl.points import heading_frames


def sign_invariant_l1(pred: Tensor, target: Tensor) -> Tensor:
    """Mean L1 distance of quaternions ``[..., 4]`` up to sign (``q`` and ``-q`` agree)."""
    plus = (pred - target).abs().sum(-1)
    minus = (pred + target).abs().sum(-1)
    return torch.minimum(plus, minus).mean() / 4.0


def window_heading(
    global_rotations: Tensor,
    root: Tensor,
    offsets: Tensor,
    groups: Tensor,
    parents: Sequence[int],
    up: int = 1,
) -> Tensor:
    """``[B, 4]`` heading of every window: a rotation about ``up`` from its first frame.

    The first frame is always a key, so the heading uses no frame the model may
    not see. It is the ground-projected left-minus-right direction of the joints
    (:func:`~skelagnostic_pcmrl.points.heading_frames` with one frame), so it needs
    only the body groups of the joints, not a particular rig's root axes. Turning
    a window about ``up`` turns its heading with it. A skeleton without left and
    right groups gets the identity.

    Args:
        global_rotations: ``[B, T, J, 4]``.
        root: ``[B, T, 3]``.
        offsets: ``[B, J, 3]`` or ``[J, 3]`` rest offsets.
        groups: ``[J]`` body-group ids (:func:`~skelagnostic_pcmrl.points.group_of_joints`).
        parents: Parent indices.
        up: Up axis index.
    """
    pos0 = fk_from_global(global_rotations[:, :1], root[:, :1], offsets, parents)
    groups = groups.to(pos0.device).expand(pos0.shape[0], -1)
    return heading_frames(pos0, groups, up, width=1)[:, 0]


def _key_continuity(q: Tensor, keys: Tensor) -> Tensor:
    """Sign-continuous quaternions along the *keyframes* only (zeros elsewhere).

    Sign flips are removed from key to key, so the result does not depend on
    the (unknown) frames between keys.
    """
    prev_incl = surrounding_keys(keys)[0]
    prev = torch.cat([torch.full_like(prev_incl[:, :1], -1), prev_incl[:, :-1]], dim=1)
    before = gather_frames(q, prev.clamp_min(0))
    flip = keys[..., None] & (prev >= 0)[..., None] & ((q * before).sum(-1) < 0)
    parity = torch.cumsum(flip.to(torch.int64), dim=1) % 2
    sign = 1.0 - 2.0 * parity.to(q.dtype)
    return q * sign[..., None] * keys[..., None, None].to(q.dtype)


def window_features(
    global_rotations: Tensor,
    root: Tensor,
    offsets: Tensor,
    tails: Tensor,
    keys: Tensor,
    parents: Sequence[int],
    baseline: bool = False,
    interm: bool = False,
    max_relative: int = 128,
) -> dict[str, Tensor]:
    """Model inputs and targets of a batch of windows.

    Args:
        global_rotations: ``[B, T, J, 4]``.
        root: ``[B, T, 3]``.
        offsets: ``[B, J, 3]`` rest offsets.
        tails: ``[B, J, 3]`` rest bone tails.
        keys: ``[B, T]`` boolean keyframe mask (frame 0 a key).
        parents: Parent indices.
        baseline: Also compute the LERP/SLERP baseline from the keys (:func:`lerp_baseline`):
            ``base_local`` (SLERPed local rotations), ``base_foq`` and ``base_root``.
        interm: Also compute (with the baseline) ``interm_inputs [B, T, 10J + 3]``, the
            baseline pose in the layout of ``inputs`` (position minus ``center``, rest
            direction, FOQ) plus the frame's place in its gap (``w``, ``sin(pi w)``
            and the gap length over ``max_relative``).
        max_relative: Gap-length scale of ``interm_inputs``.

    Returns:
        ``inputs [B, T, 10J + 1]`` plus ``positions``, ``center [B, 1, 3]``, ``q0 [B, J, 4]``,
        ``foq_keys`` (FOQ sign-continuous along the keys, zero elsewhere: what the
        model sees), and the targets ``foq`` (sign-continuous along all frames),
        ``global`` (``foq * q0``) and ``root`` (relative to ``center``).
    """
    pos = fk_from_global(global_rotations, root, offsets, parents)
    kf = keys.to(pos.dtype)
    weight = kf[:, :, None, None].expand_as(pos[..., :1])
    center = (pos * weight).sum(dim=(1, 2)) / weight.sum(dim=(1, 2)).clamp_min(1.0)
    center = center[:, None, :]
    q0 = global_rotations[:, 0]
    raw = Q.mul(global_rotations, Q.inv(q0)[:, None])
    foq = Q.continuity(raw, dim=1)
    foq_keys = _key_continuity(raw, keys)
    local_keys = _key_continuity(local_from_global(global_rotations, parents), keys)
    norms = tails.norm(dim=-1, keepdim=True)
    unit = torch.where(norms > 1e-6, tails / norms.clamp_min(1e-6), torch.zeros_like(tails))
    direction = Q.rotate(q0, unit.to(q0))  # [B, J, 3]
    num_b, num_t, num_j = pos.shape[:3]
    per_joint = torch.cat(
        [pos - center[:, :, None], direction[:, None].expand(num_b, num_t, num_j, 3), foq_keys],
        -1,
    )
    inputs = torch.cat([per_joint.flatten(2) * kf[..., None], kf[..., None]], dim=-1)
    feats = {
        "inputs": inputs,
        "positions": pos,
        "center": center,
        "q0": q0,
        "foq": foq,
        "foq_keys": foq_keys,
        "local_keys": local_keys,
        "global": Q.mul(foq, q0[:, None]),
        "root": root - center,
    }
    if baseline or interm:
        base_local, base_foq, base_root = lerp_baseline(
            local_keys, feats["root"], q0, keys, parents
        )
        feats.update(base_local=base_local, base_foq=base_foq, base_root=base_root)
    if interm:
        base_pos = fk_from_global(Q.mul(base_foq, q0[:, None]), base_root, offsets, parents)
        base_joint = torch.cat(
            [
                base_pos,
                direction[:, None].expand(num_b, num_t, num_j, 3),
                Q.continuity(base_foq, dim=1),
            ],
            -1,
        )
        prev, nxt, w = key_brackets(keys)
        span = (nxt - prev).to(pos.dtype) / float(max_relative)
        w = w.to(pos.dtype)
        place = torch.stack([w, torch.sin(math.pi * w), span], dim=-1)
        feats["interm_inputs"] = torch.cat([base_joint.flatten(2), place], dim=-1)
    return feats


def lerp_baseline(
    local_keys: Tensor, root: Tensor, q0: Tensor, keys: Tensor, parents: Sequence[int]
) -> tuple[Tensor, Tensor, Tensor]:
    """The LERP baseline of a window from its keys: local rotations, FOQ and root.

    Local rotations are SLERPed between the surrounding keys (global rotations by
    FK), the root is LERPed; only keyframe values are read.

    Args:
        local_keys: ``[B, T, J, 4]`` local rotations, sign-continuous along the keys.
        root: ``[B, T, 3]`` root positions.
        q0: ``[B, J, 4]`` first-frame global rotations.
        keys: ``[B, T]`` boolean keyframe mask.
        parents: Parent indices.

    Returns:
        ``(local [B, T, J, 4], foq [B, T, J, 4], root [B, T, 3])``.
    """
    local = slerp_keys(local_keys, keys)
    base = global_from_local(local, parents)
    return local, Q.mul(base, Q.inv(q0)[:, None]), lerp_keys(root, keys)
