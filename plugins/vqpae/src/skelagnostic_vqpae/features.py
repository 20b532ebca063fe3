"""The WalkTheDog authors' input features (``data.features=authors``), on any rig.

The authors' Unity exporter (github PeizhuoLi/walk-the-dog, read through the
re-implementation ``../shared/tools/wtd_data.py``) writes per frame the joints'
velocities, positions and rotations in a *root frame*, and their ``train_vq.py``
feeds the network the ``Velocities`` channels only. This module computes the
velocities and positions (what :class:`~skelagnostic_vqpae.data.VqpaeDataModule`
keeps: the network's input and the average-pose target) the same way:

* root position: the body root (:attr:`Skeleton.body_root
  <skelagnostic.Skeleton.body_root>`, the hips) projected on the ground;
* facing: for a biped, the horizontal normal of the sum of the unit horizontal
  right-to-left hip and shoulder vectors (the first joint of each leg and arm body
  group); for a quadruped (:attr:`Skeleton.morphology
  <skelagnostic.Skeleton.morphology>`), the horizontal hips-to-neck direction (the
  neck: a spine joint named ``*neck*``, else the spine joint after the one both
  front legs branch from). The
  facing is smoothed with a Gaussian over ``2 s`` (standard deviation a quarter of
  the window, edges repeating the end frames), as ``wtd_data.py`` approximates the
  exporter's adaptive smoothing;
* velocities: ``(p_t in root_t - p_{t-1} in root_{t-1}) * fps``, 0 on the first frame;
* a 2nd-order zero-phase Butterworth low-pass (``scipy.signal.filtfilt``, 3.25 Hz)
  over every channel kept here (the exporter filters the first half of its
  channels: the velocities, the positions and part of the rotations);
* the mirrored copy mirrors the world positions across the lateral plane with the
  skeleton's left/right pairs (:meth:`Skeleton.mirror_map
  <skelagnostic.Skeleton.mirror_map>`) swapped, as the exporter mirrors world
  transforms. :meth:`Motion.mirror <skelagnostic.Motion.mirror>` is not used: it
  reflects the local rotations and re-runs forward kinematics with the unmirrored
  offsets, which on a rig whose rest pose is not exactly symmetric gives joints that
  are not the mirror images of the recorded ones.

Joints are found from body groups and name words only (no joint name of a
particular rig), so any skeleton with two legs and two arms (biped) or with a
neck or arms branching off the spine (quadruped) works; others get a one-line
error naming the skeleton and what is missing.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.names import name_words
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError

__all__ = [
    "CUTOFF_HZ",
    "FACING_SECONDS",
    "FEATURES",
    "authors_features",
    "facing_joints",
    "lowpass",
    "root_frames",
]

#: The ``data.features`` values: ``raw`` (per-frame root-local velocities) or ``authors``.
FEATURES = ("raw", "authors")
#: Cutoff of the exporter's Butterworth low-pass, Hz.
CUTOFF_HZ = 3.25
#: Width of the facing direction's Gaussian smoothing window, seconds.
FACING_SECONDS = 2.0
#: The filter is skipped on clips of at most this many frames (``filtfilt``'s padding).
_MIN_FILTER_FRAMES = 9


def _neck(skeleton: Skeleton, starts: dict[str, int]) -> int | None:
    """A spine joint named ``*neck*``, else the one after the spine joint both arms branch from.

    The fallback is the branching joint's one spine child (the start of the neck), or
    the branching joint itself if it has none or several.
    """
    groups, names, parents = skeleton.body_groups, skeleton.joint_names, skeleton.parents
    for j in range(1, skeleton.num_joints):
        if groups[j] == "spine" and any("neck" in w for w in name_words(names[j])):
            return j
    if "left_arm" not in starts or "right_arm" not in starts:
        return None

    def ancestors(j: int) -> list[int]:
        path = []
        while parents[j] >= 0:
            j = parents[j]
            path.append(j)
        return path

    right = set(ancestors(starts["right_arm"]))
    common = next((a for a in ancestors(starts["left_arm"]) if a in right), None)
    if common is None or common == skeleton.body_root or groups[common] != "spine":
        return None
    spine = [c for c in skeleton.children(common) if groups[c] == "spine"]
    return spine[0] if len(spine) == 1 else common


def facing_joints(skeleton: Skeleton) -> dict[str, int]:
    """The joints the exporter's root frame is built from.

    Args:
        skeleton: Any skeleton.

    Returns:
        ``hips`` (the body root) and, for a quadruped, ``neck``; for any other
        morphology ``left_leg``, ``right_leg``, ``left_arm``, ``right_arm`` (the first
        joint of each group: hips and shoulders).

    Raises:
        SkelagnosticError: A joint the facing needs is missing (one line naming the
            skeleton and the missing joints).
    """
    starts = skeleton.limb_starts()
    label = f"data.features=authors: skeleton {skeleton.name or repr(skeleton)}"
    if skeleton.morphology == "quadruped":
        neck = _neck(skeleton, starts)
        if neck is None:
            raise SkelagnosticError(
                f"{label} has no neck (no spine joint named *neck* and no spine joint both "
                "arm groups branch from) for the hips-to-neck facing of a quadruped"
            )
        return {"hips": skeleton.body_root, "neck": neck}
    limbs = ("left_leg", "right_leg", "left_arm", "right_arm")
    missing = [g for g in limbs if g not in starts]
    if missing:
        raise SkelagnosticError(
            f"{label} has no {', '.join(missing)} body group (hips and shoulders give the "
            "facing of a biped)"
        )
    return {"hips": skeleton.body_root, **{g: starts[g] for g in limbs}}


def _horizontal_unit(v: Tensor, up: int) -> Tensor:
    v = v.clone()
    v[..., up] = 0.0
    return v / (v.norm(dim=-1, keepdim=True) + 1e-9)


def _smooth(direction: Tensor, fps: float, seconds: float, up: int) -> Tensor:
    """Gaussian smoothing of ``[T, 3]`` unit directions (edges repeat the end frames)."""
    half = round(seconds * fps / 2)
    if half < 1 or len(direction) < 2:
        return direction
    k = torch.arange(-half, half + 1, dtype=direction.dtype)
    weights = torch.exp(-0.5 * (k / (half / 2.0)) ** 2)
    padded = F.pad(direction.T[:, None], (half, half), mode="replicate")
    acc = F.conv1d(padded, weights.view(1, 1, -1))[:, 0].T
    acc[:, up] = 0.0
    norm = acc.norm(dim=-1, keepdim=True)
    return torch.where(norm > 1e-6, acc / norm.clamp_min(1e-9), direction)


def root_frames(
    positions: Tensor, skeleton: Skeleton, fps: float, smooth_seconds: float = FACING_SECONDS
) -> tuple[Tensor, Tensor]:
    """The exporter's root frame of every frame.

    Args:
        positions: ``[T, J, 3]`` world joint positions.
        skeleton: Their skeleton (its up axis, groups and morphology).
        fps: Frame rate of ``positions``.
        smooth_seconds: Width of the facing's Gaussian window (0: no smoothing).

    Returns:
        ``([T, 3] root positions on the ground, [T, 4] headings)``: the heading
        rotates the rest forward axis onto the (smoothed) facing about the up axis.

    Raises:
        SkelagnosticError: See :func:`facing_joints`.
    """
    joints = facing_joints(skeleton)
    up = skeleton.up_index
    if "neck" in joints:
        forward = positions[:, joints["neck"]] - positions[:, joints["hips"]]
    else:
        hips = positions[:, joints["right_leg"]] - positions[:, joints["left_leg"]]
        shoulders = positions[:, joints["right_arm"]] - positions[:, joints["left_arm"]]
        across = _horizontal_unit(hips, up) + _horizontal_unit(shoulders, up)
        upv = torch.zeros_like(across)
        upv[:, up] = 1.0
        forward = torch.linalg.cross(upv, across, dim=-1)
    forward = _smooth(_horizontal_unit(forward, up), fps, smooth_seconds, up)
    heading = Q.heading_from_direction(forward, up=up, forward=2 if up != 2 else 1)
    root = positions[:, joints["hips"]].clone()
    root[:, up] = 0.0
    return root, heading


def _mirror_positions(positions: Tensor, skeleton: Skeleton) -> Tensor:
    """World positions mirrored across the lateral plane, left and right joints swapped."""
    mapping = skeleton.mirror_map()
    if mapping == list(range(skeleton.num_joints)):
        raise SkelagnosticError(
            f"data.features=authors: skeleton {skeleton.name or repr(skeleton)} has no "
            "left/right joint pairs to mirror"
        )
    sign = torch.ones(3, dtype=positions.dtype)
    sign[0 if skeleton.up_axis in {"y", "z"} else 2] = -1.0  # as Motion.mirror
    return positions[:, mapping] * sign


def lowpass(x: np.ndarray, fps: float, cutoff: float = CUTOFF_HZ) -> np.ndarray:
    """2nd-order zero-phase Butterworth low-pass along axis 0 (unchanged if too short).

    Raises:
        SkelagnosticError: ``cutoff`` is not below the Nyquist frequency ``fps / 2``, or
            scipy is not installed.
    """
    if cutoff <= 0 or len(x) <= _MIN_FILTER_FRAMES:
        return x
    if cutoff >= fps / 2:
        raise SkelagnosticError(
            f"data.features=authors: the {cutoff} Hz low-pass needs data.fps > {2 * cutoff}, "
            f"got {fps}"
        )
    try:  # only this option needs scipy: the package's dependencies do not include it
        from scipy.signal import butter, filtfilt
    except ImportError as exc:
        raise SkelagnosticError(
            "data.features=authors needs scipy for its Butterworth low-pass: "
            "pip install -c constraints.txt scipy"
        ) from exc
    b, a = butter(2, cutoff, btype="low", fs=fps)
    return filtfilt(b, a, x, axis=0)


def authors_features(
    motion: Motion,
    mirrored: bool = False,
    cutoff: float = CUTOFF_HZ,
    smooth_seconds: float = FACING_SECONDS,
) -> tuple[Tensor, Tensor]:
    """The exporter's velocities and positions of a motion, at its frame rate and units.

    Args:
        motion: The clip (any rig; see :func:`facing_joints`).
        mirrored: Compute them for the clip's mirror image (the exporter's second copy).
        cutoff: Low-pass cutoff, Hz (0: none).
        smooth_seconds: Width of the facing's Gaussian window (0: none).

    Returns:
        ``([T, J, 3] velocities, [T, J, 3] positions)`` in the root frame, float64.

    Raises:
        SkelagnosticError: The facing joints are missing, ``mirrored`` on a rig without
            left/right pairs, or ``cutoff`` above the Nyquist frequency.
    """
    sk = motion.skeleton
    pos = motion.double().global_positions()
    if mirrored:
        pos = _mirror_positions(pos, sk)
    root, heading = root_frames(pos, sk, motion.fps, smooth_seconds)
    local = Q.rotate(Q.inv(heading)[:, None], pos - root[:, None])
    vel = torch.zeros_like(local)
    vel[1:] = (local[1:] - local[:-1]) * motion.fps
    both = np.concatenate([vel.numpy(), local.numpy()], axis=-1)
    both = lowpass(both.reshape(len(both), -1), motion.fps, cutoff).reshape(both.shape)
    out = torch.from_numpy(np.ascontiguousarray(both))
    return out[..., :3], out[..., 3:]
