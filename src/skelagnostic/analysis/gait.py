"""Gait rhythm from the feet alone: stride frequency, touch-down rates, gait phase, locking.

Every figure here is measured on the motion itself (no model is involved), for any
rig: the feet are found by :func:`~skelagnostic.analysis.touchdowns.foot_joints`,
their touch-downs by :func:`~skelagnostic.analysis.touchdowns.motion_onsets`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import torch

from skelagnostic.analysis._frames import root_frame_positions
from skelagnostic.analysis.touchdowns import foot_joints, motion_onsets
from skelagnostic.core.motion import Motion

__all__ = [
    "GAIT_PHASE_MAX_STRIDE",
    "TOUCHDOWN_MAX_INTERVAL",
    "contact_frequency",
    "contact_lock",
    "forward_swings",
    "gait_frequency",
    "gait_phase",
    "onset_rate",
    "rate_in_runs",
    "touchdown_frequency",
]

#: Longest interval (seconds) between two touch-downs that :func:`gait_phase` spans.
GAIT_PHASE_MAX_STRIDE = 2.0

#: Longest interval (s) between a foot's consecutive touch-downs that
#: :func:`touchdown_frequency` reads as one stride (slower than 0.5 Hz is no gait).
TOUCHDOWN_MAX_INTERVAL = 2.0


def onset_rate(onsets: Sequence[np.ndarray], fps: float) -> float:
    """Events per second and foot: intervals between each foot's first and last event.

    Counts the touch-downs of :func:`contact_frequency` and the forward swings of
    :func:`gait_frequency` alike; NaN when no foot has two events.

    Example:
        >>> onset_rate([np.array([0.0, 10.0, 20.0]), np.array([5.0])], fps=30.0)
        3.0
    """
    intervals = sum(max(len(o) - 1, 0) for o in onsets)
    span = sum(float(o[-1] - o[0]) for o in onsets if len(o) >= 2)
    return float(fps * intervals / span) if intervals and span > 0 else math.nan


def rate_in_runs(
    onsets: Sequence[np.ndarray], runs: Sequence[tuple[float, float]], fps: float
) -> float:
    """Touch-downs per second and foot inside ``runs`` (frames of the onsets' clip)."""
    seconds = sum(b - a for a, b in runs) / fps
    if not onsets or seconds <= 0:
        return math.nan
    count = sum(int(((o >= a) & (o < b)).sum()) for o in onsets for a, b in runs)
    return count / len(onsets) / seconds


def gait_frequency(motion: Motion, hysteresis: float = 0.25) -> float:
    """Gait (stride) frequency in Hz, measured from the feet alone.

    Each foot (:func:`~skelagnostic.analysis.touchdowns.foot_joints`) swings forward
    once per stride: its horizontal position in the character's root frame (as
    :class:`~skelagnostic.representations.GlobalPositions` ``frame="root"``),
    projected on its main (fore-aft) direction, crosses its mean upwards once per
    cycle. The crossings are found with hysteresis (the signal must go below
    ``-hysteresis`` and above ``+hysteresis`` standard deviations) and timed to a
    fraction of a frame; the frequency is the number of forward swings per
    second between each foot's first and last swing (summed over the feet):
    how many strides the motion makes, whatever replays or cuts it is made of.
    Nothing of any model is used.

    Args:
        motion: A clip of a few strides.
        hysteresis: Half-width of the dead band, in standard deviations.

    Returns:
        The frequency in Hz, or NaN when no foot completes two forward swings.

    Example:
        >>> from skelagnostic import procedural
        >>> clip, info = procedural.generate("quadruped", "trot", seconds=6.0, fps=60, seed=3)
        >>> abs(gait_frequency(clip) / info["frequency"] - 1) < 0.02
        True
    """
    return onset_rate(forward_swings(motion, hysteresis), motion.fps)


def forward_swings(motion: Motion, hysteresis: float = 0.25) -> list[np.ndarray]:
    """When each foot swings forward (fractional frames): one event per stride and foot.

    The events :func:`gait_frequency` counts: each foot's
    (:func:`~skelagnostic.analysis.touchdowns.foot_joints`) root-local horizontal
    position, projected on its main (fore-aft) direction, crossing its mean upwards,
    found with hysteresis (below ``-hysteresis`` then above ``+hysteresis`` standard
    deviations) and timed to a fraction of a frame.

    Returns:
        One array of crossing times (frames) per foot of ``foot_joints``, empty for a
        foot that does not move.
    """
    feet = foot_joints(motion)
    up = motion.skeleton.up_index
    flat = [a for a in range(3) if a != up]
    positions = root_frame_positions(motion).double().numpy()
    swings = []
    for foot in feet:
        x = positions[:, foot, flat]
        x = x - x.mean(0, keepdims=True)
        _, _, axes = np.linalg.svd(x, full_matrices=False)
        signal = x @ axes[0]
        std = float(signal.std())
        if std <= 1e-9:
            swings.append(np.zeros(0))
            continue
        crossings, armed = [], False
        for t in range(1, len(signal)):
            if signal[t] < -hysteresis * std:
                armed = True
            elif armed and signal[t - 1] < 0 <= signal[t]:
                crossings.append(t - 1 + signal[t - 1] / (signal[t - 1] - signal[t]))
                armed = False
        swings.append(np.asarray(crossings))
    return swings


def contact_frequency(motion: Motion) -> float:
    """Foot-contact frequency in Hz: touch-downs per second of each foot.

    :func:`~skelagnostic.analysis.touchdowns.motion_onsets` of the feet, counted like
    :func:`gait_frequency` counts swings (intervals between each foot's first and
    last touch-down, summed over the feet). On captured steady gaits each foot
    touches down once per stride, so this is the stride frequency measured from the
    feet's heights instead of their fore-aft swing (within a few % on the LaFAN1
    walks and MANN dog gaits of the tests). The procedural generator's feet are not
    grounded: they dip twice per stride, so on its clips this reads up to twice the
    stride frequency. Nothing of any model is used.

    Returns:
        Hz, or NaN when no foot touches down twice.
    """
    return onset_rate(motion_onsets(motion), motion.fps)


def touchdown_frequency(
    motion: Motion, max_interval: float = TOUCHDOWN_MAX_INTERVAL
) -> torch.Tensor:
    """Per-frame stride frequency from the feet's touch-downs (Hz; NaN where none steps).

    For every foot (:func:`~skelagnostic.analysis.touchdowns.motion_onsets`), a frame
    between two consecutive touch-downs at most ``max_interval`` seconds apart gets
    ``fps / interval``; a frame covered by several feet gets their mean. Nothing of
    any model is used.

    Returns:
        ``[F]`` float32, NaN on frames no foot's stride covers.

    Example:
        >>> from skelagnostic import procedural
        >>> dog, _ = procedural.generate("quadruped", "walk", seconds=6.0, fps=30, seed=3)
        >>> f = touchdown_frequency(dog)  # per frame; the clip's rate is contact_frequency
        >>> bool(abs(float(f.nanmean()) / contact_frequency(dog) - 1) < 0.05)
        True
    """
    frames = motion.num_frames
    total, count = np.zeros(frames), np.zeros(frames)
    for onsets in motion_onsets(motion):
        for a, b in itertools.pairwise(onsets.tolist()):
            if not 0 < (b - a) / motion.fps <= max_interval:
                continue
            lo, hi = math.ceil(a), min(math.floor(b), frames - 1)
            total[lo : hi + 1] += motion.fps / (b - a)
            count[lo : hi + 1] += 1
    out = np.full(frames, np.nan)
    np.divide(total, count, out=out, where=count > 0)
    return torch.from_numpy(out).float()


def gait_phase(motion: Motion, max_stride: float = GAIT_PHASE_MAX_STRIDE) -> np.ndarray:
    """``[F]`` gait phase in cycles, ``[0, 1)``, measured from the feet alone.

    The reference foot is the one with the most touch-downs
    (:func:`~skelagnostic.analysis.touchdowns.motion_onsets`); between two successive
    touch-downs at most ``max_stride`` seconds apart the phase rises linearly from 0
    to 1. It is the phase a perfect phase manifold would read from the stride;
    nothing of any model is used.

    Args:
        motion: A clip.
        max_stride: Longest interval between touch-downs (s) that counts as a stride.

    Returns:
        The phase per frame; NaN before the first touch-down, after the last, in a
        longer pause, and on every frame when no foot steps.

    Example:
        >>> from skelagnostic import procedural
        >>> clip, _ = procedural.generate("quadruped", "walk", seconds=4.0, fps=30, seed=0)
        >>> phase = gait_phase(clip)
        >>> bool(np.nanmin(phase) >= 0 and np.nanmax(phase) < 1), bool(np.isfinite(phase).any())
        (True, True)
    """
    frames = motion.num_frames
    phase = np.full(frames, np.nan)
    onsets = motion_onsets(motion)
    if not onsets:
        return phase
    ref = max(onsets, key=len)
    for start, end in itertools.pairwise(ref):
        if (end - start) / motion.fps > max_stride:
            continue
        idx = np.arange(math.ceil(start), min(math.ceil(end), frames))
        phase[idx] = (idx - start) / (end - start)
    return phase


def contact_lock(source_onsets: Sequence[np.ndarray], output_onsets: Sequence[np.ndarray]) -> float:
    """How steadily the output's touch-downs keep their place in the source's stride cycle.

    The source's cycle is read from its first foot with at least two onsets: cycle
    ``k`` runs from its ``k``-th to its ``k+1``-th touch-down, so the source's phase at
    any time between them is ``(t - o_k) / (o_{k+1} - o_k)`` (the source's own tempo,
    even when it changes). Each output foot's touch-downs inside that span get a
    source phase; the lock of the foot is the length of the mean of
    ``exp(2 pi i phase)`` (1: every touch-down of that foot at the same point of the
    source's cycle, one per cycle or a whole multiple; about 0: no relation). The
    result is the mean over the output feet with at least two such touch-downs. It
    does not need to know which output foot matches which source foot, nor the lag.

    Args:
        source_onsets: Onset times (frames) per source foot
            (:func:`~skelagnostic.analysis.touchdowns.contact_onsets`).
        output_onsets: The same for the output, on the same time axis.

    Returns:
        A value in [0, 1], NaN when either side has too few touch-downs.

    Example:
        >>> src = [np.array([0.0, 10.0, 20.0, 30.0])]
        >>> round(contact_lock(src, [np.array([3.0, 13.0, 23.0])]), 6)  # lag 0.3 cycle
        1.0
        >>> round(contact_lock(src, [np.array([3.0, 18.0, 28.0])]), 3)  # one off by half
        0.333
    """
    reference = next((np.sort(o) for o in source_onsets if len(o) >= 2), None)
    if reference is None:
        return math.nan
    locks = []
    for onsets in output_onsets:
        inside = onsets[(onsets >= reference[0]) & (onsets < reference[-1])]
        if len(inside) < 2:
            continue
        k = np.searchsorted(reference, inside, side="right") - 1
        phase = (inside - reference[k]) / (reference[k + 1] - reference[k])
        locks.append(float(np.abs(np.exp(2j * math.pi * phase).mean())))
    return float(np.mean(locks)) if locks else math.nan
