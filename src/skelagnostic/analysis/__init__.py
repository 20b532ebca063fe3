"""Gait analysis for any rig: foot contacts, touch-down rates, gait rhythm, locomotion.

Everything here is measured on the motion itself (no model), with thresholds relative
to the skeleton's height, so the same call serves a human, a dog or a procedural
character. Importing this package needs only numpy and torch (no Lightning, Hydra or
pluggy). Modules: :mod:`~skelagnostic.analysis.contacts` (per-frame foot contacts
through the skeleton's body groups), :mod:`~skelagnostic.analysis.touchdowns`
(touch-down times of the feet), :mod:`~skelagnostic.analysis.gait` (stride and
contact frequency, gait phase, phase locking), :mod:`~skelagnostic.analysis.locomotion`
(which frames travel) and :mod:`~skelagnostic.analysis.smoothness` (joint acceleration).

    >>> from skelagnostic import procedural
    >>> from skelagnostic.analysis import foot_contacts, gait_frequency
    >>> dog, info = procedural.generate("quadruped", "trot", seconds=4.0, fps=30, seed=3)
    >>> contacts, feet = foot_contacts(dog)
    >>> tuple(contacts.shape), len(feet)
    ((121, 4), 4)
    >>> abs(gait_frequency(dog) / info["frequency"] - 1) < 0.05
    True
"""

from skelagnostic.analysis.contacts import (
    CONTACT_HEIGHT,
    CONTACT_SPEED,
    FootContacts,
    contact_joints,
    contacts_of_positions,
    foot_contacts,
)
from skelagnostic.analysis.gait import (
    GAIT_PHASE_MAX_STRIDE,
    TOUCHDOWN_MAX_INTERVAL,
    contact_frequency,
    contact_lock,
    forward_swings,
    gait_frequency,
    gait_phase,
    onset_rate,
    rate_in_runs,
    touchdown_frequency,
)
from skelagnostic.analysis.locomotion import (
    LOCOMOTION_RUN_SECONDS,
    LOCOMOTION_SPAN,
    LOCOMOTION_SPEED,
    locomotion_frames,
    locomotion_runs,
)
from skelagnostic.analysis.smoothness import acceleration
from skelagnostic.analysis.touchdowns import (
    CONTACT_ENTER,
    CONTACT_MIN_LIFT,
    CONTACT_WINDOW,
    contact_onsets,
    foot_heights,
    foot_joints,
    motion_onsets,
)

__all__ = [
    "CONTACT_ENTER",
    "CONTACT_HEIGHT",
    "CONTACT_MIN_LIFT",
    "CONTACT_SPEED",
    "CONTACT_WINDOW",
    "GAIT_PHASE_MAX_STRIDE",
    "LOCOMOTION_RUN_SECONDS",
    "LOCOMOTION_SPAN",
    "LOCOMOTION_SPEED",
    "TOUCHDOWN_MAX_INTERVAL",
    "FootContacts",
    "acceleration",
    "contact_frequency",
    "contact_joints",
    "contact_lock",
    "contact_onsets",
    "contacts_of_positions",
    "foot_contacts",
    "foot_heights",
    "foot_joints",
    "forward_swings",
    "gait_frequency",
    "gait_phase",
    "locomotion_frames",
    "locomotion_runs",
    "motion_onsets",
    "onset_rate",
    "rate_in_runs",
    "touchdown_frequency",
]
