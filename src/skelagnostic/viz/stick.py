"""Stick figures: the renderer's view of a motion, and time synchronisation.

A :class:`StickFigure` is plain arrays (global joint positions, parents, body
groups, frame rate, up axis), so the renderer works for anything that has joint
positions: a :class:`~skelagnostic.Motion`, a BVH file, or the output of a model
before it is turned into rotations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

import numpy as np

from skelagnostic.errors import SkelagnosticError

if TYPE_CHECKING:
    from skelagnostic import Motion

__all__ = [
    "BODY_GROUPS",
    "FigureLike",
    "RenderError",
    "StickFigure",
    "synchronise",
    "to_stick_figures",
]

#: The body groups a joint can belong to (``Skeleton.body_groups``).
BODY_GROUPS = ("spine", "left_arm", "right_arm", "left_leg", "right_leg", "tail", "other")

_UP_AXES = ("x", "y", "z")


class RenderError(SkelagnosticError, ValueError):
    """Bad input to a rendering or plotting function, or an output that cannot be written."""


@dataclass
class StickFigure:
    """One character to draw: global joint positions over time plus its hierarchy.

    Args:
        positions: Global joint positions ``[T, J, 3]`` in the character's own
            units (a torch tensor is converted to numpy).
        parents: Parent index of every joint (root ``-1``).
        groups: Body group of every joint (one of :data:`BODY_GROUPS`); the
            colour of a bone is the group of its child joint. ``None`` draws every
            bone as ``"other"``.
        fps: Frame rate of ``positions``.
        name: Label shown next to the character.
        up_axis: Which coordinate axis points up in ``positions`` (``"x"``,
            ``"y"`` or ``"z"``).
        joint_names: Optional name of every joint (shown on hover by the HTML viewer).

    Raises:
        RenderError: If a field has the wrong shape or value; the message names it.

    Examples:
        >>> import numpy as np
        >>> fig = StickFigure(np.zeros((4, 2, 3)) + [0.0, 1.0, 0.0], parents=[-1, 0], fps=30.0)
        >>> fig.num_frames, fig.num_joints, fig.duration
        (4, 2, 0.1)
    """

    positions: np.ndarray
    parents: Sequence[int]
    groups: Sequence[str] | None = None
    fps: float = 30.0
    name: str = ""
    up_axis: str = "y"
    joint_names: Sequence[str] | None = None
    _bones: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        positions = self.positions
        if hasattr(positions, "detach"):
            positions = positions.detach().cpu().numpy()
        positions = np.asarray(positions, dtype=np.float64)
        if positions.ndim != 3 or positions.shape[-1] != 3 or positions.shape[0] < 1:
            raise RenderError(
                f"StickFigure.positions must have shape [T, J, 3] with T >= 1, "
                f"got {tuple(positions.shape)}"
            )
        if not np.isfinite(positions).all():
            raise RenderError("StickFigure.positions contains NaN or inf values")
        num_joints = positions.shape[1]
        parents = [int(p) for p in self.parents]
        if len(parents) != num_joints:
            raise RenderError(
                f"StickFigure.parents has {len(parents)} entries for {num_joints} joints"
            )
        for j, p in enumerate(parents):
            if not -1 <= p < num_joints or p == j:
                raise RenderError(f"StickFigure.parents[{j}] = {p} is not a valid parent index")
        groups = ["other"] * num_joints if self.groups is None else list(self.groups)
        if len(groups) != num_joints:
            raise RenderError(
                f"StickFigure.groups has {len(groups)} entries for {num_joints} joints"
            )
        unknown = sorted(set(groups) - set(BODY_GROUPS))
        if unknown:
            raise RenderError(
                f"StickFigure.groups has unknown body groups {unknown}; expected {BODY_GROUPS}"
            )
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise RenderError(f"StickFigure.fps must be a positive number, got {self.fps}")
        if self.up_axis not in _UP_AXES:
            raise RenderError(
                f"StickFigure.up_axis must be one of {_UP_AXES}, got {self.up_axis!r}"
            )
        if self.joint_names is not None:
            names = [str(n) for n in self.joint_names]
            if len(names) != num_joints:
                raise RenderError(
                    f"StickFigure.joint_names has {len(names)} entries for {num_joints} joints"
                )
            self.joint_names = names
        self.positions = positions
        self.parents = parents
        self.groups = groups
        self.fps = float(self.fps)
        self._bones = np.array(
            [(p, j) for j, p in enumerate(parents) if p >= 0], dtype=np.int64
        ).reshape(-1, 2)

    @classmethod
    def from_motion(cls, motion: Motion, name: str | None = None) -> StickFigure:
        """Build a stick figure from a :class:`~skelagnostic.Motion` (forward kinematics).

        Args:
            motion: The motion to draw.
            name: Label shown next to the character (default: ``motion.name``).

        Returns:
            The stick figure with the motion's skeleton hierarchy, body groups,
            frame rate and up axis.
        """
        skeleton = motion.skeleton
        return cls(
            positions=motion.global_positions().detach().cpu().numpy(),
            parents=list(skeleton.parents),
            groups=list(skeleton.body_groups),
            fps=float(motion.fps),
            name=name if name is not None else (getattr(motion, "name", None) or ""),
            up_axis=getattr(skeleton, "up_axis", "y"),
            joint_names=list(skeleton.joint_names),
        )

    @property
    def num_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.positions.shape[0])

    @property
    def num_joints(self) -> int:
        """Number of joints ``J``."""
        return int(self.positions.shape[1])

    @property
    def duration(self) -> float:
        """Time of the last frame in seconds (``(T - 1) / fps``)."""
        return (self.num_frames - 1) / self.fps

    @property
    def bones(self) -> np.ndarray:
        """``[B, 2]`` array of (parent, child) joint indices."""
        return self._bones

    def z_up(self) -> np.ndarray:
        """Positions ``[T, J, 3]`` rotated so that the up axis is ``z`` (right-handed)."""
        order = {"x": (1, 2, 0), "y": (2, 0, 1), "z": (0, 1, 2)}[self.up_axis]
        return self.positions[..., list(order)]

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Positions at arbitrary times (seconds), linearly interpolated, z-up.

        Times past the last frame hold the last pose; negative times hold the first.

        Args:
            times: ``[F]`` times in seconds.

        Returns:
            ``[F, J, 3]`` z-up positions.
        """
        positions = self.z_up()
        index = np.clip(np.asarray(times, dtype=np.float64) * self.fps, 0.0, self.num_frames - 1)
        lo = np.floor(index).astype(np.int64)
        hi = np.minimum(lo + 1, self.num_frames - 1)
        w = (index - lo)[:, None, None]
        return positions[lo] * (1.0 - w) + positions[hi] * w


#: Anything :func:`to_stick_figures` understands: a Motion, a BVH or glTF path or a
#: StickFigure.
FigureLike = Union["Motion", StickFigure, str, Path]


def to_stick_figures(
    items: FigureLike | Sequence[FigureLike], labels: Sequence[str] | None = None
) -> list[StickFigure]:
    """Turn motions, BVH paths and stick figures into a list of stick figures.

    Args:
        items: One item or a sequence of items. A ``str``/``Path`` is read with
            :func:`skelagnostic.read_gltf` when it ends in ``.glb``/``.gltf``, else
            with :func:`skelagnostic.read_bvh`, and labelled with its file stem.
        labels: Optional labels, one per item, overriding the default names.

    Returns:
        One :class:`StickFigure` per item, in order.

    Raises:
        RenderError: If ``items`` is empty, an item has an unsupported type, or
            ``labels`` has the wrong length.
    """
    if isinstance(items, (str, Path, StickFigure)) or hasattr(items, "skeleton"):
        items = [items]  # type: ignore[list-item]
    items = list(items)  # type: ignore[arg-type]
    if not items:
        raise RenderError("motions: nothing to render (empty sequence)")
    if labels is not None and len(labels) != len(items):
        raise RenderError(f"labels: got {len(labels)} labels for {len(items)} motions")
    figures = []
    for k, item in enumerate(items):
        figure = _to_stick_figure(item, k)
        if labels is not None:  # a copy: the caller's StickFigure keeps its name
            figure = replace(figure, name=str(labels[k]))
        figures.append(figure)
    return figures


def _to_stick_figure(item: Any, index: int) -> StickFigure:
    if isinstance(item, StickFigure):
        return item
    if isinstance(item, (str, Path)):
        from skelagnostic.io.motion_files import read_motion

        return StickFigure.from_motion(read_motion(item, other="bvh"), name=Path(item).stem)
    if hasattr(item, "skeleton") and hasattr(item, "global_positions"):
        return StickFigure.from_motion(item, name=getattr(item, "name", None) or f"motion {index}")
    raise RenderError(
        f"motions[{index}]: expected a Motion, a BVH path or a StickFigure, "
        f"got {type(item).__name__}"
    )


def synchronise(
    figures: Sequence[StickFigure], fps: float | None = None, max_frames: int | None = None
) -> tuple[np.ndarray, float]:
    """The common clock on which several figures are drawn.

    The clock runs from 0 to the longest duration at ``fps`` (default: the
    highest input frame rate, at most 30); shorter motions hold their last pose.
    When the clock has more than ``max_frames`` ticks it keeps every ``k``-th
    tick, and the playback rate drops by ``k`` so that playback stays real time.

    Args:
        figures: The figures to synchronise.
        fps: Output frame rate.
        max_frames: Upper bound on the number of output frames.

    Returns:
        ``(times, playback_fps)``: ``[F]`` times in seconds and the rate at
        which to play the frames back.

    Raises:
        RenderError: If ``fps`` or ``max_frames`` is not positive.

    Examples:
        >>> import numpy as np
        >>> a = StickFigure(np.zeros((121, 1, 3)), parents=[-1], fps=120.0)
        >>> b = StickFigure(np.zeros((31, 1, 3)), parents=[-1], fps=30.0)
        >>> times, rate = synchronise([a, b], fps=10.0)
        >>> len(times), rate
        (11, 10.0)
        >>> times, rate = synchronise([a, b], fps=10.0, max_frames=4)
        >>> times.tolist(), rate
        ([0.0, 0.3, 0.6, 0.9], 3.3333333333333335)
    """
    if fps is None:
        fps = min(30.0, max(f.fps for f in figures))
    if not (math.isfinite(fps) and fps > 0):
        raise RenderError(f"fps must be a positive number, got {fps}")
    if max_frames is not None and max_frames < 1:
        raise RenderError(f"max_frames must be at least 1, got {max_frames}")
    duration = max(f.duration for f in figures)
    count = math.floor(duration * fps + 1e-9) + 1
    stride = 1 if max_frames is None else math.ceil(count / max_frames)
    times = np.arange(0, count, stride, dtype=np.float64) / fps
    return times, fps / stride
