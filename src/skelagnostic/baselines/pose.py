"""Static pose baselines: what a model must beat to have learned any motion."""

from __future__ import annotations

import torch

__all__ = ["mean_pose", "mean_pose_on_trajectory"]


def _check(positions: torch.Tensor) -> None:
    if positions.dim() < 3 or positions.shape[-1] != 3:
        raise ValueError(f"positions must be [..., T, J, 3], got shape {tuple(positions.shape)}")


def mean_pose(positions: torch.Tensor) -> torch.Tensor:
    """Every frame replaced by the clip's temporal mean pose.

    Args:
        positions: ``[..., T, J, 3]`` global joint positions.

    Returns:
        ``[..., T, J, 3]``: the mean over ``T`` of each joint, repeated over ``T``.

    Example:
        >>> x = torch.tensor([[[0.0, 0, 0]], [[2.0, 0, 0]]])
        >>> mean_pose(x)[:, 0, 0].tolist()
        [1.0, 1.0]
    """
    _check(positions)
    return positions.mean(dim=-3, keepdim=True).expand_as(positions)


def mean_pose_on_trajectory(positions: torch.Tensor, root: int = 0) -> torch.Tensor:
    """The clip's mean root-relative pose carried along the true root trajectory.

    Only the limbs' motion is left to explain: the root joint is exact.

    Args:
        positions: ``[..., T, J, 3]`` global joint positions.
        root: Index of the root joint.

    Returns:
        ``[..., T, J, 3]``.
    """
    _check(positions)
    root_pos = positions[..., root : root + 1, :]
    return (positions - root_pos).mean(dim=-3, keepdim=True) + root_pos
