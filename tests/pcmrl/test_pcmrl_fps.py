"""Farthest point sampling and kNN grouping of the point encoder against loop references."""

from __future__ import annotations

import pytest
import torch
from skelagnostic_pcmrl.recon.fps import farthest_point_sampling, gather_points, knn_indices

from skelagnostic.errors import SkelagnosticError


def _fps_reference(points: torch.Tensor, m: int) -> list[int]:
    """Textbook farthest-first traversal, one point at a time."""
    chosen = [0]
    while len(chosen) < m:
        best, best_d = -1, -1.0
        for i in range(points.shape[0]):
            d = min(float((points[i] - points[j]).square().sum()) for j in chosen)
            if d > best_d:
                best, best_d = i, d
        chosen.append(best)
    return chosen


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_fps_matches_reference_over_a_batch(dtype: torch.dtype) -> None:
    gen = torch.Generator().manual_seed(0)
    pts = torch.randn(2, 3, 40, 3, generator=gen, dtype=dtype)
    idx = farthest_point_sampling(pts, 10)
    assert idx.shape == (2, 3, 10)
    for a in range(2):
        for b in range(3):
            assert idx[a, b].tolist() == _fps_reference(pts[a, b], 10)


def test_fps_spreads_points_and_validates() -> None:
    line = torch.tensor([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [2, 0, 0], [4.9, 0, 0]])
    assert farthest_point_sampling(line, 3).tolist() == [0, 2, 3]
    assert farthest_point_sampling(line, 5).sort().values.tolist() == [0, 1, 2, 3, 4]
    with pytest.raises(SkelagnosticError, match="num_samples"):
        farthest_point_sampling(line, 6)


def test_knn_and_gather_match_brute_force() -> None:
    gen = torch.Generator().manual_seed(1)
    pts = torch.randn(4, 30, 3, generator=gen)
    feats = torch.randn(4, 30, 5, generator=gen)
    centres = gather_points(pts, farthest_point_sampling(pts, 8))
    idx = knn_indices(centres, pts, 6)
    for b in range(4):
        for m in range(8):
            d = (pts[b] - centres[b, m]).norm(dim=-1)
            assert set(idx[b, m].tolist()) == set(d.argsort()[:6].tolist())
    grouped = gather_points(feats, idx)
    assert grouped.shape == (4, 8, 6, 5)
    assert torch.equal(grouped[2, 3, 1], feats[2, idx[2, 3, 1]])
