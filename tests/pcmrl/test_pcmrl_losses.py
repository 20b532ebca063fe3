"""KNN loss (Eq. 5), end-effector loss (Eq. 6) and unit-norm penalty against loop references."""

from __future__ import annotations

import math

import pytest
import torch
from skelagnostic_pcmrl.recon.losses import end_effector_loss, temporal_knn_loss, unit_norm_penalty

from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import temporal_knn_distance


def _brute_force(preds, target, g_p, g_t, k):
    """Eq. 5 with loops: per target point, trajectory distance to every same-group point."""
    frames = preds.shape[0]
    total = 0.0
    for a in range(target.shape[1]):
        deltas = []
        for b in range(preds.shape[1]):
            if g_p[b] != g_t[a]:
                continue
            deltas.append(sum(float((target[t, a] - preds[t, b]).norm()) for t in range(frames)))
        total += sum(sorted(deltas)[:k])
    return total


def _clouds(seed: int, batch: int = 2, frames: int = 5, n: int = 40, m: int = 12):
    gen = torch.Generator().manual_seed(seed)
    preds = torch.randn(batch, frames, n, 3, generator=gen, dtype=torch.float64)
    target = torch.randn(batch, frames, m, 3, generator=gen, dtype=torch.float64)
    g_p = torch.randint(0, 3, (batch, n), generator=gen)
    g_t = torch.randint(0, 3, (batch, m), generator=gen)
    return preds, target, g_p, g_t


def test_knn_loss_equals_brute_force_sum_and_mean() -> None:
    preds, target, g_p, g_t = _clouds(0)
    k = 4
    ref = [_brute_force(preds[b], target[b], g_p[b].tolist(), g_t[b].tolist(), k) for b in range(2)]
    loss_sum = temporal_knn_loss(preds, target, g_p, g_t, k=k, reduction="sum")
    assert math.isclose(float(loss_sum), sum(ref) / 2, rel_tol=1e-9)
    loss_mean = temporal_knn_loss(preds, target, g_p, g_t, k=k)
    assert math.isclose(float(loss_mean), sum(r / (12 * k * 5) for r in ref) / 2, rel_tol=1e-9)


def test_knn_loss_agrees_with_the_core_metric_and_is_differentiable() -> None:
    preds, target, g_p, g_t = _clouds(1, batch=1)
    preds.requires_grad_(True)
    loss = temporal_knn_loss(preds, target, g_p[0], g_t[0], k=3)
    ref = temporal_knn_distance(
        preds[0].detach(), target[0], preds_groups=g_p[0], target_groups=g_t[0], k=3
    )
    assert math.isclose(float(loss.detach()), float(ref), rel_tol=1e-9)
    loss.backward()
    assert preds.grad is not None and preds.grad.abs().sum() > 0
    # gradient of the selected-pair recomputation = gradient through the full distance matrix
    p2 = preds.detach().clone().requires_grad_(True)
    delta = torch.cdist(target[0], p2[0]).sum(0)
    delta = delta.masked_fill(g_t[0][:, None] != g_p[0][None, :], float("inf"))
    full = delta.topk(3, dim=-1, largest=False).values.sum() / (12 * 3 * 5)
    full.backward()
    assert torch.allclose(preds.grad, p2.grad, atol=1e-12)


def test_knn_loss_is_zero_for_identical_clouds_and_respects_groups() -> None:
    gen = torch.Generator().manual_seed(2)
    pts = torch.randn(1, 4, 16, 3, generator=gen)
    groups = torch.arange(16) % 2
    # k = 1: every point's nearest same-group neighbour is itself
    assert float(temporal_knn_loss(pts, pts, groups, groups, k=1)) == pytest.approx(0.0, abs=1e-6)
    # swapping the groups of the predicted cloud forbids the self matches
    assert float(temporal_knn_loss(pts, pts, 1 - groups, groups, k=1)) > 0.1


def test_authors_variant_terms() -> None:
    """Three terms / sqrt(T): a pure translation changes the global and not the normalised term."""
    gen = torch.Generator().manual_seed(3)
    pts = torch.randn(1, 9, 20, 3, generator=gen)
    groups = torch.zeros(20, dtype=torch.long)
    moved = pts + torch.tensor([0.5, 0.0, 0.0])
    loss = temporal_knn_loss(moved, pts, groups, groups, k=1, variant="authors")
    # global term: |flattened trajectory difference| = sqrt(9 * 0.5^2), / sqrt(9);
    # normalised and velocity terms: 0
    assert float(loss) == pytest.approx(0.5, rel=1e-5)
    assert float(temporal_knn_loss(pts, pts, groups, groups, k=1, variant="authors")) == (
        pytest.approx(0.0, abs=1e-5)
    )


def test_knn_loss_rejects_bad_arguments() -> None:
    preds, target, g_p, g_t = _clouds(4)
    with pytest.raises(SkelagnosticError, match="variant"):
        temporal_knn_loss(preds, target, g_p, g_t, variant="x")
    with pytest.raises(SkelagnosticError, match="frames differ"):
        temporal_knn_loss(preds[:, :3], target, g_p, g_t)
    with pytest.raises(SkelagnosticError, match="entries"):
        temporal_knn_loss(preds, target, g_p[:, :5], g_t)


def test_end_effector_loss_is_eq6() -> None:
    src = torch.zeros(2, 3, 4, 3)
    pred = torch.zeros(2, 3, 5, 3)
    pred[:, :, 4, 1] = 2.0  # target joint 4 is 2 away from source joint 1 in every frame
    pred[0, 0, 2, 0] = 3.0  # target joint 2 is 3 away in one of three frames of sequence 0
    loss = end_effector_loss(pred, src, [(1, 4), (0, 2)])
    assert float(loss) == pytest.approx((2.0 + 1.0 + 2.0) / 2)
    assert float(end_effector_loss(pred, src, [])) == 0.0


def test_unit_norm_penalty() -> None:
    q = torch.tensor([[1.0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, 0, 0.5]])
    assert float(unit_norm_penalty(q)) == pytest.approx((0 + 1 + 0.25) / 3)
