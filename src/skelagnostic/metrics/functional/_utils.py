"""Private pieces shared by the functional metrics of several modules."""

from __future__ import annotations

from torch import Tensor

#: Reductions over pairs or neighbours understood by the position and point-cloud metrics.
REDUCTIONS = ("mean", "sum")


def _mean_compute(total: Tensor, count: Tensor) -> Tensor:
    """``total / count`` (NaN when nothing was counted)."""
    return total / count
