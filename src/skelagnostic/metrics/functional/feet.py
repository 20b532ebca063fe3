"""Foot skate as functions: how far a foot slides while it should be planted.

The functional twins of :mod:`skelagnostic.metrics.feet`. Contacts come from the
caller (labelled data, or a detector such as ``skelagnostic.analysis.foot_contacts``),
so the metric measures the motion and nothing else: the same contact labels can
score a model's output and the baselines.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.metrics._checks import check_indices, check_tensor, fail
from skelagnostic.metrics.functional._utils import _mean_compute

__all__ = ["foot_skate", "foot_skate_ratio"]

#: Up axes understood by the foot-skate metrics, by name and by index.
UP_AXES = {"x": 0, "y": 1, "z": 2}


def _up_index(name: str, up_axis: str | int) -> int:
    """The index of the up axis (``"x"``/``"y"``/``"z"`` or ``0``/``1``/``2``)."""
    if isinstance(up_axis, str) and up_axis in UP_AXES:
        return UP_AXES[up_axis]
    if isinstance(up_axis, int) and not isinstance(up_axis, bool) and 0 <= up_axis <= 2:
        return up_axis
    raise fail(name, f"up_axis must be 'x', 'y', 'z' or 0, 1, 2, got {up_axis!r}")


def _check_rate(name: str, arg: str, value: float, *, allow_zero: bool = False) -> float:
    """A finite positive (or, with ``allow_zero``, non-negative) number, as ``float``."""
    number = (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None
    )
    low_ok = number is not None and (number > 0 or (allow_zero and number == 0))
    if number is None or not math.isfinite(number) or not low_ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise fail(name, f"{arg} must be a finite number {bound}, got {value!r}")
    return number


def _contact_speeds(
    name: str,
    positions: Tensor,
    contacts: Tensor,
    fps: float,
    up_axis: str | int,
    feet: Sequence[int] | None,
) -> Tensor:
    """Horizontal speeds (units/s) of every foot step between two contact frames.

    Returns a 1-D tensor with one speed per (sequence, foot, t) where the foot is in
    contact at both frames ``t`` and ``t + 1``.
    """
    check_tensor(name, "positions", positions, min_ndim=3, last_dim=3, layout="[..., T, J, 3]")
    fps = _check_rate(name, "fps", fps)
    up = _up_index(name, up_axis)
    indices = check_indices(name, "feet", feet)
    if indices is not None:
        joints = positions.shape[-2]
        if not all(-joints <= i < joints for i in indices):
            raise fail(
                name, f"feet {indices} refer to joints beyond the {joints} joints of positions"
            )
        positions = positions[..., indices, :]
    if not isinstance(contacts, Tensor) or contacts.dtype != torch.bool:
        kind = contacts.dtype if isinstance(contacts, Tensor) else type(contacts).__name__
        raise fail(name, f"contacts must be a boolean tensor [..., T, feet], got {kind}")
    if contacts.shape != positions.shape[:-1]:
        raise fail(
            name,
            f"contacts must have shape {list(positions.shape[:-1])} (positions without xyz, "
            f"after selecting the feet), got {list(contacts.shape)}",
        )
    if positions.shape[-3] < 2:
        raise fail(name, "positions need at least 2 frames to measure a speed")
    step = positions[..., 1:, :, :] - positions[..., :-1, :, :]  # [..., T-1, F, 3]
    horizontal = [axis for axis in range(3) if axis != up]
    speed = torch.linalg.vector_norm(step[..., horizontal], dim=-1) * fps  # [..., T-1, F]
    planted = contacts[..., 1:, :] & contacts[..., :-1, :]
    return speed[planted]


def _foot_skate_update(
    positions: Tensor,
    contacts: Tensor,
    fps: float,
    up_axis: str | int = "y",
    feet: Sequence[int] | None = None,
) -> tuple[Tensor, Tensor]:
    """Sum of planted-foot horizontal speeds and the number of planted steps."""
    speeds = _contact_speeds("foot_skate", positions, contacts, fps, up_axis, feet)
    return speeds.sum(), torch.tensor(speeds.numel(), device=speeds.device)


def _foot_skate_ratio_update(
    positions: Tensor,
    contacts: Tensor,
    fps: float,
    threshold: float,
    up_axis: str | int = "y",
    feet: Sequence[int] | None = None,
) -> tuple[Tensor, Tensor]:
    """Number of planted steps faster than ``threshold``, and the number of planted steps."""
    name = "foot_skate_ratio"
    threshold = _check_rate(name, "threshold", threshold, allow_zero=True)
    speeds = _contact_speeds(name, positions, contacts, fps, up_axis, feet)
    above = (speeds > threshold).sum().to(positions.dtype)
    return above, torch.tensor(speeds.numel(), device=speeds.device)


def foot_skate(
    positions: Tensor,
    contacts: Tensor,
    fps: float,
    *,
    up_axis: str | int = "y",
    feet: Sequence[int] | None = None,
) -> Tensor:
    r"""Mean horizontal speed of the feet while they are in contact (foot skate).

    For every foot ``f`` and every pair of consecutive frames ``(t, t+1)`` at which
    ``f`` is in contact at both frames, the horizontal displacement (the up axis
    removed) times the frame rate; the mean over all such steps of all feet and
    sequences:

    $$
    \mathrm{skate} = \frac{1}{|P|} \sum_{(f, t) \in P}
    \mathrm{fps}\,\lVert h(p_{f,t+1} - p_{f,t}) \rVert_2
    $$

    in the positions' units per second (metres in, m/s out: multiply by 100 for the
    cm/s most papers quote). A motion whose planted feet do not move scores 0.

    Args:
        positions: Global joint positions ``[..., T, J, 3]``: only the feet, or all
            joints with ``feet`` selecting the foot joints.
        contacts: Boolean contact labels ``[..., T, F]`` for the ``F`` feet.
        fps: Frame rate of the motion (frames per second).
        up_axis: The up axis, ``"x"``, ``"y"`` (default) or ``"z"`` (or its index).
        feet: Joint indices of the feet in ``positions`` (all joints when ``None``).

    Returns:
        Scalar tensor; NaN when no foot is in contact at two consecutive frames.

    Raises:
        MotionError: On bad shapes, a non-boolean contact mask, NaN/inf positions,
            a non-positive frame rate or an unknown up axis.

    Examples:
        >>> import torch
        >>> positions = torch.zeros(4, 1, 3)                 # one foot, 4 frames
        >>> positions[:, 0, 0] = torch.tensor([0.0, 0.0, 0.1, 0.3])  # slides along x
        >>> contacts = torch.tensor([[True], [True], [True], [False]])
        >>> foot_skate(positions, contacts, fps=10.0)        # steps 0->1 (0) and 1->2 (1 unit/s)
        tensor(0.5000)
    """
    return _mean_compute(*_foot_skate_update(positions, contacts, fps, up_axis, feet))


def foot_skate_ratio(
    positions: Tensor,
    contacts: Tensor,
    fps: float,
    threshold: float,
    *,
    up_axis: str | int = "y",
    feet: Sequence[int] | None = None,
) -> Tensor:
    """Share of planted-foot steps whose horizontal speed exceeds ``threshold``.

    The steps are those of [`foot_skate`][skelagnostic.metrics.functional.foot_skate]
    (a foot in contact at two consecutive frames); a step counts when its horizontal
    speed is strictly above ``threshold`` (positions' units per second).

    Args:
        positions: Global joint positions ``[..., T, J, 3]``.
        contacts: Boolean contact labels ``[..., T, F]``.
        fps: Frame rate of the motion.
        threshold: Speed above which a planted step skates, in the positions' units
            per second (e.g. ``0.05 * height`` per second).
        up_axis: The up axis, ``"x"``, ``"y"`` (default) or ``"z"`` (or its index).
        feet: Joint indices of the feet in ``positions`` (all joints when ``None``).

    Returns:
        Scalar tensor in ``[0, 1]``; NaN when no foot is in contact at two
        consecutive frames.

    Raises:
        MotionError: As [`foot_skate`][skelagnostic.metrics.functional.foot_skate], and on
            a negative or non-finite threshold.

    Examples:
        >>> import torch
        >>> positions = torch.zeros(4, 1, 3)
        >>> positions[:, 0, 0] = torch.tensor([0.0, 0.0, 0.1, 0.3])
        >>> contacts = torch.tensor([[True], [True], [True], [False]])
        >>> foot_skate_ratio(positions, contacts, fps=10.0, threshold=0.5)
        tensor(0.5000)
    """
    return _mean_compute(
        *_foot_skate_ratio_update(positions, contacts, fps, threshold, up_axis, feet)
    )
