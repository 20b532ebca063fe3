"""Input validation shared by the metrics (shapes, dtypes, NaN, masks).

Every check raises :class:`~skelagnostic.errors.MotionError` (a
:class:`~skelagnostic.errors.SkelagnosticError` and a ``ValueError``) with a
message that starts with the metric name and names the offending argument.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skelagnostic.errors import MotionError


def fail(metric: str, message: str) -> MotionError:
    """Build the error every check raises: ``"<metric>: <message>"``."""
    return MotionError(f"{metric}: {message}")


def check_choice(metric: str, name: str, value: str, choices: Sequence[str]) -> None:
    """Reject an option value outside ``choices``."""
    if value not in choices:
        raise fail(metric, f"{name} must be one of {list(choices)}, got {value!r}")


def check_positive_int(metric: str, name: str, value: int) -> None:
    """Reject anything but a positive Python integer."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise fail(metric, f"{name} must be a positive integer, got {value!r}")


def check_tensor(
    metric: str,
    name: str,
    x: object,
    *,
    min_ndim: int,
    last_dim: int | None = None,
    layout: str,
) -> Tensor:
    """Check a floating-point data tensor: type, rank, last dimension and finiteness.

    Args:
        metric: Metric name used as the message prefix.
        name: Argument name (``"preds"``, ``"target"``, ...).
        x: The value to check.
        min_ndim: Minimum number of dimensions.
        last_dim: Required size of the last dimension, if any.
        layout: Human-readable expected layout, e.g. ``"[..., J, 3]"``.

    Returns:
        ``x`` unchanged.
    """
    if not isinstance(x, Tensor):
        kind = type(x).__name__
        raise fail(metric, f"{name} must be a torch.Tensor of shape {layout}, got {kind}")
    if not x.is_floating_point():
        raise fail(metric, f"{name} must be a floating-point tensor, got dtype {x.dtype}")
    if x.ndim < min_ndim or (last_dim is not None and x.shape[-1] != last_dim):
        raise fail(metric, f"{name} must have shape {layout}, got {list(x.shape)}")
    if not bool(torch.isfinite(x).all()):
        bad = "NaN" if bool(torch.isnan(x).any()) else "infinite"
        raise fail(metric, f"{name} contains {bad} values; clean or mask the data first")
    return x


def check_same_shape(metric: str, preds: Tensor, target: Tensor, dim_names: Sequence[str]) -> None:
    """Require ``preds.shape == target.shape`` and name the first differing dimension.

    ``dim_names`` names the trailing dimensions (e.g. ``("frames", "joints", "xyz")``).
    """
    if preds.shape == target.shape:
        return
    message = (
        f"preds and target must have the same shape, got preds {list(preds.shape)} "
        f"and target {list(target.shape)}"
    )
    if preds.ndim == target.ndim:
        names = ["batch"] * (preds.ndim - len(dim_names)) + list(dim_names)
        for axis, (a, b) in enumerate(zip(preds.shape, target.shape, strict=True)):
            if a != b:
                message += f" ({names[axis]} differ: {a} vs {b})"
                break
    raise fail(metric, message)


def promote(preds: Tensor, target: Tensor) -> tuple[Tensor, Tensor]:
    """Cast both inputs to their common floating dtype (e.g. float32 + float64 -> float64)."""
    dtype = torch.promote_types(preds.dtype, target.dtype)
    return preds.to(dtype), target.to(dtype)


def check_frame_mask(metric: str, mask: object, batch_frames: torch.Size) -> Tensor:
    """Check a ``[B, T]`` boolean (or 0/1) frame mask and return it as ``bool``."""
    if not isinstance(mask, Tensor):
        raise fail(metric, f"mask must be a torch.Tensor of shape {list(batch_frames)}")
    if mask.shape != batch_frames:
        raise fail(
            metric,
            f"mask must have shape [B, T] = {list(batch_frames)}, got {list(mask.shape)}",
        )
    if mask.dtype != torch.bool:
        if mask.is_floating_point() or mask.is_complex():
            raise fail(metric, f"mask must be a boolean or integer tensor, got dtype {mask.dtype}")
        if bool(((mask != 0) & (mask != 1)).any()):
            raise fail(metric, "an integer mask may only contain 0 and 1")
        mask = mask.bool()
    return mask


def reshape_per_item(
    metric: str, name: str, value: float | Tensor, leading: torch.Size, like: Tensor
) -> Tensor:
    """Broadcast a scalar or a per-item tensor over the leading dimensions ``leading``.

    ``value`` may be a Python number, a 0-d tensor or a tensor whose shape is a
    prefix of ``leading`` (e.g. one value per sequence ``[B]`` for ``leading == [B, T]``).
    The result has shape ``leading`` and the dtype/device of ``like``.
    """
    v = torch.as_tensor(value, dtype=like.dtype, device=like.device)
    if v.ndim > len(leading) or tuple(v.shape) != tuple(leading[: v.ndim]):
        raise fail(
            metric,
            f"{name} must be a number or a tensor whose shape is a prefix of {list(leading)}, "
            f"got shape {list(v.shape)}",
        )
    if not bool(torch.isfinite(v).all()) or bool((v <= 0).any()):
        raise fail(metric, f"{name} must be finite and > 0")
    return v.reshape(*v.shape, *([1] * (len(leading) - v.ndim))).expand(leading)


def check_bones(name: str, bones: Sequence[tuple[int, int]]) -> tuple[list[int], list[int]]:
    """Validate ``(parent, child)`` pairs; return the parent and child index lists."""
    pairs = list(bones)
    if not pairs:
        raise fail(name, "bones must list at least one (parent, child) pair")
    for pair in pairs:
        if (
            len(pair) != 2
            or not all(isinstance(j, int) and not isinstance(j, bool) and j >= 0 for j in pair)
            or pair[0] == pair[1]
        ):
            raise fail(name, f"bones must be (parent, child) pairs of joint indices, got {pair!r}")
    return [p for p, _ in pairs], [c for _, c in pairs]


def check_indices(name: str, arg: str, indices: Sequence[int] | None) -> list[int] | None:
    """Validate an optional list of joint indices."""
    if indices is None:
        return None
    out = list(indices)
    if not out or not all(isinstance(i, int) and not isinstance(i, bool) for i in out):
        raise fail(name, f"{arg} must be a non-empty sequence of joint indices")
    return out


def check_same_frames(metric: str, preds: Tensor, target: Tensor) -> None:
    """Raise unless ``preds`` and ``target`` share every dimension before the last two.

    For point sets whose point counts may differ (``[..., T, N, 3]`` vs ``[..., T, M, 3]``).
    """
    if preds.shape[:-2] != target.shape[:-2]:
        raise fail(
            metric,
            "preds and target must share their sequence and frame dimensions, got "
            f"preds {list(preds.shape)} and target {list(target.shape)}",
        )
