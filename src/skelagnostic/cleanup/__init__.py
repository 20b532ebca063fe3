"""Clean-up passes on finished motion: foot locking.

A model's output, a retarget or an interpolation often lets planted feet slide.
:func:`foot_lock` pins them and solves the legs with two-bone IK, fading in and
out with inertialization so nothing pops; :func:`foot_lock_figures` measures what
it does to a motion (skate before and after, the change, the largest acceleration).
"""

from skelagnostic.cleanup.footlock import HALFLIFE, contact_runs, foot_lock, leg_chain
from skelagnostic.cleanup.measure import (
    FOOT_LOCK_METRICS,
    SPIKE_TOLERANCE,
    foot_lock_figures,
    largest_acceleration,
)

__all__ = [
    "FOOT_LOCK_METRICS",
    "HALFLIFE",
    "SPIKE_TOLERANCE",
    "contact_runs",
    "foot_lock",
    "foot_lock_figures",
    "largest_acceleration",
    "leg_chain",
]
