"""Foot-skate metrics: how far the feet slide while they should be planted."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from torch import Tensor

from skelagnostic.metrics._checks import check_indices
from skelagnostic.metrics.functional.feet import (
    _check_rate,
    _foot_skate_ratio_update,
    _foot_skate_update,
    _up_index,
)
from skelagnostic.metrics.positions import _SumCountMetric

__all__ = ["FootSkate", "FootSkateRatio"]


class FootSkate(_SumCountMetric):
    """Mean horizontal speed of the feet while in contact, over every planted step seen.

    See [`foot_skate`][skelagnostic.metrics.functional.foot_skate] for the definition;
    every planted step (a foot in contact at two consecutive frames) has the same weight.

    Args:
        fps: Frame rate of the motion.
        up_axis: The up axis, ``"x"``, ``"y"`` (default) or ``"z"`` (or its index).
        feet: Joint indices of the feet in the positions (all joints when ``None``).
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = FootSkate(fps=10.0)
        >>> positions = torch.zeros(2, 4, 1, 3)              # [B, T, feet, 3]
        >>> positions[0, :, 0, 2] = torch.tensor([0.0, 0.1, 0.2, 0.3])   # slides along z
        >>> metric.update(positions, torch.ones(2, 4, 1, dtype=torch.bool))
        >>> metric.compute()                                 # 3 steps at 1 unit/s, 3 at 0
        tensor(0.5000)
    """

    is_differentiable = True
    higher_is_better = False
    plot_lower_bound = 0.0

    def __init__(
        self,
        fps: float,
        *,
        up_axis: str | int = "y",
        feet: Sequence[int] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self.fps = _check_rate("FootSkate", "fps", fps)
        self.up_axis = _up_index("FootSkate", up_axis)
        self.feet = check_indices("FootSkate", "feet", feet)

    def update(self, positions: Tensor, contacts: Tensor) -> None:
        """Accumulate sequences of positions ``[..., T, J, 3]`` and contacts ``[..., T, F]``."""
        self._accumulate(
            *_foot_skate_update(positions, contacts, self.fps, self.up_axis, self.feet)
        )


class FootSkateRatio(_SumCountMetric):
    """Share of planted steps whose horizontal foot speed exceeds a threshold.

    See [`foot_skate_ratio`][skelagnostic.metrics.functional.foot_skate_ratio].

    Args:
        fps: Frame rate of the motion.
        threshold: Speed above which a planted step skates (positions' units per second).
        up_axis: The up axis, ``"x"``, ``"y"`` (default) or ``"z"`` (or its index).
        feet: Joint indices of the feet in the positions (all joints when ``None``).
        **kwargs: Passed to `torchmetrics.Metric`.

    Examples:
        >>> import torch
        >>> metric = FootSkateRatio(fps=10.0, threshold=0.5)
        >>> positions = torch.zeros(2, 4, 1, 3)
        >>> positions[0, :, 0, 2] = torch.tensor([0.0, 0.1, 0.2, 0.3])
        >>> metric.update(positions, torch.ones(2, 4, 1, dtype=torch.bool))
        >>> metric.compute()
        tensor(0.5000)
    """

    is_differentiable = False
    higher_is_better = False
    plot_lower_bound = 0.0
    plot_upper_bound = 1.0

    def __init__(
        self,
        fps: float,
        threshold: float,
        *,
        up_axis: str | int = "y",
        feet: Sequence[int] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self.fps = _check_rate("FootSkateRatio", "fps", fps)
        self.threshold = _check_rate("FootSkateRatio", "threshold", threshold, allow_zero=True)
        self.up_axis = _up_index("FootSkateRatio", up_axis)
        self.feet = check_indices("FootSkateRatio", "feet", feet)

    def update(self, positions: Tensor, contacts: Tensor) -> None:
        """Accumulate sequences of positions ``[..., T, J, 3]`` and contacts ``[..., T, F]``."""
        self._accumulate(
            *_foot_skate_ratio_update(
                positions, contacts, self.fps, self.threshold, self.up_axis, self.feet
            )
        )
