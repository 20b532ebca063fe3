"""The :class:`Motion`: local joint rotations and a root trajectory over time."""

from __future__ import annotations

import builtins
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import forward_kinematics
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import MotionError

__all__ = ["UNITS", "Motion", "reroot"]


def _as_tensor(x: Any, name: str, dtype: torch.dtype | None) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        t = x
    else:
        t = torch.as_tensor(np.asarray(x))
    if not t.is_floating_point():
        t = t.to(torch.float64 if dtype is None else dtype)
    if dtype is not None:
        t = t.to(dtype)
    return t


def _first_bad(t: torch.Tensor) -> tuple[int, ...]:
    bad = (~torch.isfinite(t)).nonzero()
    return tuple(int(v) for v in bad[0])


class Motion:
    """Skeletal motion: local rotations per joint and the root trajectory.

    Args:
        skeleton: The :class:`~skelagnostic.Skeleton` the motion animates.
        rotations: ``[T, J, 4]`` local rotations, unit quaternions (w, x, y, z). They
            are re-normalised; zero-norm quaternions are rejected.
        root_positions: ``[T, 3]`` global root positions.
        fps: Frames per second (> 0).
        translations: Optional ``[T, J, 3]`` animated local translations replacing the
            skeleton offsets (BVH files with position channels on non-root joints).
        name: Optional label (file name for motions read from disk).
        units: Optional length unit of the data (a key of :data:`UNITS`).
        dtype: Optional dtype for every tensor (default: keep the input's float dtype).

    Raises:
        MotionError: On wrong shapes, NaN/inf values, zero quaternions or bad fps; the
            message names the field, frame and joint.
    """

    def __init__(
        self,
        skeleton: Skeleton,
        rotations: torch.Tensor | np.ndarray,
        root_positions: torch.Tensor | np.ndarray,
        fps: float,
        translations: torch.Tensor | np.ndarray | None = None,
        name: str | None = None,
        units: str | None = None,
        dtype: torch.dtype | None = None,
    ) -> None:
        if not isinstance(skeleton, Skeleton):
            raise MotionError(f"skeleton must be a Skeleton, got {type(skeleton).__name__}")
        rot = _as_tensor(rotations, "rotations", dtype)
        dtype = rot.dtype
        root = _as_tensor(root_positions, "root_positions", dtype).to(rot.device)
        num_j = skeleton.num_joints
        if rot.dim() != 3 or rot.shape[1:] != (num_j, 4):
            raise MotionError(
                f"rotations must have shape [T, {num_j}, 4] for skeleton {skeleton!r}, "
                f"got {list(rot.shape)}"
            )
        num_t = rot.shape[0]
        if root.shape != (num_t, 3):
            raise MotionError(
                f"root_positions must have shape [{num_t}, 3], got {list(root.shape)}"
            )
        for field, t in (("rotations", rot), ("root_positions", root)):
            if not torch.isfinite(t).all():
                idx = _first_bad(t)
                where = f"frame {idx[0]}" + (
                    f", joint {skeleton.joint_names[idx[1]]!r}" if field == "rotations" else ""
                )
                raise MotionError(f"{field} has a NaN/inf value at {where}")
        norms = rot.norm(dim=-1)
        if num_t and (norms < 1e-8).any():
            f, j = (int(v) for v in (norms < 1e-8).nonzero()[0])
            raise MotionError(
                f"rotations has a zero quaternion at frame {f}, joint {skeleton.joint_names[j]!r}"
            )
        trans = None
        if translations is not None:
            trans = _as_tensor(translations, "translations", dtype).to(rot.device)
            if trans.shape != (num_t, num_j, 3):
                raise MotionError(
                    f"translations must have shape [{num_t}, {num_j}, 3], got {list(trans.shape)}"
                )
            if not torch.isfinite(trans).all():
                idx = _first_bad(trans)
                raise MotionError(
                    f"translations has a NaN/inf value at frame {idx[0]}, "
                    f"joint {skeleton.joint_names[idx[1]]!r}"
                )
        fps = float(fps)
        if not math.isfinite(fps) or fps <= 0:
            raise MotionError(f"fps must be a positive number, got {fps}")
        if units is not None and units not in UNITS:
            raise MotionError(f"unknown units {units!r}; known: {', '.join(UNITS)}")
        self.skeleton = skeleton
        self._rotations: torch.Tensor | None = rot / norms.unsqueeze(-1).clamp_min(1e-12)
        self._pending: Callable[[], torch.Tensor] | None = None
        self.root_positions = root
        self.translations = trans
        self.fps = fps
        self.name = name
        self.units = units

    @classmethod
    def _deferred(
        cls,
        skeleton: Skeleton,
        rotations: Callable[[], torch.Tensor],
        root_positions: torch.Tensor,
        fps: float,
        translations: torch.Tensor | None = None,
        name: str | None = None,
    ) -> Motion:
        """A motion whose rotations are computed on first access (for readers).

        The caller guarantees what ``__init__`` would check: ``rotations()``
        returns finite unit quaternions ``[T, J, 4]`` of ``root_positions``'s
        dtype and device, ``root_positions`` (``[T, 3]``) and ``translations``
        are finite, and ``fps`` is positive. BVH reading uses it so that a file
        is parsed without converting every Euler angle up front; the conversion
        runs once, when :attr:`rotations` (or anything built on it) is first used.
        """
        motion = cls.__new__(cls)
        motion.skeleton = skeleton
        motion._rotations = None
        motion._pending = rotations
        motion.root_positions = root_positions
        motion.translations = translations
        motion.fps = float(fps)
        motion.name = name
        motion.units = None
        return motion

    @property
    def rotations(self) -> torch.Tensor:
        """``[T, J, 4]`` local rotations, unit quaternions (w, x, y, z)."""
        if self._rotations is None:
            assert self._pending is not None
            self._rotations, self._pending = self._pending(), None
        return self._rotations

    @rotations.setter
    def rotations(self, value: torch.Tensor) -> None:
        self._rotations, self._pending = value, None

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_rotations"], state["_pending"] = self.rotations, None
        return state

    # ------------------------------------------------------------------ basics
    @property
    def num_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.root_positions.shape[0])

    @property
    def num_joints(self) -> int:
        """Number of joints ``J``."""
        return self.skeleton.num_joints

    @property
    def duration(self) -> float:
        """Length in seconds, ``(T - 1) / fps``."""
        return max(self.num_frames - 1, 0) / self.fps

    @property
    def dtype(self) -> torch.dtype:
        """Floating dtype of the tensors."""
        return self.root_positions.dtype

    @property
    def device(self) -> torch.device:
        """Device of the tensors."""
        return self.root_positions.device

    def __len__(self) -> int:
        return self.num_frames

    def __repr__(self) -> str:
        label = f" {self.name!r}" if self.name else ""
        return (
            f"Motion{label}({self.num_frames} frames at {self.fps:g} fps, "
            f"{self.num_joints} joints, {self.dtype})"
        )

    def _replace(self, **changes: Any) -> Motion:
        kwargs = {
            "skeleton": self.skeleton,
            "rotations": self.rotations,
            "root_positions": self.root_positions,
            "fps": self.fps,
            "translations": self.translations,
            "name": self.name,
            "units": self.units,
        }
        kwargs.update(changes)
        return Motion(**kwargs)

    def to(self, dtype: torch.dtype | None = None, device: Any = None) -> Motion:
        """A copy with tensors (and skeleton offsets) moved to ``dtype`` / ``device``."""

        def conv(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t.to(dtype=dtype or t.dtype, device=device or t.device)

        return self._replace(
            rotations=conv(self.rotations),
            root_positions=conv(self.root_positions),
            translations=conv(self.translations),
        )

    def float(self) -> Motion:
        """A float32 copy (training precision)."""
        return self.to(torch.float32)

    def double(self) -> Motion:
        """A float64 copy (I/O precision)."""
        return self.to(torch.float64)

    def __getitem__(self, key: slice | int) -> Motion:
        """Frames ``key`` (a slice with step, or one frame index) as a new Motion."""
        if isinstance(key, int):
            n = self.num_frames
            if not -n <= key < n:
                raise IndexError(f"frame {key} out of range for {n} frames")
            key = slice(key % n, key % n + 1)
        if not isinstance(key, slice):
            raise TypeError(f"Motion indices must be int or slice, got {type(key).__name__}")
        step = key.step or 1
        if step <= 0:
            raise ValueError("Motion slices need a positive step")
        return self._replace(
            rotations=self.rotations[key],
            root_positions=self.root_positions[key],
            translations=None if self.translations is None else self.translations[key],
            fps=self.fps / step,
        )

    # ---------------------------------------------------------- kinematics
    def _fk(self) -> tuple[torch.Tensor, torch.Tensor]:
        offsets = self.skeleton.offsets.to(dtype=self.dtype, device=self.device)
        return forward_kinematics(
            self.rotations, self.root_positions, offsets, self.skeleton.parents, self.translations
        )

    def global_positions(self) -> torch.Tensor:
        """``[T, J, 3]`` joint positions in world space (forward kinematics)."""
        return self._fk()[1]

    def global_rotations(self) -> torch.Tensor:
        """``[T, J, 4]`` joint rotations in world space, unit quaternions (w, x, y, z)."""
        return self._fk()[0]

    def facing(self) -> torch.Tensor:
        """``[T, 4]`` heading of the character: a rotation about the up axis only.

        The forward direction is perpendicular to the left-to-right vector of the
        hips and shoulders (the first joint of each limb group), projected on the
        ground; without limbs it falls back to the rotated rest forward axis of the
        body root (:attr:`Skeleton.body_root <skelagnostic.Skeleton.body_root>`, the
        file root unless that is a static trajectory carrier).
        """
        sk = self.skeleton
        up = sk.up_index
        fwd_axis = 2 if up != 2 else 1
        starts = sk.limb_starts()
        pos = self.global_positions()
        across = torch.zeros(self.num_frames, 3, dtype=self.dtype, device=self.device)
        for limb in ("arm", "leg"):
            left, right = starts.get(f"left_{limb}"), starts.get(f"right_{limb}")
            if left is not None and right is not None:
                across = across + pos[:, left] - pos[:, right]
        across[:, up] = 0.0
        upv = torch.zeros(3, dtype=self.dtype, device=self.device)
        upv[up] = 1.0
        forward = torch.linalg.cross(across, upv.expand_as(across), dim=-1)
        heading = Q.heading_from_direction(forward, up=up, forward=fwd_axis)
        degenerate = (across.norm(dim=-1) < 1e-9).unsqueeze(-1)
        if bool(degenerate.any()):
            body = (
                self.rotations[:, 0]
                if sk.body_root == 0
                else self.global_rotations()[:, sk.body_root]
            )
            fallback = Q.yaw(body, up=up, forward=fwd_axis)
            heading = torch.where(degenerate, fallback, heading)
        return heading

    def root_local_velocities(self) -> torch.Tensor:
        """``[T, J, 3]`` joint velocities (units per second) in the character's facing frame.

        Velocities are backward differences of the global positions (the first
        frame repeats the second's), rotated by the inverse of :meth:`facing`.
        """
        pos = self.global_positions()
        if self.num_frames < 2:
            return torch.zeros_like(pos)
        vel = torch.empty_like(pos)
        vel[1:] = (pos[1:] - pos[:-1]) * self.fps
        vel[0] = vel[1]
        inv = Q.inv(self.facing()).unsqueeze(1)
        return Q.rotate(inv, vel)

    # -------------------------------------------------------------- editing
    def resample(self, fps: builtins.float) -> Motion:
        """The motion at another frame rate: slerp for rotations, lerp for positions.

        The new motion covers the same time span, starting at the first frame; its
        frame count is ``floor(duration * fps) + 1``.
        """
        fps = float(fps)
        if not math.isfinite(fps) or fps <= 0:
            raise MotionError(f"resample: fps must be positive, got {fps}")
        n_old = self.num_frames
        if n_old < 2 or fps == self.fps:
            return self._replace(fps=fps)
        n_new = math.floor(self.duration * fps + 1e-9) + 1
        t = torch.arange(n_new, dtype=torch.float64) * (self.fps / fps)
        i0 = t.floor().long().clamp(max=n_old - 1)
        i1 = (i0 + 1).clamp(max=n_old - 1)
        w = (t - i0.double()).to(self.dtype).to(self.device)
        i0, i1 = i0.to(self.device), i1.to(self.device)
        rot = Q.slerp(self.rotations[i0], self.rotations[i1], w[:, None])
        root = torch.lerp(self.root_positions[i0], self.root_positions[i1], w[:, None])
        trans = None
        if self.translations is not None:
            trans = torch.lerp(self.translations[i0], self.translations[i1], w[:, None, None])
        return self._replace(rotations=rot, root_positions=root, translations=trans, fps=fps)

    def mirror(self) -> Motion:
        """The left/right mirror image across the plane normal to the lateral axis.

        Joints swap with their counterpart (see :meth:`Skeleton.mirror_map`) and
        each local rotation is reflected. The result is exact when the skeleton's
        rest offsets are mirror-symmetric (the usual case for BVH rigs).

        Raises:
            MotionError: If the skeleton has no left/right joint pairs.
        """
        mapping = self.skeleton.mirror_map()
        if mapping == list(range(self.num_joints)):
            raise MotionError(
                f"mirror: skeleton {self.skeleton!r} has no left/right joint pairs to swap"
            )
        lat = 0 if self.skeleton.up_axis in {"y", "z"} else 2
        qsign = torch.ones(4, dtype=self.dtype, device=self.device)
        qsign[1 + (lat + 1) % 3] = -1.0
        qsign[1 + (lat + 2) % 3] = -1.0
        psign = torch.ones(3, dtype=self.dtype, device=self.device)
        psign[lat] = -1.0
        rot = self.rotations[:, mapping] * qsign
        root = self.root_positions * psign
        trans = None if self.translations is None else self.translations[:, mapping] * psign
        return self._replace(rotations=rot, root_positions=root, translations=trans)

    def scaled(self, factor: builtins.float) -> Motion:
        """The motion with every length (offsets, root path, translations) times ``factor``."""
        return self._replace(
            skeleton=self.skeleton.scaled(factor),
            root_positions=self.root_positions * factor,
            translations=None if self.translations is None else self.translations * factor,
        )

    def convert_units(self, to: str, from_: str | None = None) -> Motion:
        """The motion expressed in other length units (see :data:`UNITS`).

        Args:
            to: Target unit, e.g. ``"m"``.
            from_: Source unit; defaults to :attr:`units`.

        Raises:
            MotionError: If the source unit is unknown or not given.
        """
        src = from_ or self.units
        if src is None:
            raise MotionError("convert_units: the motion's units are unknown; pass from_=...")
        for u in (src, to):
            if u not in UNITS:
                raise MotionError(f"unknown units {u!r}; known: {', '.join(UNITS)}")
        out = self.scaled(UNITS[src] / UNITS[to])
        out.units = to
        return out

    def to_metres(self, units: str | None = None) -> Motion:
        """The motion in metres: the one conversion path of the package.

        The source unit is ``units`` if given, else :attr:`units`, else the
        guess of :func:`~skelagnostic.core.units.infer_units` from the
        skeleton's height (a human of about 1.7 m, a tailed quadruped of about
        0.6 m). The result has ``units == "m"``.

        Args:
            units: Unit the motion is in (a key of :data:`UNITS`), overriding :attr:`units`.

        Raises:
            SkelagnosticError: ``units`` is unknown, or it must be guessed and the
                skeleton has no height.

        Example:
            >>> from skelagnostic import procedural
            >>> walk = procedural.generate("biped22", "walk", seconds=1.0)[0]  # in cm
            >>> metres = walk.to_metres()
            >>> metres.units, round(metres.skeleton.height() / walk.skeleton.height(), 6)
            ('m', 0.01)
        """
        return self.convert_units("m", from_=infer_units(self.skeleton, units or self.units))


def reroot(motion: Motion, joint: str | int) -> Motion:
    """Drop the joints above ``joint`` and make it the root (keeping its global motion).

    Used for rigs whose file root is a fixed helper (Bandai-Namco's ``joint_Root``,
    a static trajectory carrier: see :attr:`Skeleton.body_root
    <skelagnostic.Skeleton.body_root>`). Forward kinematics of the kept joints is
    unchanged. Animated translations that only repeat the kept joints' offsets
    (six channels on every joint) are dropped. The skeleton counterpart is
    :meth:`Skeleton.rooted_at <skelagnostic.core.skeleton.Skeleton.rooted_at>`.

    Args:
        motion: The motion.
        joint: The new root (name or index); the joints not below it are dropped.

    Returns:
        The motion on ``motion.skeleton.rooted_at(joint)`` (``motion`` itself when
        ``joint`` is already the root).

    Raises:
        SkeletonError: ``joint`` is unknown.
    """
    sk = motion.skeleton
    new_root = sk.index(joint)
    if new_root == 0:
        return motion
    skeleton = sk.rooted_at(new_root)
    keep = [sk.index(name) for name in skeleton.joint_names]
    offsets = skeleton.offsets
    rotations = motion.rotations[:, keep].clone()
    rotations[:, 0] = motion.global_rotations()[:, new_root]
    root = motion.global_positions()[:, new_root]
    trans = None if motion.translations is None else motion.translations[:, keep]
    if trans is not None and torch.equal(
        trans[:, 1:], offsets[1:].to(trans).expand_as(trans[:, 1:])
    ):
        trans = None
    return Motion(
        skeleton,
        rotations,
        root,
        motion.fps,
        translations=trans,
        name=motion.name,
        units=motion.units,
    )
