"""Inertialization: hide the jump at a transition with a decaying offset.

At a transition from a source animation to a destination animation, the
difference between where the source would have continued and where the
destination starts (position *and* velocity) is stored as an offset, added to the
destination, and decayed to zero with a critically damped spring (Bollo 2016,
"Inertialization: High-Performance Animation Transitions in Gears of War"; the
exact spring decay of Holden's Motion-Matching code). With ``x0, v0`` the offset
at the transition and ``y = 2 ln 2 / halflife``::

    x(t) = exp(-y t) (x0 + (v0 + y x0) t)
    v(t) = exp(-y t) (v0 - (v0 + y x0) y t)

so the output is continuous in value and velocity and the offset is halved
(roughly) every ``halflife`` seconds. Offsets still active at the next transition
are carried over, so quick successive transitions stay smooth.

:func:`inertialize` treats features as vectors (root positions, descriptors);
:func:`inertialize_rotations` does the same for unit quaternions, with the offset
kept as a rotation vector and applied on the left, ``exp(x(t)) * q(t)`` (Holden's
quaternion inertialization).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from skelagnostic.matching._errors import MatchingError


def decay_offset(
    x0: torch.Tensor, v0: torch.Tensor, t: torch.Tensor, halflife: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Critically damped decay of an offset and its velocity.

    Args:
        x0: ``[D]`` offset at time 0.
        v0: ``[D]`` offset velocity at time 0 (units per second).
        t: ``[n]`` times in seconds.
        halflife: Time in seconds for the offset to decay by about half (> 0).

    Returns:
        ``(x [n, D], v [n, D])`` the offset and its velocity at the given times.

    Examples:
        >>> import torch
        >>> x, v = decay_offset(torch.ones(1), torch.zeros(1), torch.tensor([0.0, 10.0]), 0.1)
        >>> [round(float(a), 4) for a in x[:, 0]]
        [1.0, 0.0]
    """
    y = 2.0 * math.log(2.0) / halflife
    t = t[:, None]
    j1 = v0 + y * x0
    decay = torch.exp(-y * t)
    return decay * (x0 + j1 * t), decay * (v0 - j1 * y * t)


def inertialize(
    segments: Sequence[torch.Tensor],
    continuations: Sequence[torch.Tensor],
    dt: float,
    halflife: float,
) -> torch.Tensor:
    """Concatenate played segments, inertializing every transition between them.

    Args:
        segments: ``S`` tensors ``[n_s, D]``: the frames played from each source,
            in order.
        continuations: At least ``S - 1`` tensors ``[2, D]``: the two frames segment
            ``s`` would have played next had there been no transition (its
            source's continuation; the second one gives the source velocity, so
            repeat the first at the end of a clip). Extra entries are ignored.
        dt: Seconds per frame.
        halflife: Decay halflife in seconds (> 0).

    Returns:
        ``[sum n_s, D]`` the output, equal to the first segment on its frames and
        continuous in value and velocity at every transition.

    Raises:
        MatchingError: On an empty segment list, empty segments, mismatched widths or
            a non-positive ``dt``/``halflife``.

    Examples:
        >>> import torch
        >>> a = torch.zeros(5, 1)
        >>> b = torch.ones(5, 1)  # a jump of 1 at the transition
        >>> out = inertialize([a, b], [torch.zeros(2, 1)], dt=1 / 30, halflife=0.1)
        >>> float(out[5, 0])  # the first destination frame continues the source
        0.0
        >>> 0.0 < float(out[9, 0]) < 1.0
        True
    """
    width = _check_segments(segments, continuations, dt, halflife, trailing=1)
    out = [segments[0]]
    x = torch.zeros(width, dtype=torch.float64, device=segments[0].device)
    v = torch.zeros_like(x)
    for s in range(1, len(segments)):
        seg = segments[s].double()
        cont = continuations[s - 1].double().reshape(2, width)
        elapsed = x.new_tensor([segments[s - 1].shape[0] * dt])
        x, v = (c[0] for c in decay_offset(x, v, elapsed, halflife))
        # forward differences on both sides, so an unbroken replay gets no offset
        src_v = (cont[1] - cont[0]) / dt
        dst_v = (seg[1] - seg[0]) / dt if seg.shape[0] > 1 else torch.zeros_like(x)
        x = x + cont[0] - seg[0]
        v = v + src_v - dst_v
        times = torch.arange(seg.shape[0], dtype=torch.float64, device=x.device) * dt
        offset, _ = decay_offset(x, v, times, halflife)
        out.append((seg + offset).to(segments[s].dtype))
    return torch.cat(out)


def _check_segments(
    segments: Sequence[torch.Tensor],
    continuations: Sequence[torch.Tensor],
    dt: float,
    halflife: float,
    trailing: int,
) -> int:
    """Check the arguments of the two inertializers and return the segments' width.

    ``trailing`` is 1 for :func:`inertialize` (``[n, D]`` segments) and 2 for
    :func:`inertialize_rotations` (``[n, J, 4]``).
    """
    if len(segments) == 0:
        raise MatchingError("segments: nothing to inertialize")
    if len(continuations) < len(segments) - 1:
        raise MatchingError(
            f"continuations: need {len(segments) - 1} for {len(segments)} segments, "
            f"got {len(continuations)}"
        )
    if not (dt > 0 and halflife > 0):
        raise MatchingError(f"dt/halflife: must be > 0, got dt={dt}, halflife={halflife}")
    shape = tuple(segments[0].shape[1:])
    expected = "[frames>0, " + ", ".join(str(d) for d in shape) + "]"
    for s, seg in enumerate(segments):
        if seg.dim() != 1 + trailing or seg.shape[0] == 0 or tuple(seg.shape[1:]) != shape:
            raise MatchingError(f"segments[{s}]: expected {expected}, got {tuple(seg.shape)}")
    if trailing == 2 and shape[-1] != 4:
        raise MatchingError(f"segments: expected quaternions [frames, joints, 4], got {shape}")
    for s, cont in enumerate(continuations[: len(segments) - 1]):
        if tuple(cont.shape) != (2, *shape):
            raise MatchingError(
                f"continuations[{s}]: expected {(2, *shape)}, got {tuple(cont.shape)}"
            )
    return shape[0]


def _to_rotvec(q: torch.Tensor) -> torch.Tensor:
    """Scaled axis-angle of unit (w, x, y, z) quaternions (shortest arc)."""
    q = torch.where(q[..., :1] < 0, -q, q)
    xyz = q[..., 1:]
    norm = torch.linalg.vector_norm(xyz, dim=-1, keepdim=True)
    angle = 2 * torch.atan2(norm, q[..., :1])
    scale = torch.where(norm > 1e-12, angle / norm.clamp_min(1e-12), torch.full_like(norm, 2.0))
    return xyz * scale


def _from_rotvec(v: torch.Tensor) -> torch.Tensor:
    """Unit (w, x, y, z) quaternions from scaled axis-angle vectors."""
    angle = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    half = 0.5 * angle
    small = torch.full_like(angle, 0.5)  # sin(a / 2) / a -> 1 / 2
    scale = torch.where(angle > 1e-12, torch.sin(half) / angle.clamp_min(1e-12), small)
    return torch.cat([torch.cos(half), v * scale], dim=-1)


def inertialize_rotations(
    segments: Sequence[torch.Tensor],
    continuations: Sequence[torch.Tensor],
    dt: float,
    halflife: float,
) -> torch.Tensor:
    """Concatenate played rotation segments, inertializing every transition between them.

    The rotation counterpart of :func:`inertialize`: at a transition the offset is
    the rotation from the new segment's first frame to where the previous one would
    have continued (with its own offset still applied), as a rotation vector ``x0``;
    its angular velocity offset ``v0`` is the difference of the two sides' forward
    differences. Both decay with :func:`decay_offset` and the output frame is
    ``exp(x(t)) * q(t)`` per joint.

    Args:
        segments: ``S`` tensors ``[n_s, J, 4]`` of unit (w, x, y, z) quaternions (local
            joint rotations), in order.
        continuations: At least ``S - 1`` tensors ``[2, J, 4]``: the two frames segment
            ``s`` would have played next (repeat the first at the end of a clip).
        dt: Seconds per frame.
        halflife: Decay halflife in seconds (> 0).

    Returns:
        ``[sum n_s, J, 4]`` unit quaternions, equal to the first segment on its
        frames and continuous in rotation and angular velocity at every transition.

    Raises:
        MatchingError: On an empty segment list, empty segments, shapes that are not
            ``[frames, J, 4]`` alike, or a non-positive ``dt``/``halflife``.

    Examples:
        >>> import math, torch
        >>> still = torch.tensor([1.0, 0.0, 0.0, 0.0]).expand(5, 1, 4)
        >>> half_turn = torch.tensor([0.0, 0.0, 1.0, 0.0]).expand(5, 1, 4)  # 180 deg about y
        >>> out = inertialize_rotations([still, half_turn], [still[:2]], 1 / 30, 0.1)
        >>> [round(float(w), 3) for w in out[4:6, 0, 0]]  # the cut frame continues `still`
        [1.0, 1.0]
        >>> 0.0 < abs(float(out[8, 0, 0])) < 1.0  # then turns towards the new segment
        True
    """
    from skelagnostic.core import quaternion as Q

    joints = _check_segments(segments, continuations, dt, halflife, trailing=2)
    out = [segments[0]]
    x = segments[0].new_zeros(joints, 3)
    v = torch.zeros_like(x)
    for s in range(1, len(segments)):
        seg, cont = segments[s], continuations[s - 1]
        elapsed = x.new_tensor([segments[s - 1].shape[0] * dt])
        x, v = (c[0] for c in decay_offset(x, v, elapsed, halflife))
        # offset rotation: where the old replay (with its offset) would be, relative to the new
        carried = Q.mul(_from_rotvec(x), cont[0])
        x = _to_rotvec(Q.mul(carried, Q.inv(seg[0])))
        src_v = _to_rotvec(Q.mul(cont[1], Q.inv(cont[0]))) / dt
        dst_v = (
            _to_rotvec(Q.mul(seg[1], Q.inv(seg[0]))) / dt
            if seg.shape[0] > 1
            else torch.zeros_like(x)
        )
        v = v + src_v - dst_v
        times = torch.arange(seg.shape[0], dtype=x.dtype, device=x.device) * dt
        offset, _ = decay_offset(x.reshape(-1), v.reshape(-1), times, halflife)
        out.append(Q.mul(_from_rotvec(offset.reshape(-1, joints, 3)), seg))
    return torch.cat(out)
