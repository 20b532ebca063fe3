"""Motion matching as a reusable component.

A :class:`MotionDatabase` holds per-frame features (phase-manifold points, pose
descriptors, frequencies, ...) of many clips, normalised per feature group.
:func:`motion_matching` (fixed replay length) and
:func:`frequency_scaled_motion_matching` (one query per period, time-warped
replay; WalkTheDog Alg. 1 / Eq. 9) return the chosen ``(clip, frame, length)``
segments and the assembled, inertialized output features;
:func:`assemble_motion` turns a result into a :class:`~skelagnostic.Motion` of the
source clips. The search is exact (identical to scanning every window) and
bounded in memory.

This package depends on torch and numpy only (no lightning, hydra or pluggy).
"""

from skelagnostic.matching._errors import MatchingError
from skelagnostic.matching.assemble import assemble_motion
from skelagnostic.matching.database import MotionDatabase
from skelagnostic.matching.inertialization import (
    decay_offset,
    inertialize,
    inertialize_rotations,
)
from skelagnostic.matching.matching import (
    MatchResult,
    Segment,
    frequency_scaled_motion_matching,
    motion_matching,
)
from skelagnostic.matching.windows import WindowIndex, cycle_lengths, sample_frames

__all__ = [
    "MatchResult",
    "MatchingError",
    "MotionDatabase",
    "Segment",
    "WindowIndex",
    "assemble_motion",
    "cycle_lengths",
    "decay_offset",
    "frequency_scaled_motion_matching",
    "inertialize",
    "inertialize_rotations",
    "motion_matching",
    "sample_frames",
]
