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
    if len(segments) == 0:
        raise MatchingError("segments: nothing to inertialize")
    if len(continuations) < len(segments) - 1:
        raise MatchingError(
            f"continuations: need {len(segments) - 1} for {len(segments)} segments, "
            f"got {len(continuations)}"
        )
    if not (dt > 0 and halflife > 0):
        raise MatchingError(f"dt/halflife: must be > 0, got dt={dt}, halflife={halflife}")
    width = segments[0].shape[-1]
    for s, seg in enumerate(segments):
        if seg.dim() != 2 or seg.shape[0] == 0 or seg.shape[1] != width:
            raise MatchingError(
                f"segments[{s}]: expected [frames>0, {width}], got {tuple(seg.shape)}"
            )
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
