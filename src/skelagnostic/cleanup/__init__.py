"""Clean-up passes on finished motion: foot locking.

A model's output, a retarget or an interpolation often lets planted feet slide.
:func:`foot_lock` pins them and solves the legs with two-bone IK, fading in and
out with inertialization so nothing pops.
"""

from skelagnostic.cleanup.footlock import HALFLIFE, contact_runs, foot_lock, leg_chain

__all__ = ["HALFLIFE", "contact_runs", "foot_lock", "leg_chain"]
