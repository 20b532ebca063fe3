"""When feet touch down: touch-down times from foot heights, and the feet that step.

:func:`foot_joints` finds a character's feet from where its end effectors move
(no names needed), :func:`contact_onsets` times each foot's touch-downs from its
height alone, scaled by the foot's own local range, so the same rule serves a
human's toes and a dog's paws. :func:`motion_onsets` puts both together for a clip.
"""

from __future__ import annotations

import numpy as np

from skelagnostic.analysis._frames import root_frame_positions
from skelagnostic.core.motion import Motion

__all__ = [
    "CONTACT_ENTER",
    "CONTACT_MIN_LIFT",
    "CONTACT_WINDOW",
    "contact_onsets",
    "foot_heights",
    "foot_joints",
    "motion_onsets",
]

#: Contact rule of :func:`contact_onsets`: a foot touches down when its height above its
#: local lowest drops below this share of its local height range (and lifts off above twice
#: that).
CONTACT_ENTER = 0.25

#: Seconds of the centred window over which :func:`contact_onsets` takes a foot's local
#: lowest and highest level (about one stride of a walk).
CONTACT_WINDOW = 1.0

#: Smallest local height range of a foot that counts as stepping, in skeleton heights.
CONTACT_MIN_LIFT = 0.02


def foot_joints(motion: Motion, max_height: float = 0.35) -> list[int]:
    """The end effectors that stay near the ground: the feet (or toes) of a character.

    Args:
        motion: A clip.
        max_height: Largest mean height over the ground, as a share of the skeleton height
            (a quadruped's height is that of its shoulders and hips, its head held level:
            the MANN dog's ankle joints move about 11 cm above the ground, 26 % of 43 cm).

    Returns:
        Joint indices: every end effector whose mean height above the root's ground
        projection is below ``max_height`` of the skeleton height, else the two lowest.
    """
    skeleton = motion.skeleton
    ends = skeleton.end_effectors()
    heights = root_frame_positions(motion)[:, ends, skeleton.up_index].mean(0)
    scale = max(skeleton.height(), 1e-9)
    feet = [j for j, h in zip(ends, heights.tolist(), strict=True) if h < max_height * scale]
    if feet:
        return feet
    return [ends[k] for k in heights.argsort()[:2].tolist()]


def contact_onsets(
    heights: np.ndarray,
    fps: float,
    min_lift: float,
    enter: float = CONTACT_ENTER,
    window: float = CONTACT_WINDOW,
) -> list[np.ndarray]:
    """Touch-down times (fractional frames) of each foot, from its height over time.

    Each foot's height is measured from its local lowest level and scaled by its local
    range (minimum and maximum over a centred ``window`` of seconds), so the rule is the
    same for a human's toes and a dog's paws, needs no ground plane and follows a
    floor that changes (steps, obstacles). A foot is in contact below ``enter`` of its
    range and lifted above ``2 * enter`` (hysteresis), and only while its local range
    reaches ``min_lift`` (a foot that stays put does not step); each touch-down is
    timed to a fraction of a frame by linear interpolation at the ``enter`` level.

    Args:
        heights: ``[F, N]`` height of N feet.
        fps: Frame rate.
        min_lift: Smallest local range of a stepping foot, in the units of ``heights``.
        enter: Contact level, share of the local range.
        window: Seconds of the centred window of the local range.

    Returns:
        One array of onset times (frames) per foot.

    Example:
        >>> t = np.arange(400) / 100.0
        >>> feet = np.stack([np.sin(np.pi * 1.5 * t) ** 2], 1)  # one foot, 1.5 steps/s
        >>> onsets = contact_onsets(feet, fps=100.0, min_lift=0.1)[0]
        >>> np.round(np.diff(onsets) / 100.0, 2).tolist()
        [0.67, 0.67, 0.67, 0.67, 0.67]
    """
    from numpy.lib.stride_tricks import sliding_window_view

    half = max(1, round(window * fps / 2))
    out = []
    for h in np.asarray(heights, dtype=np.float64).T:
        padded = sliding_window_view(np.pad(h, half, mode="edge"), 2 * half + 1)
        low, span = padded.min(1), np.ptp(padded, axis=1)
        stepping = span >= min_lift
        level = np.where(stepping, (h - low) / np.maximum(span, 1e-12), 0.0)
        onsets, lifted = [], False
        for t in range(1, len(level)):
            if stepping[t] and level[t] > 2 * enter:
                lifted = True
            elif lifted and level[t - 1] >= enter > level[t]:
                onsets.append(t - 1 + (level[t - 1] - enter) / (level[t - 1] - level[t]))
                lifted = False
        out.append(np.asarray(onsets))
    return out


def foot_heights(motion: Motion) -> np.ndarray:
    """``[F, N]`` heights (along the up axis) of the feet (:func:`foot_joints`)."""
    feet = foot_joints(motion)
    up = motion.skeleton.up_index
    return motion.global_positions()[:, feet, up].double().numpy()


def motion_onsets(motion: Motion) -> list[np.ndarray]:
    """Touch-down times (frames) of a clip's feet (:func:`contact_onsets`).

    A stepping foot lifts at least :data:`CONTACT_MIN_LIFT` of the skeleton height.
    """
    min_lift = CONTACT_MIN_LIFT * max(motion.skeleton.height(), 1e-9)
    return contact_onsets(foot_heights(motion), motion.fps, min_lift)
