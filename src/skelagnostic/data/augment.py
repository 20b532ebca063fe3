"""Augmentation of training windows: mirror, yaw about the up axis, speed change.

What ``data.augment.*`` sets (:class:`Augmentation`). Each training window draws
its own transform from a generator seeded by ``(seed, epoch, window index)``
(:func:`window_rng`), never from the global random state, so a window gets the same
transform whatever the number of data-loader workers or DDP processes. The
transforms act on the motion before the representation encodes it: the window
cache holds encoded features, so an augmenting dataset reads the clip's resampled
motion from a second cache entry (:func:`motion_frames`, one per clip), cuts the
source span of the window, transforms it and encodes it (:class:`WindowAugmenter`).

* **mirror** (:meth:`Motion.mirror <skelagnostic.Motion.mirror>`): left and right
  swap through the skeleton's body groups (:meth:`Skeleton.mirror_map
  <skelagnostic.Skeleton.mirror_map>`); a skeleton without left/right pairs is not
  mirrored.
* **yaw** (:func:`rotate_yaw`): the whole window, root trajectory included, turns
  about the vertical line through its first root position.
* **speed** (:func:`change_speed`): a source span ``factor`` times the window's
  duration is resampled to the window's frame count with
  :meth:`Motion.resample <skelagnostic.Motion.resample>` (slerp for rotations,
  lerp for positions), so the motion plays ``factor`` times faster.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.data.cache import CacheEntry
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import MotionRepresentation

__all__ = [
    "MOTION_LAYOUT",
    "SPEED_RANGE",
    "Augmentation",
    "Draw",
    "WindowAugmenter",
    "change_speed",
    "frames_motion",
    "motion_frames",
    "plan_span",
    "rotate_yaw",
    "window_rng",
]

#: Layout of the cached motion entries (:func:`motion_frames`); part of their cache key.
MOTION_LAYOUT = "local-rotations-root-translations-v1"
#: Smallest and largest speed factor ``data.augment.speed`` accepts.
SPEED_RANGE = (0.25, 4.0)


class Draw(NamedTuple):
    """The transform one window gets (:meth:`Augmentation.draw`)."""

    #: Whether the window is mirrored.
    mirror: bool
    #: Rotation about the up axis, radians.
    yaw: float
    #: Speed factor (> 1: faster).
    speed: float


def window_rng(seed: int, epoch: int, index: int) -> np.random.Generator:
    """The generator of one window's augmentation, from ``(seed, epoch, window index)`` only."""
    return np.random.default_rng([int(seed) % 2**32, int(epoch) % 2**32, int(index)])


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SkelagnosticError(f"data.augment.{field} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Augmentation:
    """The augmentation options of training windows (``data.augment.*``); off by default.

    Attributes:
        mirror: Probability that a window is mirrored, in ``[0, 1]``.
        yaw: Largest rotation about the up axis, degrees in ``[0, 180]``: each window
            turns by an angle drawn uniformly in ``[-yaw, yaw]`` (0: off).
        speed: ``(low, high)`` speed factors within :data:`SPEED_RANGE`, or ``None``
            (off): each window plays at a factor drawn log-uniformly in the range.
    """

    mirror: float = 0.0
    yaw: float = 0.0
    speed: tuple[float, float] | None = None

    @classmethod
    def parse(cls, options: Augmentation | Mapping[str, Any] | None) -> Augmentation:
        """The options of a ``data.augment`` mapping, checked.

        ``yaw`` may be ``true`` (any angle: 180), ``false`` (off) or degrees;
        ``speed`` a pair ``[low, high]``, one factor, or ``null``.

        Raises:
            SkelagnosticError: An unknown key or a bad value (names ``data.augment.<key>``).
        """
        if options is None or isinstance(options, Augmentation):
            return options or cls()
        if not isinstance(options, Mapping):
            raise SkelagnosticError(
                f"data.augment must be a mapping of mirror, yaw and speed, got {options!r}"
            )
        for key in options:
            if key not in ("mirror", "yaw", "speed"):
                raise SkelagnosticError(
                    f"data.augment.{key} is not an augmentation option; known: mirror, yaw, speed"
                )
        mirror = _number(options.get("mirror", 0.0), "mirror")
        if not 0 <= mirror <= 1:
            raise SkelagnosticError(f"data.augment.mirror must be in [0, 1], got {mirror:g}")
        yaw = options.get("yaw", False)
        yaw = (180.0 if yaw else 0.0) if isinstance(yaw, bool) else _number(yaw, "yaw")
        if not 0 <= yaw <= 180:
            raise SkelagnosticError(
                f"data.augment.yaw must be true, false or degrees in [0, 180], got {yaw:g}"
            )
        return cls(mirror, yaw, _speed_range(options.get("speed")))

    @property
    def enabled(self) -> bool:
        """Whether any transform is on."""
        return self.mirror > 0 or self.yaw > 0 or self.speed is not None

    def draw(self, seed: int, epoch: int, index: int) -> Draw:
        """The transform of window ``index`` in ``epoch`` of a run seeded ``seed``."""
        rng = window_rng(seed, epoch, index)
        u_mirror, u_yaw, u_speed = rng.random(3)
        speed = 1.0
        if self.speed is not None:
            low, high = (math.log(s) for s in self.speed)
            speed = math.exp(low + (high - low) * u_speed)
        yaw = math.radians(self.yaw) * (2.0 * u_yaw - 1.0)
        return Draw(bool(u_mirror < self.mirror), yaw, speed)


def _speed_range(value: Any) -> tuple[float, float] | None:
    if value is None:
        return None
    pair = [value, value] if isinstance(value, (int, float)) else value
    if not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2:
        raise SkelagnosticError(
            f"data.augment.speed must be [low, high] speed factors or null, got {value!r}"
        )
    low, high = (_number(v, "speed") for v in pair)
    if not SPEED_RANGE[0] <= low <= high <= SPEED_RANGE[1]:
        raise SkelagnosticError(
            f"data.augment.speed=[{low:g}, {high:g}]: need {SPEED_RANGE[0]:g} <= low <= high "
            f"<= {SPEED_RANGE[1]:g}"
        )
    return None if low == high == 1.0 else (low, high)


# ---------------------------------------------------------------------- transforms
def rotate_yaw(motion: Motion, angle: float, pivot: torch.Tensor | None = None) -> Motion:
    """``motion`` turned by ``angle`` radians about the up axis, root trajectory included.

    Args:
        motion: Any motion.
        angle: Counter-clockwise angle seen from above, radians.
        pivot: ``[3]`` a point of the vertical axis of rotation (default: the first
            frame's root position).

    Returns:
        The motion with its root rotation and root positions turned.
    """
    q = torch.zeros(4, dtype=torch.float64)
    q[0], q[1 + motion.skeleton.up_index] = math.cos(angle / 2), math.sin(angle / 2)
    q = q.to(motion.rotations)
    root = motion.root_positions
    centre = root[0] if pivot is None else pivot.to(root)
    rotations = motion.rotations.clone()
    rotations[:, 0] = Q.mul(q, rotations[:, 0])
    return Motion(
        motion.skeleton,
        rotations,
        Q.rotate(q, root - centre) + centre,
        motion.fps,
        translations=motion.translations,
        name=motion.name,
        units=motion.units,
    )


def change_speed(motion: Motion, factor: float, frames: int) -> Motion:
    """The first ``frames`` frames of ``motion`` played ``factor`` times faster, same fps.

    Frame ``k`` of the result is the motion at source frame ``k * factor``
    (:meth:`Motion.resample <skelagnostic.Motion.resample>`: slerp between the
    rotations, lerp between the positions).

    Raises:
        SkelagnosticError: ``motion`` is shorter than ``(frames - 1) * factor + 1`` frames.
    """
    if factor == 1.0:
        out = motion
    else:
        out = motion.resample(motion.fps / factor)
    if out.num_frames < frames:
        raise SkelagnosticError(
            f"change_speed: {motion.num_frames} frames at speed {factor:g} give {out.num_frames} "
            f"frames, {frames} asked"
        )
    out = out[:frames]
    return Motion(
        out.skeleton,
        out.rotations,
        out.root_positions,
        motion.fps,
        translations=out.translations,
        name=motion.name,
        units=motion.units,
    )


def plan_span(
    start: int, num_frames: int, window: int, speed: float, lead: int
) -> tuple[int, int, int, float]:
    """The source frames an augmented window is cut from.

    The window of ``window`` frames, plus ``lead`` frames before it (the context a
    representation such as velocities reads), covers ``(window + lead - 1) * speed``
    source frames. The span starts ``lead`` frames before ``start`` (moved back
    when it would pass the clip's end); the lead is dropped at the clip's start and
    the speed lowered when the clip is too short for it.

    Args:
        start: First frame of the window in the clip.
        num_frames: Frames of the clip (at least ``window``).
        window: Frames of the window.
        speed: Speed factor drawn for the window.
        lead: Context frames asked before the window (0 or 1).

    Returns:
        ``(first source frame, source frames, lead frames, speed)``.
    """
    lead = min(lead, start)
    steps = window + lead - 1
    if steps and lead and speed * steps > num_frames - 1:
        lead, steps = 0, window - 1
    if steps:
        speed = min(speed, (num_frames - 1) / steps * (1 - 1e-9))
        count = min(num_frames, math.ceil(speed * steps) + 1)
    else:
        count = 1
    return max(0, min(start - lead, num_frames - count)), count, lead, speed


# ------------------------------------------------------------- cached raw motion
def motion_frames(motion: Motion) -> np.ndarray:
    """``[1, T, R, 4]`` float32 of a motion for the cache (:func:`frames_motion` reads it).

    Rows: the ``J`` local rotations, the root position (padded with 0), then, if the
    motion has them, the ``J`` animated translations (padded with 0).
    """
    m = motion.float()
    rows = [m.rotations, F.pad(m.root_positions, (0, 1))[:, None]]
    if m.translations is not None:
        rows.append(F.pad(m.translations, (0, 1)))
    return torch.cat(rows, dim=1).numpy()[None]


def frames_motion(values: np.ndarray, skeleton: Skeleton, fps: float, units: str | None) -> Motion:
    """The motion of ``[T, R, 4]`` rows written by :func:`motion_frames`."""
    t = torch.from_numpy(values)
    j = skeleton.num_joints
    translations = t[:, j + 1 :, :3] if t.shape[1] > j + 1 else None
    return Motion(skeleton, t[:, :j], t[:, j, :3], fps, translations=translations, units=units)


class WindowAugmenter:
    """Augmented features of a dataset's training windows (what :class:`WindowDataset` calls).

    Picklable into data-loader workers (cache paths, options and a representation).

    Args:
        options: The transforms.
        representation: Encodes the transformed motion (its normalisation is not used:
            items hold raw features).
        motions: The clips' raw motion entries (:func:`motion_frames`), in dataset order.
        window: Frames per window.
    """

    def __init__(
        self,
        options: Augmentation,
        representation: MotionRepresentation,
        motions: Sequence[CacheEntry],
        window: int,
    ) -> None:
        self.options = options
        self.representation = representation
        self.motions = list(motions)
        self.window = int(window)
        self._skeletons = [Skeleton.from_dict(e.meta["skeleton"]) for e in self.motions]
        #: Per clip, whether its skeleton has left/right pairs to mirror.
        self.mirrorable = [sk.mirror_map() != list(range(sk.num_joints)) for sk in self._skeletons]

    def window_motion(self, clip: int, start: int, draw: Draw) -> tuple[Motion, int, int]:
        """The transformed motion of a window, with its lead frames and source start.

        Returns:
            ``(motion of lead + window frames, lead, first source frame)``.
        """
        entry = self.motions[clip]
        lead = 0 if self.representation.window_dependent else 1
        first, count, lead, speed = plan_span(
            start, entry.layout[1][1], self.window, draw.speed, lead
        )
        values = entry.read_frames(first, first + count)
        meta = entry.meta
        motion = frames_motion(values, self._skeletons[clip], meta["fps"], meta.get("units"))
        motion = change_speed(motion, speed, self.window + lead)
        if draw.mirror and self.mirrorable[clip]:
            motion = motion.mirror()
        if draw.yaw:
            motion = rotate_yaw(motion, draw.yaw, motion.root_positions[lead])
        return motion, lead, first + lead

    def features(self, clip: int, start: int, draw: Draw) -> tuple[torch.Tensor, int]:
        """``([window, N, C] float32 features, first source frame)`` of an augmented window."""
        motion, lead, first = self.window_motion(clip, start, draw)
        return self.representation.encode(motion)[lead:].float(), first
