"""Farthest point sampling and kNN grouping in torch (PC-MRL Sec. 4.2, Point Transformer [52]).

The encoder's pooling stages keep a quarter of the points by farthest-first
traversal and group each kept point with its ``k`` nearest neighbours. Both
are written in plain torch, vectorised over any number of leading batch
dimensions (frames x sequences), so they run on CPU and GPU alike.
"""

from __future__ import annotations

import torch

from skelagnostic.errors import SkelagnosticError

__all__ = ["farthest_point_sampling", "gather_points", "knn_indices"]


def farthest_point_sampling(points: torch.Tensor, num_samples: int, start: int = 0) -> torch.Tensor:
    """Indices of ``num_samples`` points chosen by farthest-first traversal.

    The first index is ``start``; each next one is the point whose distance to
    the already chosen set is largest (ties: the lowest index).

    Args:
        points: ``[..., N, 3]`` point positions.
        num_samples: How many to keep (``1 <= num_samples <= N``).
        start: Index of the first point.

    Returns:
        ``[..., num_samples]`` long indices into ``N``.

    Raises:
        SkelagnosticError: ``num_samples`` or ``start`` out of range.

    Examples:
        >>> pts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [2, 0, 0]])
        >>> farthest_point_sampling(pts, 3).tolist()
        [0, 2, 3]
    """
    num = points.shape[-2]
    if not 1 <= num_samples <= num:
        raise SkelagnosticError(
            f"farthest_point_sampling: num_samples={num_samples} must be in [1, {num}]"
        )
    if not 0 <= start < num:
        raise SkelagnosticError(f"farthest_point_sampling: start={start} out of range [0, {num})")
    lead = points.shape[:-2]
    flat = points.detach().reshape(-1, num, points.shape[-1])
    batch = flat.shape[0]
    rows = torch.arange(batch, device=points.device)
    chosen = torch.empty(batch, num_samples, dtype=torch.long, device=points.device)
    current = torch.full((batch,), start, dtype=torch.long, device=points.device)
    dist = torch.full((batch, num), float("inf"), dtype=flat.dtype, device=points.device)
    for i in range(num_samples):
        chosen[:, i] = current
        if i + 1 == num_samples:
            break
        d = (flat - flat[rows, current].unsqueeze(1)).square().sum(-1)
        dist = torch.minimum(dist, d)
        current = dist.argmax(dim=-1)
    return chosen.reshape(*lead, num_samples)


def gather_points(values: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """``values[..., indices, :]`` per batch element.

    Args:
        values: ``[..., N, C]``.
        indices: ``[..., M]`` or ``[..., M, K]`` indices into ``N``.

    Returns:
        ``[..., M, C]`` or ``[..., M, K, C]``.
    """
    lead = values.shape[:-2]
    channels = values.shape[-1]
    flat_idx = indices.reshape(*lead, -1)
    out = torch.gather(values, -2, flat_idx.unsqueeze(-1).expand(*flat_idx.shape, channels))
    return out.reshape(*indices.shape, channels)


def knn_indices(queries: torch.Tensor, points: torch.Tensor, k: int) -> torch.Tensor:
    """Indices of the ``k`` nearest ``points`` of every query (Euclidean, nearest first).

    Args:
        queries: ``[..., M, 3]``.
        points: ``[..., N, 3]`` (same leading dimensions).
        k: Neighbours per query (``k <= N``).

    Returns:
        ``[..., M, k]`` long indices into ``N``.
    """
    if not 1 <= k <= points.shape[-2]:
        raise SkelagnosticError(f"knn_indices: k={k} must be in [1, {points.shape[-2]}]")
    d = (queries.detach().unsqueeze(-2) - points.detach().unsqueeze(-3)).square().sum(-1)
    return d.topk(k, dim=-1, largest=False).indices
