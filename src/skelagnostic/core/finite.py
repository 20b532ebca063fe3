"""Finiteness checks of named tensors (weights, gradients, checkpoints)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch

__all__ = ["first_non_finite"]


def first_non_finite(tensors: Iterable[tuple[str, Any]]) -> str | None:
    """The name of the first floating-point tensor holding a NaN or an infinity, if any.

    Args:
        tensors: ``(name, value)`` pairs, e.g. ``state_dict().items()``; values that
            are not floating-point tensors are skipped.

    Example:
        >>> import torch
        >>> first_non_finite([("a", torch.ones(2)), ("b", torch.tensor([1.0, float("nan")]))])
        'b'
    """
    for name, value in tensors:
        if (
            isinstance(value, torch.Tensor)
            and value.is_floating_point()
            and not bool(torch.isfinite(value).all())
        ):
            return name
    return None
