"""Foot-lock cleanup: pin planted feet and solve each leg with analytic two-bone IK.

For every foot and every contact (a run of frames in which the foot is planted),
the foot's horizontal position is pinned to its mean over the contact; its height
stays the animation's. The difference between the pinned and the animated
position is an offset that is exact inside the contact and is faded in before and
out after it with the critically damped decay of inertialization
(:func:`skelagnostic.matching.inertialization.decay_offset`), starting from the
offset's value *and* velocity at the contact's edge, so the foot's path stays
continuous in position and velocity: no pop.

The leg is then solved with the analytic two-bone IK of game engines (hip, knee,
ankle; the knee stays in the plane it bends in): the hip and knee turn, the ankle
keeps its world orientation, so a toe below it moves with it. Joints that are not
on a leg's chain are untouched. Written by hand: no maintained Python library
offers two-bone IK on quaternion hierarchies (fairmotion and bvhio have none).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from skelagnostic.analysis import contact_joints, foot_contacts
from skelagnostic.core import quaternion as quat
from skelagnostic.core.kinematics import forward_kinematics
from skelagnostic.core.motion import Motion
from skelagnostic.errors import MotionError
from skelagnostic.matching.inertialization import decay_offset

__all__ = ["contact_runs", "foot_lock", "leg_chain"]

#: Default half-life (seconds) of the fade in and out of a contact.
HALFLIFE = 0.1
#: Share of a leg's length over which IK approaches full extension softly.
SOFT_REACH = 0.05
#: Distance of the knee from the hip-ankle line, in thigh lengths, from which IK keeps
#: the frame's own bend plane (below it fades into the averaged hinge's).
BENT = 0.02


def contact_runs(contacts: torch.Tensor) -> list[tuple[int, int]]:
    """The runs of ``True`` in a ``[T]`` boolean mask, as ``(first, last)`` frames (inclusive).

    Examples:
        >>> contact_runs(torch.tensor([False, True, True, False, True]))
        [(1, 2), (4, 4)]
    """
    flags = contacts.to(torch.int8).tolist()
    runs, start = [], None
    for t, flag in enumerate(flags):
        if flag and start is None:
            start = t
        elif not flag and start is not None:
            runs.append((start, t - 1))
            start = None
    if start is not None:
        runs.append((start, len(flags) - 1))
    return runs


def _moving_ancestor(offsets: torch.Tensor, parents: Sequence[int], joint: int) -> int:
    """The highest joint at ``joint``'s position: climb while the bone above has zero length."""
    while parents[joint] >= 0 and float(offsets[joint].norm()) == 0.0:
        joint = parents[joint]
    return joint


def leg_chain(motion: Motion, foot: int) -> tuple[int, int, int]:
    """The ``(hip, knee, ankle)`` joints that two-bone IK turns to move ``foot``.

    The three joints lie in ``foot``'s body group (its leg). The ankle is the parent
    of a leaf foot (a human toe: the foot below keeps its pose) when the leg has the
    joints for it, else ``foot`` itself (a dog's paw); the knee and the hip are the
    next joints up that sit at a different place (zero-length bones are skipped).

    Raises:
        MotionError: If the leg has fewer than two moving bones above the foot.
    """
    sk = motion.skeleton
    parents, offsets, groups = sk.parents, sk.offsets, sk.body_groups
    leaf = not sk.children(foot) and parents[foot] >= 0
    for ankle in [parents[foot], foot] if leaf else [foot]:
        chain = [_moving_ancestor(offsets, parents, ankle)]
        while len(chain) < 3 and parents[chain[-1]] >= 0:
            chain.append(_moving_ancestor(offsets, parents, parents[chain[-1]]))
        limb = groups[foot].endswith(("_leg", "_arm"))  # a quadruped's front legs are arms
        if limb and len(chain) == 3 and all(groups[j] == groups[foot] for j in chain):
            return chain[2], chain[1], chain[0]
    raise MotionError(
        f"foot_lock: joint {sk.joint_names[foot]!r} of {sk!r} has no hip and knee above it in "
        f"a leg (its body group is {groups[foot]!r}; two-bone IK needs two bones of one leg)"
    )


def _merged(runs: list[tuple[int, int]], min_gap: int) -> list[tuple[int, int]]:
    """``runs`` with those separated by fewer than ``min_gap`` free frames joined."""
    out: list[tuple[int, int]] = []
    for first, last in runs:
        if out and first - out[-1][1] - 1 < min_gap:
            out[-1] = (out[-1][0], last)
        else:
            out.append((first, last))
    return out


def _fade(
    exact: torch.Tensor, edge: int, inner: int, frames: torch.Tensor, fps: float, halflife: float
) -> torch.Tensor:
    """The offset left at a contact's ``edge`` decaying over ``frames`` away from it.

    The spring starts from the offset's value at ``edge`` and its rate of change away
    from the contact (measured from the ``inner`` neighbour, inside the contact).
    """
    v0 = (exact[edge] - exact[inner]) * fps if inner != edge else torch.zeros_like(exact[edge])
    elapsed = (frames - edge).abs().to(exact.dtype) / fps
    return decay_offset(exact[edge], v0, elapsed, halflife)[0].to(exact)


def _blended_offsets(
    positions: torch.Tensor, contacts: torch.Tensor, up: int, fps: float, halflife: float
) -> torch.Tensor:
    """``[T, 3]`` offset moving one foot's path to its pinned one, faded around contacts.

    Inside a contact the offset pins the foot; after it the offset left at its last
    frame decays with the inertialization spring (forward in time), and before the
    next contact that contact's offset grows back the same way (backward in time).
    Contacts less than a half-life apart are one contact (a lift that short is a
    labelling flicker, not a step). Between two contacts the two fades are
    cross-faded with a smoothstep, whose zero slope at both ends keeps the path
    continuous in position and velocity even when the gap is too short for the
    springs to settle.
    """
    exact = torch.zeros_like(positions)
    runs = _merged(contact_runs(contacts), max(1, round(halflife * fps)))
    for first, last in runs:
        pinned = positions[first : last + 1].mean(dim=0)
        exact[first : last + 1] = pinned - positions[first : last + 1]
    exact[:, up] = 0.0
    out = exact.clone()
    frames = positions.shape[0]
    gaps = [(-1, runs[0][0])] if runs else []
    gaps += [(runs[i][1], runs[i + 1][0]) for i in range(len(runs) - 1)]
    gaps += [(runs[-1][1], frames)] if runs else []
    for after, before in gaps:  # the free frames strictly between two edges
        idx = torch.arange(after + 1, before)
        if not idx.numel():
            continue
        if after < 0:
            out[idx] = _fade(exact, before, min(before + 1, runs[0][1]), idx, fps, halflife)
            continue
        start = next(first for first, last in runs if last == after)
        leaving = _fade(exact, after, max(after - 1, start), idx, fps, halflife)
        if before >= frames:
            out[idx] = leaving
            continue
        end = next(last for first, last in runs if first == before)
        coming = _fade(exact, before, min(before + 1, end), idx, fps, halflife)
        x = ((idx - after).to(exact.dtype) / (before - after))[:, None]
        weight = x * x * (3 - 2 * x)  # smoothstep: 0 -> 1 with zero slope at both ends
        out[idx] = (1 - weight) * leaving + weight * coming
    return out


def _soft_reach(
    dist: torch.Tensor, now: torch.Tensor, upper: torch.Tensor, lower: torch.Tensor
) -> torch.Tensor:
    """The hip-ankle distance IK aims for: ``dist``, softly kept inside the leg's reach.

    Near full extension a hard clamp kinks the knee's path (a visible snap); the
    soft limit of Nicholas' "soft IK" approaches the reach exponentially instead, over
    the last :data:`SOFT_REACH` of the leg's length. Only the change from the
    animation's own distance ``now`` is softened (``now`` plus the soft limit's change
    from ``now`` to ``dist``), so a target that does not move the ankle keeps the pose
    exactly, however extended the leg.
    """
    reach = upper + lower
    soft = SOFT_REACH * reach
    start = reach - soft

    def limited(x: torch.Tensor) -> torch.Tensor:
        over = (x - start).clamp_min(0.0)
        return torch.where(x > start, start + soft * (1 - torch.exp(-over / soft)), x)

    shortest = (upper - lower).abs() + 1e-4 * reach
    softened = now + limited(dist) - limited(now)
    return torch.minimum(softened, reach).clamp_min(shortest)


def _bend_direction(
    hip_world: torch.Tensor, h: torch.Tensor, k: torch.Tensor, a: torch.Tensor, aim: torch.Tensor
) -> torch.Tensor:
    """``[n, 3]`` unit direction, perpendicular to ``aim``, in which the knee bends.

    Where the leg is bent (the knee at least :data:`BENT` of the thigh's length off
    the hip-ankle line), the frame's own bend plane, turned with the hip-ankle line
    onto ``aim``: a target that does not move the ankle keeps the knee exactly where
    it is. Where the leg is nearly straight, that plane is ill-defined and flips
    from frame to frame; there the direction fades (smoothstep) into the hinge's:
    a knee's axis, ``(knee - hip) x (ankle - knee)``, is fixed in the thigh's frame,
    and averaged in that frame over the frames (weighted by how bent the leg is) it
    stays defined on straight frames, so the knee does not snap.
    """
    hinge = _hinge_direction(hip_world, h, k, a, aim)
    line = a - h
    line = line / line.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    own = (k - h) - ((k - h) * line).sum(-1, keepdim=True) * line
    own = quat.rotate(quat.rotation_between(line, aim), own)  # onto the new hip-ankle line
    own = own - (own * aim).sum(-1, keepdim=True) * aim
    size = own.norm(dim=-1, keepdim=True)
    x = (size / (BENT * (k - h).norm(dim=-1, keepdim=True)).clamp_min(1e-30)).clamp(0.0, 1.0)
    weight = x * x * (3 - 2 * x)
    bend = weight * own / size.clamp_min(1e-30) + (1 - weight) * hinge
    return bend / bend.norm(dim=-1, keepdim=True).clamp_min(1e-30)


def _hinge_direction(
    hip_world: torch.Tensor, h: torch.Tensor, k: torch.Tensor, a: torch.Tensor, aim: torch.Tensor
) -> torch.Tensor:
    """The bend direction of the knee's hinge axis averaged in the thigh's frame (unit)."""
    cross = torch.linalg.cross(k - h, a - k, dim=-1)
    local = quat.rotate(quat.inv(hip_world), cross).sum(dim=0)
    if float(local.norm()) <= 1e-12 * float((k - h).norm(dim=-1).amax() ** 2):
        bend = (k - h) - ((k - h) * aim).sum(-1, keepdim=True) * aim  # never bent: this frame's
    else:
        axis = quat.rotate(hip_world, local.expand_as(cross))
        bend = torch.linalg.cross(aim, axis, dim=-1)
    return bend / bend.norm(dim=-1, keepdim=True).clamp_min(1e-30)


def _solve_leg(
    motion: Motion,
    rotations: torch.Tensor,
    chain: tuple[int, int, int],
    ankle_target: torch.Tensor,
    frames: torch.Tensor,
) -> torch.Tensor:
    """Two-bone IK on ``frames``: turn hip and knee so the ankle reaches ``ankle_target``."""
    hip, knee, ankle = chain
    sk = motion.skeleton
    parents = sk.parents
    offsets = sk.offsets.to(rotations)

    def fk(rot: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        trans = None if motion.translations is None else motion.translations[frames]
        return forward_kinematics(rot, motion.root_positions[frames], offsets, parents, trans)

    rot = rotations[frames].clone()
    glob, pos = fk(rot)
    ankle_world = glob[:, ankle].clone()
    h, k, a = pos[:, hip], pos[:, knee], pos[:, ankle]
    upper = (k - h).norm(dim=-1)
    lower = (a - k).norm(dim=-1)
    reach = ankle_target - h
    dist = _soft_reach(reach.norm(dim=-1), (a - h).norm(dim=-1), upper, lower)
    aim = reach / reach.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    bend = _bend_direction(glob[:, hip], h, k, a, aim)
    cos_hip = ((upper**2 + dist**2 - lower**2) / (2 * upper * dist)).clamp(-1.0, 1.0)
    sin_hip = (1 - cos_hip**2).sqrt()
    new_knee = h + upper[:, None] * (cos_hip[:, None] * aim + sin_hip[:, None] * bend)
    new_ankle = h + dist[:, None] * aim
    # hip: turn the thigh onto the new knee
    turn = quat.rotation_between(k - h, new_knee - h)
    parent_glob = glob[:, parents[hip]] if parents[hip] >= 0 else None
    hip_world = quat.mul(turn, glob[:, hip])
    rot[:, hip] = hip_world if parent_glob is None else quat.mul(quat.inv(parent_glob), hip_world)
    glob, pos = fk(rot)
    # knee: turn the shin onto the new ankle
    turn = quat.rotation_between(pos[:, ankle] - pos[:, knee], new_ankle - pos[:, knee])
    knee_world = quat.mul(turn, glob[:, knee])
    rot[:, knee] = quat.mul(quat.inv(glob[:, parents[knee]]), knee_world)
    glob, _ = fk(rot)
    # ankle: keep its world orientation, so the foot below it keeps its pose
    rot[:, ankle] = quat.mul(quat.inv(glob[:, parents[ankle]]), ankle_world)
    out = rotations.clone()
    out[frames] = quat.normalize(rot)
    return out


def foot_lock(
    motion: Motion,
    contacts: torch.Tensor | None = None,
    feet: Sequence[int] | None = None,
    *,
    halflife: float = HALFLIFE,
) -> Motion:
    """Pin planted feet in place and solve the legs with two-bone IK.

    Args:
        motion: The motion to clean up (any units, any up axis).
        contacts: ``[T, F]`` boolean contact labels, one column per foot of ``feet``
            (e.g. from the ground truth); default: detected on ``motion`` by
            :func:`skelagnostic.analysis.foot_contacts`.
        feet: The ``F`` joint indices that touch the ground (toes or ankles); default
            :func:`skelagnostic.analysis.contact_joints` of the skeleton (the feet of
            every leg, through the body groups).
        halflife: Seconds over which the pinning fades in before and out after a
            contact (the inertialization half-life; > 0).

    Returns:
        A new motion: the same root trajectory and the same rotations except those of
        the hips, knees and ankles of legs whose foot was moved.

    Raises:
        MotionError: On contact labels of the wrong shape or dtype, an unknown foot, a
            non-positive half-life, or a foot without two bones above it.

    Examples:
        >>> from skelagnostic import procedural
        >>> motion, _ = procedural.generate("biped22", "walk", seconds=1.0, seed=0)
        >>> feet = [motion.skeleton.index("LeftToe"), motion.skeleton.index("RightToe")]
        >>> contacts = torch.zeros(motion.num_frames, 2, dtype=torch.bool)
        >>> contacts[5:15, 0] = True                    # say the left foot is planted
        >>> locked = foot_lock(motion, contacts, feet)
        >>> def slide(m):                               # horizontal path length, cm
        ...     toe = m.global_positions()[5:15, feet[0]][:, [0, 2]]
        ...     return float((toe[1:] - toe[:-1]).norm(dim=-1).sum())
        >>> round(slide(motion), 1), round(slide(locked), 1)
        (21.2, 0.7)
    """
    if contacts is None:
        contacts, feet = foot_contacts(motion, joints=None if feet is None else list(feet))
    elif feet is None:
        feet = contact_joints(motion.skeleton)
    frames, num = motion.num_frames, len(feet)
    if not isinstance(contacts, torch.Tensor) or contacts.dtype != torch.bool:
        raise MotionError("foot_lock: contacts must be a boolean tensor [T, feet]")
    if tuple(contacts.shape) != (frames, num):
        raise MotionError(
            f"foot_lock: contacts must have shape [{frames}, {num}] (frames, feet), "
            f"got {list(contacts.shape)}"
        )
    if not (isinstance(halflife, int | float) and math.isfinite(halflife) and halflife > 0):
        raise MotionError(f"foot_lock: halflife must be a finite number > 0, got {halflife!r}")
    joints = motion.skeleton.num_joints
    for foot in feet:
        if not (isinstance(foot, int) and 0 <= foot < joints):
            raise MotionError(
                f"foot_lock: foot {foot!r} is not a joint index of {motion.skeleton!r}"
            )
    positions = motion.global_positions()
    rotations = motion.rotations
    up = motion.skeleton.up_index
    for f, foot in enumerate(feet):
        offset = _blended_offsets(positions[:, foot], contacts[:, f], up, motion.fps, halflife)
        moved = offset.norm(dim=-1) > 0
        if not bool(moved.any()):
            continue
        chain = leg_chain(motion, foot)
        # every frame from the first to the last moved one, also those whose offset is
        # exactly zero (a one-frame contact pins the foot where it is), so that any
        # rounding of the solver is the same on all of them: a frame left out between
        # solved ones made the knee jump when the IK was not the identity there
        span = moved.nonzero().flatten()
        frames_moved = torch.arange(int(span[0]), int(span[-1]) + 1)
        target = positions[frames_moved, chain[2]] + offset[frames_moved]
        rotations = _solve_leg(motion, rotations, chain, target, frames_moved)
    return motion._replace(rotations=rotations)
