"""L2Q (LaFAN1 global-quaternion error): both interfaces, sign-continuity handling."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import L2Q
from skelagnostic.metrics.functional import l2q


def remove_discontinuities_np(q: np.ndarray) -> np.ndarray:
    """The benchmark's loop over time ([B, T, J, 4] here, axis 1)."""
    q = q.copy()
    for i in range(1, q.shape[1]):
        flip = np.sum(q[:, i - 1] * q[:, i], axis=-1) < np.sum(q[:, i - 1] * -q[:, i], axis=-1)
        q[:, i] = np.where(flip[..., None], -q[:, i], q[:, i])
    return q


def reference(preds, target, mask=None, continuity=True) -> float:
    if continuity:
        preds, target = remove_discontinuities_np(preds), remove_discontinuities_np(target)
    per_frame = np.sqrt(np.sum((preds - target) ** 2.0, axis=(2, 3)))
    return float(np.mean(per_frame if mask is None else per_frame[mask]))


def random_quats(shape, gen, dtype=torch.float64):
    return torch.nn.functional.normalize(torch.randn(*shape, 4, generator=gen, dtype=dtype), dim=-1)


def smooth_pair(seed=0, dtype=torch.float64):
    """Slowly varying quaternions (continuous) and a perturbed prediction."""
    gen = torch.Generator().manual_seed(seed)
    base = random_quats((3, 1, 6), gen, dtype)
    drift = 0.05 * torch.randn(3, 12, 6, 4, generator=gen, dtype=dtype).cumsum(1)
    target = torch.nn.functional.normalize(base + drift, dim=-1)
    preds = torch.nn.functional.normalize(
        target + 0.1 * random_quats((3, 12, 6), gen, dtype), dim=-1
    )
    return preds, target


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_matches_benchmark_transcription(dtype):
    preds, target = smooth_pair(dtype=dtype)
    expected = reference(preds.double().numpy(), target.double().numpy())
    value = l2q(preds, target)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-12)


def test_random_quaternions_with_flips_match_reference():
    gen = torch.Generator().manual_seed(1)
    preds, target = random_quats((4, 10, 5), gen), random_quats((4, 10, 5), gen)
    for continuity in (True, False):
        expected = reference(preds.numpy(), target.numpy(), continuity=continuity)
        assert l2q(preds, target, continuity=continuity).item() == pytest.approx(expected)


def test_sign_flips_do_not_count_as_errors():
    preds, target = smooth_pair(seed=2)
    flipped = target.clone()
    flipped[:, 5:8] *= -1  # same rotations, opposite sign on a few frames
    flipped[1, 3:, 2] *= -1
    assert l2q(preds, flipped).item() == pytest.approx(l2q(preds, target).item())
    assert l2q(target, flipped).item() == pytest.approx(0.0, abs=1e-12)
    assert l2q(target, flipped, continuity=False).item() > 0.5


def test_mask_and_class_accumulation():
    preds, target = smooth_pair(seed=3)
    mask = torch.zeros(3, 12, dtype=torch.bool)
    mask[:, 4:9] = True
    expected = reference(preds.numpy(), target.numpy(), mask=mask.numpy())
    assert l2q(preds, target, mask).item() == pytest.approx(expected)
    metric = L2Q()
    metric.update(preds[:2], target[:2], mask[:2])
    metric.update(preds[2:], target[2:], mask[2:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-6)


def test_hand_computed():
    target = torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(1, 2, 3, 1)
    preds = target.clone()
    # frame 1: two joints each sqrt(2) away, so the frame norm is sqrt(4) = 2
    preds[0, 1, 0] = torch.tensor([0.0, 1.0, 0.0, 0.0])
    preds[0, 1, 2] = torch.tensor([0.0, 0.0, 1.0, 0.0])
    assert l2q(preds, target).item() == pytest.approx((0.0 + 2.0) / 2)


@pytest.mark.data
def test_real_clip_against_reference(lafan_clip):
    quats = sa.read_bvh(lafan_clip).global_rotations()[:240].double()
    windows = quats.unfold(0, 30, 30).permute(0, 3, 1, 2)  # [8, 30, J, 4]
    target, preds = windows[:, 2:], windows[:, :-2]
    expected = reference(preds.numpy(), target.numpy())
    assert l2q(preds, target).item() == pytest.approx(expected, rel=1e-10)
    assert 0.0 < expected < 1.0


def test_gradient():
    preds, target = smooth_pair(seed=4)
    preds = preds[:1, :3, :2].clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda p: l2q(p, target[:1, :3, :2]), (preds,))


def test_errors():
    q = torch.zeros(2, 3, 4, 4)
    q[..., 0] = 1
    with pytest.raises(MotionError, match=r"\[B, T, J, 4\]"):
        l2q(q[..., :3], q[..., :3])
    with pytest.raises(MotionError, match=r"frames differ: 3 vs 2"):
        l2q(q, q[:, :2])
    with pytest.raises(MotionError, match=r"target contains NaN"):
        l2q(q, q.clone().fill_(float("nan")))
    with pytest.raises(MotionError, match=r"mask selects no frame"):
        l2q(q, q, torch.zeros(2, 3, dtype=torch.bool))
    with pytest.raises(MotionError, match=r"mask must be a boolean or integer"):
        l2q(q, q, torch.ones(2, 3))
    assert L2Q().higher_is_better is False
