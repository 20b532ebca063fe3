"""Temporal KNN point-cloud distance (PC-MRL Eq. 5): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skelagnostic.errors import MotionError
from skelagnostic.metrics import TemporalKNNDistance
from skelagnostic.metrics.functional import temporal_knn_distance


def reference(preds, target, g_p, g_t, k, reduction="mean") -> float:
    """Explicit loops over sequences and reference points, straight from Eq. 5."""
    preds = preds.reshape(-1, *preds.shape[-3:])
    target = target.reshape(-1, *target.shape[-3:])
    values = []
    for p, t in zip(preds, target, strict=True):
        total = 0.0
        for a in range(t.shape[1]):
            deltas = [
                np.sum(np.linalg.norm(t[:, a] - p[:, b], axis=-1))
                for b in range(p.shape[1])
                if g_p[b] == g_t[a]
            ]
            total += np.sum(np.sort(deltas)[:k])
        if reduction == "mean":
            total /= t.shape[1] * k * t.shape[0]
        values.append(total)
    return float(np.mean(values))


@pytest.mark.parametrize("reduction", ["mean", "sum"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_random_clouds_with_groups(reduction, dtype):
    gen = torch.Generator().manual_seed(0)
    groups = ["spine", "left_arm", "right_arm", "left_leg", "right_leg"]
    target = torch.randn(2, 6, 40, 3, generator=gen, dtype=dtype)
    preds = torch.randn(2, 6, 30, 3, generator=gen, dtype=dtype)
    g_t = [groups[i % 5] for i in range(40)]
    g_p = [groups[(i * 3) % 5] for i in range(30)]
    expected = reference(preds.double().numpy(), target.double().numpy(), g_p, g_t, 4, reduction)
    value = temporal_knn_distance(
        preds, target, preds_groups=g_p, target_groups=g_t, k=4, reduction=reduction
    )
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-12)
    metric = TemporalKNNDistance(k=4, reduction=reduction)
    metric.update(preds[:1], target[:1], g_p, g_t)
    metric.update(preds[1:], target[1:], g_p, g_t)
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


def test_integer_groups_and_no_groups():
    gen = torch.Generator().manual_seed(1)
    target = torch.randn(5, 12, 3, generator=gen, dtype=torch.float64)
    preds = torch.randn(5, 10, 3, generator=gen, dtype=torch.float64)
    g_t, g_p = torch.arange(12) % 2, torch.arange(10) % 2
    expected = reference(preds.numpy(), target.numpy(), g_p.tolist(), g_t.tolist(), 3)
    value = temporal_knn_distance(preds, target, preds_groups=g_p, target_groups=g_t, k=3)
    assert value.item() == pytest.approx(expected)
    one = reference(preds.numpy(), target.numpy(), [0] * 10, [0] * 12, 3)
    assert temporal_knn_distance(preds, target, k=3).item() == pytest.approx(one)


def test_neighbours_are_chosen_over_the_whole_trajectory():
    """A point close in most frames beats one that is closest in a single frame."""
    target = torch.zeros(3, 1, 3)
    preds = torch.zeros(3, 2, 3)
    preds[:, 0, 0] = torch.tensor([0.1, 0.1, 0.1])  # total 0.3
    preds[:, 1, 0] = torch.tensor([0.0, 0.0, 1.0])  # closest in frames 0-1, total 1.0
    assert temporal_knn_distance(preds, target, k=1, reduction="sum").item() == pytest.approx(0.3)


def test_identical_clouds_score_zero_and_gradient():
    gen = torch.Generator().manual_seed(2)
    cloud = torch.randn(4, 9, 3, generator=gen, dtype=torch.float64)
    assert temporal_knn_distance(cloud, cloud, k=1).item() == 0.0
    preds = (
        cloud + 0.1 * torch.randn(4, 9, 3, generator=gen, dtype=torch.float64)
    ).requires_grad_()
    assert torch.autograd.gradcheck(lambda p: temporal_knn_distance(p, cloud, k=2), (preds,))


def test_chunked_time_accumulation(monkeypatch):
    from skelagnostic.metrics.functional import point_cloud

    gen = torch.Generator().manual_seed(3)
    target = torch.randn(2, 7, 6, 3, generator=gen, dtype=torch.float64)
    preds = torch.randn(2, 7, 5, 3, generator=gen, dtype=torch.float64)
    whole = temporal_knn_distance(preds, target, k=2)
    monkeypatch.setattr(point_cloud, "_KNN_CHUNK_ELEMENTS", 1)  # one frame at a time
    assert temporal_knn_distance(preds, target, k=2).item() == pytest.approx(whole.item())


def test_errors():
    target, preds = torch.zeros(4, 6, 3), torch.zeros(4, 5, 3)
    with pytest.raises(MotionError, match=r"body group 1 has 2 predicted points, fewer than k=3"):
        temporal_knn_distance(
            preds, target, preds_groups=[0, 0, 0, 1, 1], target_groups=[0, 1] * 3, k=3
        )
    with pytest.raises(MotionError, match=r"both preds_groups and target_groups"):
        temporal_knn_distance(preds, target, preds_groups=[0] * 5)
    with pytest.raises(MotionError, match=r"target_groups has 2 labels for 6 points"):
        temporal_knn_distance(preds, target, preds_groups=[0] * 5, target_groups=[0, 0])
    with pytest.raises(MotionError, match=r"sequence and frame dimensions"):
        temporal_knn_distance(torch.zeros(3, 5, 3), target)
    with pytest.raises(MotionError, match=r"k must be a positive integer"):
        TemporalKNNDistance(k=0)
    with pytest.raises(MotionError, match=r"preds contains infinite"):
        temporal_knn_distance(preds + float("inf"), target, k=1)
