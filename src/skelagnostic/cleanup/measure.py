"""What the foot-lock cleanup does to a motion, measured: skate, change, smoothness.

:func:`foot_lock_figures` runs :func:`~skelagnostic.cleanup.foot_lock` on a motion
as ``cleanup=footlock`` does on the verbs (contacts detected on the motion itself)
and reports the issue's three criteria: the foot skate before and after (and its
reduction), the mean change of every joint (the MPJPE between the locked and the
unlocked motion) and the largest joint acceleration before and after (a pop of the
blend or of the IK shows as a larger maximum). ``skelagnostic evaluate
cleanup=footlock`` adds them to a protocol's report for the model's output of every
held-out clip.
"""

from __future__ import annotations

import math

import torch

from skelagnostic.analysis import contact_joints, contacts_of_positions
from skelagnostic.cleanup.footlock import HALFLIFE, foot_lock
from skelagnostic.core.motion import Motion
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.metrics.functional import foot_skate

__all__ = ["FOOT_LOCK_METRICS", "SPIKE_TOLERANCE", "foot_lock_figures", "largest_acceleration"]

#: Share by which the locked motion's largest joint acceleration may exceed the input's
#: before it counts as a new spike (a pinned foot's own path changes its acceleration a
#: little; a pop of the blend or of the IK is several times the input's).
SPIKE_TOLERANCE = 0.05

#: The figures of :func:`foot_lock_figures`, with their descriptions.
FOOT_LOCK_METRICS = {
    "footlock_skate_before_cm_s": "foot skate of the model's output before foot_lock, on the "
    "contacts detected on that output, cm/s, lower is better",
    "footlock_skate_after_cm_s": "the same after foot_lock (same contacts), cm/s, lower is better",
    "footlock_skate_reduction_pct": "100 x (1 - after / before), %; the issue's target: >= 70",
    "footlock_mpjpe_cm": "MPJPE between the locked and the unlocked output (every joint, every "
    "frame), cm; the issue's target: <= 1",
    "footlock_accel_max_input": "largest joint acceleration of the output before foot_lock "
    "(any joint, any frame), m/s^2",
    "footlock_accel_max_locked": "largest joint acceleration after foot_lock, m/s^2",
    "footlock_new_accel_spike": "1 when the locked output's largest joint acceleration exceeds "
    "the input's by more than 5 %, else 0; the mean is the share of clips with a new spike "
    "(target: 0)",
}


def largest_acceleration(positions: torch.Tensor, fps: float) -> float:
    """The largest joint acceleration of ``[T, J, 3]`` positions, in their units per s^2.

    The norm of each joint's second difference times ``fps^2``, maximised over joints
    and frames (NaN for fewer than 3 frames): unlike
    :func:`~skelagnostic.analysis.acceleration`, not averaged over the joints, so a
    pop of one foot is not diluted by the still ones.
    """
    if positions.shape[0] < 3:
        return math.nan
    second = positions[2:] - 2 * positions[1:-1] + positions[:-2]
    return float(second.norm(dim=-1).amax()) * fps**2


def foot_lock_figures(motion: Motion, halflife: float = HALFLIFE) -> dict[str, float]:
    """:data:`FOOT_LOCK_METRICS` of :func:`~skelagnostic.cleanup.foot_lock` on ``motion``.

    The contacts are those ``foot_lock`` detects by default (the rule of
    :func:`~skelagnostic.analysis.foot_contacts` on the motion itself), computed once
    from the positions measured here and given to ``foot_lock``; the skate before and
    after is read on them.

    Args:
        motion: A model's output (any rig with legs, any units: centimetres and metres
            per unit from :func:`~skelagnostic.core.units.infer_units`).
        halflife: The fade of :func:`~skelagnostic.cleanup.foot_lock`, seconds.

    Returns:
        The figures; ``footlock_skate_reduction_pct`` is NaN when the input does not
        skate at all (nothing to reduce) or has no contacts.

    Raises:
        SkelagnosticError: The skeleton has no legs
            (:func:`~skelagnostic.analysis.contact_joints`).
        MotionError: As :func:`~skelagnostic.cleanup.foot_lock` (a foot without two
            bones above it).

    Examples:
        >>> from skelagnostic import procedural
        >>> walk, _ = procedural.generate("biped22", "walk", seconds=2.0, seed=0)
        >>> figures = foot_lock_figures(walk)
        >>> figures["footlock_skate_after_cm_s"] < figures["footlock_skate_before_cm_s"]
        True
    """
    sk = motion.skeleton
    feet = contact_joints(sk)
    before = motion.global_positions().double()
    up, fps = sk.up_index, motion.fps
    contacts = contacts_of_positions(before[:, feet], fps, up, sk.height())
    after = foot_lock(motion, contacts, feet, halflife=halflife).global_positions().double()
    metres = UNITS[infer_units(sk, motion.units)]
    cm = 100.0 * metres
    skate_in = float(foot_skate(before * cm, contacts, fps, up_axis=up, feet=feet))
    skate_out = float(foot_skate(after * cm, contacts, fps, up_axis=up, feet=feet))
    reduction = 100.0 * (1.0 - skate_out / skate_in) if skate_in > 0 else math.nan
    accel_in = largest_acceleration(before, fps) * metres
    accel_out = largest_acceleration(after, fps) * metres
    return {
        "footlock_skate_before_cm_s": skate_in,
        "footlock_skate_after_cm_s": skate_out,
        "footlock_skate_reduction_pct": reduction,
        "footlock_mpjpe_cm": float((after - before).norm(dim=-1).mean()) * cm,
        "footlock_accel_max_input": accel_in,
        "footlock_accel_max_locked": accel_out,
        "footlock_new_accel_spike": float(accel_out > accel_in * (1 + SPIKE_TOLERANCE)),
    }
