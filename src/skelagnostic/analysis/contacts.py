"""Foot contacts for any rig: which feet touch the ground on each frame.

The feet are found through the skeleton's body groups
(:attr:`~skelagnostic.core.skeleton.Skeleton.body_groups`): the end of each leg
(``left_leg``, ``right_leg``), and the end of each arm that stands on the ground in
the rest template (a quadruped's front legs are its arms). A foot is in contact on a
frame when it is near its lowest level in the clip and nearly still; both thresholds
are shares of the skeleton's height (:meth:`~skelagnostic.core.skeleton.Skeleton.height`),
so no length unit is assumed and the same rule serves a human's toes and a dog's paws.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError, printable

__all__ = [
    "CONTACT_ARM_REACH",
    "CONTACT_FLOOR_QUANTILE",
    "CONTACT_HEIGHT",
    "CONTACT_SPEED",
    "FootContacts",
    "contact_joints",
    "contacts_of_positions",
    "foot_contacts",
]

#: Largest height of a foot above its floor while in contact, in skeleton heights.
CONTACT_HEIGHT = 0.04

#: Largest speed of a foot while in contact, in skeleton heights per second.
CONTACT_SPEED = 0.5

#: Share of a foot's frames below its floor level (robust to a few glitched frames).
CONTACT_FLOOR_QUANTILE = 0.02

#: An arm counts as a leg when its end lies this close to the rest template's lowest
#: point, in skeleton heights (a dog's front paws: 0; a human's hands: about 0.5).
CONTACT_ARM_REACH = 0.25

_LEGS = ("left_leg", "right_leg")
_ARMS = ("left_arm", "right_arm")


class FootContacts(NamedTuple):
    """What :func:`foot_contacts` returns: the contacts and the joints they were read on."""

    #: ``[F, N]`` bool, True where foot ``n`` touches the ground.
    contacts: torch.Tensor
    #: The N joints (one per leg, in :func:`contact_joints` order).
    joints: list[int]


def contact_joints(skeleton: Skeleton, arm_reach: float = CONTACT_ARM_REACH) -> list[int]:
    """The joint that touches the ground at the end of every leg, biped or quadruped.

    Per body group (``left_leg``, ``right_leg``, then ``left_arm``, ``right_arm``) the
    group's end effector (:meth:`~skelagnostic.core.skeleton.Skeleton.end_effectors`:
    its toe, foot or deepest leaf). An arm's end counts only when it lies within
    ``arm_reach`` skeleton heights of the lowest joint of the rest template
    (:meth:`~skelagnostic.core.skeleton.Skeleton.template`): a quadruped's front
    paws do, a human's hands do not.

    Args:
        skeleton: Any skeleton whose joints carry body groups.
        arm_reach: Largest rest height of a walking arm's end, in skeleton heights.

    Returns:
        Joint indices, legs first (left, right), then walking arms (left, right).

    Raises:
        SkelagnosticError: No leg or walking arm was found; the message names the
            skeleton and the body groups it looked for.

    Example:
        >>> from skelagnostic import procedural
        >>> dog = procedural.skeleton("quadruped")
        >>> [dog.joint_names[j] for j in contact_joints(dog)]
        ['LeftFoot', 'RightFoot', 'LeftHand', 'RightHand']
    """
    ends = {skeleton.body_groups[j]: j for j in skeleton.end_effectors()}
    feet = [ends[g] for g in _LEGS if g in ends]
    template = skeleton.template()
    up = template[:, 1]  # the template stands along +Y
    scale = max(skeleton.height(), 1e-9)
    for group in _ARMS:
        if group in ends and float(up[ends[group]] - up.min()) <= arm_reach * scale:
            feet.append(ends[group])
    if not feet:
        groups = sorted(set(skeleton.body_groups))
        raise SkelagnosticError(
            f"foot contacts: no foot found on skeleton {printable(repr(skeleton))}: looked for "
            f"the end joints of body groups {', '.join(_LEGS)} (and of {', '.join(_ARMS)} "
            f"within {arm_reach:g} heights of the ground at rest); its groups are "
            f"{', '.join(groups)} (Skeleton(body_groups=...) sets them)"
        )
    return feet


def foot_contacts(
    motion: Motion,
    height: float = CONTACT_HEIGHT,
    speed: float = CONTACT_SPEED,
    joints: list[int] | None = None,
) -> FootContacts:
    """Per-frame foot contacts of a clip, from each foot's height and speed.

    A foot (:func:`contact_joints`) is in contact on a frame when both hold:

    * its height along the skeleton's up axis is at most ``height`` skeleton heights
      above its floor (the :data:`CONTACT_FLOOR_QUANTILE` quantile of its heights
      over the clip: the level it stands on, whatever the joint's offset from the
      sole);
    * its speed (central difference of its global position, times the frame rate) is
      at most ``speed`` skeleton heights per second.

    Args:
        motion: A clip of any rig (any length unit: every threshold is relative).
        height: Contact height, in skeleton heights.
        speed: Contact speed, in skeleton heights per second.
        joints: The foot joints; default :func:`contact_joints` of the skeleton.

    Returns:
        ``(contacts [F, N] bool, joints)``.

    Raises:
        SkelagnosticError: The skeleton has no foot (:func:`contact_joints`), or a
            threshold is not positive.

    Example:
        >>> from skelagnostic import procedural
        >>> walk, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
        >>> contacts, feet = foot_contacts(walk)
        >>> tuple(contacts.shape), [walk.skeleton.joint_names[j] for j in feet]
        ((61, 2), ['LeftToe', 'RightToe'])
    """
    skeleton = motion.skeleton
    feet = list(joints) if joints is not None else contact_joints(skeleton)
    pos = motion.global_positions()[:, feet]
    contacts = contacts_of_positions(
        pos, motion.fps, skeleton.up_index, skeleton.height(), height, speed
    )
    return FootContacts(contacts, feet)


def contacts_of_positions(
    positions: torch.Tensor,
    fps: float,
    up_index: int,
    scale: float,
    height: float = CONTACT_HEIGHT,
    speed: float = CONTACT_SPEED,
) -> torch.Tensor:
    """The rule of :func:`foot_contacts` on feet positions already computed.

    For callers that hold the global positions (an evaluation protocol that ran
    forward kinematics once): no skeleton, no second forward kinematics.

    Args:
        positions: ``[..., F, N, 3]`` global positions of the ``N`` feet over ``F`` frames.
        fps: Frame rate.
        up_index: Index of the up axis (0, 1 or 2).
        scale: The skeleton's height, in the positions' units.
        height: Contact height, in skeleton heights.
        speed: Contact speed, in skeleton heights per second.

    Returns:
        ``[..., F, N]`` bool contacts.

    Raises:
        SkelagnosticError: A threshold is not positive.
    """
    if not (height > 0 and speed > 0):
        raise SkelagnosticError(
            f"foot contacts: height and speed must be positive, got {height} and {speed}"
        )
    scale = max(float(scale), 1e-9)
    pos = positions.double()
    level = pos[..., up_index]
    floor = torch.quantile(level, CONTACT_FLOOR_QUANTILE, dim=-2, keepdim=True)
    low = level - floor <= height * scale
    if pos.shape[-3] < 2:
        return low
    frames = pos.movedim(-3, 0)  # central differences over the frames, one-sided at the ends
    step = torch.cat(
        [frames[1:2] - frames[:1], (frames[2:] - frames[:-2]) / 2, frames[-1:] - frames[-2:-1]]
    ).movedim(0, -3)
    still = step.norm(dim=-1) * fps <= speed * scale
    return low & still
