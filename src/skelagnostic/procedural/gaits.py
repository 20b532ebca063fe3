"""Gaits played on the procedural rigs: :func:`generate` one clip, :func:`dataset` many.

Joint angles are smooth periodic functions of a gait phase (``walk``, ``run``,
``idle`` for bipeds; ``walk``, ``trot``, ``gallop``, ``idle`` for the quadruped),
so the gait frequency, phase and speed of every clip are known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.procedural.rigs import KINDS, joint_roles, skeleton

#: Gaits per morphology.
GAITS: dict[str, tuple[str, ...]] = {
    "biped": ("walk", "run", "idle"),
    "quadruped": ("walk", "trot", "gallop", "idle"),
}


@dataclass(frozen=True)
class _Gait:
    frequency: float  # strides per second
    hip: float  # degrees of limb swing
    knee: float  # degrees of knee flexion
    bob: float  # vertical bob as a fraction of leg length
    arm: float  # degrees of arm swing (bipeds)
    elbow: float  # degrees of elbow bend (bipeds)
    spine: float  # degrees of spine flexion/twist
    offsets: tuple[float, float, float, float] = (0.0, 0.5, 0.0, 0.5)  # LF RF LH RH phases


_BIPED_GAITS = {
    "walk": _Gait(0.9, 25.0, 35.0, 0.02, 18.0, 15.0, 4.0),
    "run": _Gait(1.4, 38.0, 75.0, 0.05, 35.0, 85.0, 7.0),
    "idle": _Gait(0.25, 1.5, 2.0, 0.004, 2.0, 8.0, 1.5),
}


_QUAD_GAITS = {
    # phase offsets of (left front, right front, left hind, right hind)
    "walk": _Gait(1.0, 20.0, 30.0, 0.02, 0.0, 0.0, 3.0, (0.25, 0.75, 0.0, 0.5)),
    "trot": _Gait(2.0, 25.0, 40.0, 0.04, 0.0, 0.0, 3.0, (0.0, 0.5, 0.5, 0.0)),
    "gallop": _Gait(2.8, 40.0, 60.0, 0.08, 0.0, 0.0, 12.0, (0.0, 0.1, 0.5, 0.6)),
    "idle": _Gait(0.3, 1.0, 1.5, 0.003, 0.0, 0.0, 1.0, (0.0, 0.5, 0.5, 0.0)),
}


def _axis_angle(axis: str, degrees: torch.Tensor) -> torch.Tensor:
    half = torch.deg2rad(degrees) / 2
    q = torch.zeros(*degrees.shape, 4, dtype=degrees.dtype)
    q[..., 0] = torch.cos(half)
    q[..., 1 + "xyz".index(axis)] = torch.sin(half)
    return q


#: Values of ``generate(root_carrier=...)`` and ``generate(channels=...)``.
_ROOT_CARRIERS = (None, "static")


_CHANNEL_LAYOUTS = (None, "all6")


_SIX = ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]


_THREE = _SIX[3:]


def _export_layout(motion: Motion, root_carrier: str | None, channels: str | None) -> Motion:
    """``motion`` laid out as ``generate(root_carrier=..., channels=...)`` asks.

    ``root_carrier="static"`` puts a static root ``joint_Root`` above the old
    root, whose OFFSET becomes its position in the last frame (an export-time
    pose, as MotionBuilder writes it) and whose per-frame position goes to the
    translations, so forward kinematics of the old joints is unchanged.
    ``channels="all6"`` gives every joint six channels.
    """
    sk = motion.skeleton
    num_frames = motion.num_frames
    names, parents, offsets = sk.joint_names, sk.parents, sk.offsets
    end_sites, groups, body_root = sk.end_sites, sk.body_groups, sk.body_root
    rotations, root, translations = motion.rotations, motion.root_positions, motion.translations
    layout = [_SIX] + [_THREE] * (sk.num_joints - 1)
    if root_carrier == "static":
        names, groups = ["joint_Root", *names], ["spine", *groups]
        parents = [-1, *(p + 1 for p in parents)]
        offsets = torch.cat([torch.zeros(1, 3, dtype=offsets.dtype), offsets])
        offsets[1] = root[-1]
        end_sites = {j + 1: v for j, v in end_sites.items()}
        body_root = 1
        rotations = torch.cat([Q.identity(num_frames, 1, dtype=motion.dtype), rotations], 1)
        translations = offsets.to(motion.dtype).expand(num_frames, -1, -1).clone()
        translations[:, 1] = root
        root = torch.zeros(num_frames, 3, dtype=motion.dtype)
        layout = [_SIX, *layout]
    if channels == "all6":
        layout = [_SIX] * len(names)
    skeleton = Skeleton(
        names,
        parents,
        offsets,
        end_sites=end_sites,
        body_groups=groups,
        up_axis=sk.up_axis,
        name=sk.name,
        morphology=sk.morphology,
        channels=layout,
        body_root=body_root,
    )
    return Motion(
        skeleton,
        rotations,
        root,
        motion.fps,
        translations=translations,
        name=motion.name,
        units=motion.units,
    )


def generate(
    kind: str = "biped22",
    gait: str = "walk",
    seconds: float = 4.0,
    fps: float = 30.0,
    seed: int = 0,
    frequency: float | None = None,
    speed: float | None = None,
    turn_rate: float = 0.0,
    scale: float | None = None,
    noise: float = 0.0,
    root_carrier: str | None = None,
    channels: str | None = None,
) -> tuple[Motion, dict[str, Any]]:
    """Generate a procedural gait with known frequency and phase.

    The seed varies the body size (±8 %), the stride frequency (±8 %), the
    amplitudes (±10 %) and the start phase unless they are given explicitly.

    Args:
        kind: Skeleton kind (see :data:`KINDS`).
        gait: Gait name (see :data:`GAITS`).
        seconds: Duration.
        fps: Frame rate of the result.
        seed: Random seed of the variations.
        frequency: Stride frequency in Hz (default: the gait's, varied by the seed).
        speed: Forward speed in cm/s (default: what the stride geometry implies).
        turn_rate: Heading change in degrees per second.
        scale: Body size factor (default: varied by the seed around 1).
        noise: Standard deviation in degrees of i.i.d. rotation noise added to animated joints.
        root_carrier: The layout of the exported file's root. ``None``: the hips are
            the root and carry the trajectory (LaFAN1, CMU). ``"static"``: a static
            root ``joint_Root`` at the origin whose only child, the hips, carries the
            trajectory in its position channels, with the hips' OFFSET at their
            position in the last frame (what a MotionBuilder export written with the
            time slider at the end of the take holds; the Bandai-Namco research
            motion dataset has this layout). Forward kinematics of the body joints is
            the same as without the carrier.
        channels: Channels per joint when written with :func:`~skelagnostic.write_bvh`.
            ``None``: six on the root (and the carrier's child), three rotations on
            the others. ``"all6"``: six on every joint, the position channels of the
            non-root joints repeating their OFFSETs (Bandai-Namco, MotionBuilder).

    Returns:
        ``(motion, info)``: ``info`` holds ``kind``, ``gait``, ``frequency`` (Hz),
        ``phase`` (``[T]`` tensor in [0, 1), stride phase per frame, 0 at the left
        hind/leg's forward-most swing), ``speed`` (cm/s), ``seed`` and
        ``synthetic=True``.

    Raises:
        SkelagnosticError: For unknown kinds or gaits, non-positive or non-finite
            durations or frame rates, or an
            unknown ``root_carrier`` or ``channels``.

    Examples:
        >>> import skelagnostic as sa
        >>> motion, info = sa.procedural.generate("quadruped", "trot", seconds=1.0, fps=60)
        >>> motion.num_frames, round(info["frequency"], 2) > 0
        (61, True)
    """
    table = _check_arguments(kind, gait, seconds, fps, root_carrier, channels)
    rng = np.random.default_rng(seed)
    g = table[gait]
    jitter = lambda spread: float(1.0 + spread * (2.0 * rng.random() - 1.0))  # noqa: E731
    body = scale if scale is not None else jitter(0.08)
    freq = frequency if frequency is not None else g.frequency * jitter(0.08)
    amp = jitter(0.10)
    phase0 = float(rng.random())
    sk = skeleton(kind, body)
    roles = joint_roles(kind)
    num_frames = math.floor(seconds * fps + 1e-9) + 1
    t = torch.arange(num_frames, dtype=torch.float64) / fps
    phase = torch.remainder(phase0 + freq * t, 1.0)
    rot = Q.identity(num_frames, sk.num_joints, dtype=torch.float64)
    stride = _Stride(g, amp, freq, phase, t, gait == "idle")
    if kind == "quadruped":
        pelvis, bob, default_speed, sway = _animate_quadruped(rot, roles, sk, stride)
    else:
        pelvis, bob, default_speed, sway = _animate_biped(rot, roles, sk, stride, body)
    spd = default_speed if speed is None else float(speed)
    heading = torch.deg2rad(torch.as_tensor(turn_rate, dtype=torch.float64) * t)
    yaw = _axis_angle("y", torch.rad2deg(heading))
    rot[:, 0] = Q.mul(yaw, pelvis)
    root = _root_path(spd, turn_rate, heading, t, sway, sk.offsets[0, 1] + bob)
    if noise > 0:
        _add_noise(rot, sorted(j for r, j in roles.items() if r != "root"), noise, seed)
    motion = Motion(sk, rot, root, fps, name=f"{kind}_{gait}_{seed}", units="cm")
    if root_carrier is not None or channels is not None:
        motion = _export_layout(motion, root_carrier, channels)
    info = {
        "kind": kind,
        "gait": gait,
        "frequency": float(freq),
        "phase": phase.to(torch.float32),
        "speed": float(spd),
        "seed": seed,
        "synthetic": True,
    }
    return motion, info


def _check_arguments(
    kind: str,
    gait: str,
    seconds: float,
    fps: float,
    root_carrier: str | None,
    channels: str | None,
) -> dict[str, _Gait]:
    """The gait table of ``kind``'s morphology, after checking :func:`generate`'s arguments.

    Raises:
        SkelagnosticError: As :func:`generate` says.
    """
    if kind not in KINDS:
        raise SkelagnosticError(f"unknown procedural skeleton {kind!r}; known: {', '.join(KINDS)}")
    morph = "quadruped" if kind == "quadruped" else "biped"
    table = _QUAD_GAITS if morph == "quadruped" else _BIPED_GAITS
    if gait not in table:
        raise SkelagnosticError(
            f"unknown gait {gait!r} for a {morph}; known: {', '.join(GAITS[morph])}"
        )
    if not 0 < seconds < math.inf or not 0 < fps < math.inf:
        raise SkelagnosticError(
            f"seconds and fps must be positive and finite, got {seconds} and {fps}"
        )
    if root_carrier not in _ROOT_CARRIERS:
        raise SkelagnosticError(
            f"root_carrier must be one of {', '.join(map(repr, _ROOT_CARRIERS))}, "
            f"got {root_carrier!r}"
        )
    if channels not in _CHANNEL_LAYOUTS:
        raise SkelagnosticError(
            f"channels must be one of {', '.join(map(repr, _CHANNEL_LAYOUTS))}, got {channels!r}"
        )
    return table


@dataclass(frozen=True)
class _Stride:
    """What every joint's curve of one clip depends on.

    Attributes:
        gait: The gait's angles and timing.
        amp: Amplitude factor of the clip (varied by the seed).
        freq: Stride frequency in Hz.
        phase: ``[T]`` stride phase in [0, 1).
        t: ``[T]`` time in seconds.
        idle: The gait stands still.
    """

    gait: _Gait
    amp: float
    freq: float
    phase: torch.Tensor
    t: torch.Tensor
    idle: bool


#: The root's rotation (without heading), vertical bob, default speed (cm/s) and
#: lateral sway of a clip.
_RootMotion = tuple[torch.Tensor, torch.Tensor, float, torch.Tensor]


def _put(rot: torch.Tensor, roles: dict[str, int], role: str, q: torch.Tensor) -> None:
    """Set the local rotation of the joint playing ``role``, if the skeleton has one."""
    if role in roles:
        rot[:, roles[role]] = q


def _animate_biped(
    rot: torch.Tensor, roles: dict[str, int], sk: Skeleton, stride: _Stride, body: float
) -> _RootMotion:
    """Write the legs', arms' and spine's rotations of a biped into ``rot``.

    Returns:
        The root's motion (see :data:`_RootMotion`).
    """
    g, amp, phase, t = stride.gait, stride.amp, stride.phase, stride.t
    two_pi = 2.0 * math.pi
    hip, knee = g.hip * amp, g.knee * amp
    leg = float(sk.offsets[roles["l_knee"]].norm() + sk.offsets[roles["l_ankle"]].norm())
    for side, shift in (("l", 0.0), ("r", 0.5)):
        ph = two_pi * (phase + shift)
        # hip flexion is a negative rotation about +X (the foot moves to +Z)
        _put(rot, roles, f"{side}_hip", _axis_angle("x", -hip * torch.sin(ph)))
        _put(
            rot,
            roles,
            f"{side}_knee",
            _axis_angle("x", knee * torch.clamp(torch.sin(ph - 1.2), min=0) + 0.1 * knee),
        )
        _put(rot, roles, f"{side}_ankle", _axis_angle("x", -0.3 * hip * torch.sin(ph - 0.5)))
        down = 78.0 if side == "l" else -78.0
        arm = -(g.arm * amp) * torch.sin(ph + math.pi)  # swings opposite to the leg
        shoulder = Q.mul(_axis_angle("x", arm), _axis_angle("z", -down + 0 * t))
        _put(rot, roles, f"{side}_shoulder", shoulder)
        bend = g.elbow * amp * (1.0 + 0.3 * torch.sin(ph + math.pi))
        _put(rot, roles, f"{side}_elbow", _axis_angle("y", (-bend if side == "l" else bend)))
    twist = g.spine * amp * torch.sin(two_pi * phase)
    _put(rot, roles, "spine0", _axis_angle("y", -0.5 * twist))
    _put(rot, roles, "spine1", _axis_angle("y", -0.5 * twist))
    _put(rot, roles, "spine2", _axis_angle("x", torch.full_like(t, 3.0)))
    _put(rot, roles, "neck", _axis_angle("y", 0.3 * twist))
    pelvis = _axis_angle("y", twist)
    bob = g.bob * leg * torch.cos(2.0 * two_pi * phase)
    default_speed = 4.0 * leg * math.sin(math.radians(hip)) * stride.freq
    if stride.idle:
        default_speed = 0.0
        sway = 1.5 * body * torch.sin(two_pi * phase)
    else:
        sway = 0.03 * leg * torch.sin(two_pi * phase)
    return pelvis, bob, default_speed, sway


def _animate_quadruped(
    rot: torch.Tensor, roles: dict[str, int], sk: Skeleton, stride: _Stride
) -> _RootMotion:
    """Write the four legs', spine's and tail's rotations of a quadruped into ``rot``.

    Returns:
        The root's motion (see :data:`_RootMotion`).
    """
    g, amp, phase = stride.gait, stride.amp, stride.phase
    two_pi = 2.0 * math.pi
    hip, knee = g.hip * amp, g.knee * amp
    front = float(sum(sk.offsets[roles[f"lf_{k}"]].norm() for k in (1, 2, 3)))
    hind = float(sum(sk.offsets[roles[f"lh_{k}"]].norm() for k in (1, 2)))
    leg = 0.5 * (front + hind)
    for (prefix, chain), off in zip(
        (("lf", 3), ("rf", 3), ("lh", 2), ("rh", 2)), g.offsets, strict=True
    ):
        ph = two_pi * (phase + off)
        _put(rot, roles, f"{prefix}_1", _axis_angle("x", -hip * torch.sin(ph)))
        sign = 1.0 if prefix.endswith("f") else -1.0  # elbows and hocks bend opposite ways
        _put(
            rot,
            roles,
            f"{prefix}_2",
            _axis_angle("x", sign * knee * torch.clamp(torch.sin(ph - 1.2), min=0)),
        )
        if chain == 3:
            _put(
                rot,
                roles,
                f"{prefix}_3",
                _axis_angle("x", -0.4 * knee * torch.clamp(torch.sin(ph - 2.0), min=0)),
            )
    flex = g.spine * amp * torch.sin(two_pi * phase)
    _put(rot, roles, "spine0", _axis_angle("x", flex))
    _put(rot, roles, "spine1", _axis_angle("x", -flex))
    _put(rot, roles, "neck", _axis_angle("x", 0.5 * flex))
    _put(rot, roles, "tail0", _axis_angle("y", 10.0 * torch.sin(two_pi * phase)))
    _put(rot, roles, "tail1", _axis_angle("y", 10.0 * torch.sin(two_pi * phase - 1.0)))
    pelvis = _axis_angle("x", -0.5 * flex)
    bob = g.bob * leg * torch.cos(2.0 * two_pi * phase)
    default_speed = 0.0 if stride.idle else 4.0 * leg * math.sin(math.radians(hip)) * stride.freq
    sway = 0.01 * leg * torch.sin(two_pi * phase)
    return pelvis, bob, default_speed, sway


def _root_path(
    speed: float,
    turn_rate: float,
    heading: torch.Tensor,
    t: torch.Tensor,
    sway: torch.Tensor,
    height: torch.Tensor,
) -> torch.Tensor:
    """``[T, 3]`` root positions: the heading integrated at ``speed``, plus the sway.

    Args:
        speed: Forward speed in cm/s.
        turn_rate: Heading change in degrees per second.
        heading: ``[T]`` heading in radians.
        t: ``[T]`` time in seconds.
        sway: ``[T]`` lateral sway in cm.
        height: ``[T]`` root height in cm.
    """
    if abs(turn_rate) > 1e-9:
        w = math.radians(turn_rate)
        x = speed / w * (1.0 - torch.cos(heading))
        z = speed / w * torch.sin(heading)
    else:
        x, z = torch.zeros_like(t), speed * t
    lateral = torch.stack(
        [sway * torch.cos(heading), torch.zeros_like(t), -sway * torch.sin(heading)], dim=-1
    )
    return torch.stack([x, height, z], dim=-1) + lateral


def _add_noise(rot: torch.Tensor, animated: list[int], noise: float, seed: int) -> None:
    """Compose i.i.d. random rotations (``noise`` degrees std) onto the ``animated`` joints."""
    num_frames = rot.shape[0]
    gen = torch.Generator().manual_seed(seed)
    axis = torch.randn(num_frames, len(animated), 3, generator=gen, dtype=torch.float64)
    ang = torch.randn(num_frames, len(animated), generator=gen, dtype=torch.float64) * noise
    axis = axis / axis.norm(dim=-1, keepdim=True)
    half = torch.deg2rad(ang) / 2
    dq = torch.cat([torch.cos(half)[..., None], torch.sin(half)[..., None] * axis], -1)
    rot[:, animated] = Q.mul(rot[:, animated], dq)


def dataset(
    kinds: tuple[str, ...] = ("biped22", "biped31", "biped17"),
    gaits: tuple[str, ...] | None = None,
    clips_per_gait: int = 2,
    seconds: float = 4.0,
    fps: float = 30.0,
    seed: int = 0,
) -> list[tuple[Motion, dict[str, Any]]]:
    """Several procedural clips: every kind x gait x ``clips_per_gait`` seeds.

    Args:
        kinds: Skeleton kinds.
        gaits: Gaits to play (default: every gait of each kind's morphology).
        clips_per_gait: Clips per (kind, gait), each with its own seed.
        seconds: Duration of each clip.
        fps: Frame rate.
        seed: Base seed; clip ``i`` uses ``seed + i``.

    Returns:
        A list of ``(motion, info)`` pairs, in a deterministic order.
    """
    out = []
    counter = 0
    for kind in kinds:
        morph = "quadruped" if kind == "quadruped" else "biped"
        for gait in gaits or GAITS[morph]:
            if gait not in GAITS[morph]:
                continue
            for _ in range(clips_per_gait):
                out.append(
                    generate(
                        kind,
                        gait,
                        seconds=seconds,
                        fps=fps,
                        seed=seed + counter,
                        turn_rate=float(np.random.default_rng(seed + counter).uniform(-20, 20)),
                    )
                )
                counter += 1
    return out
