"""Bone-length consistency (HuMoT Eq. 2): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import BoneLengthConsistency
from skelagnostic.metrics.functional import bone_length_consistency


def reference(preds: np.ndarray, target: np.ndarray, bones, ddof: int = 0) -> float:
    """Loop over sequences and bones: Var_t(pred length / gt length), averaged."""
    preds = preds.reshape(-1, *preds.shape[-3:])
    target = target.reshape(-1, *target.shape[-3:])
    values = []
    for p, t in zip(preds, target, strict=True):
        for parent, child in bones:
            lp = np.linalg.norm(p[:, child] - p[:, parent], axis=-1)
            lt = np.linalg.norm(t[:, child] - t[:, parent], axis=-1)
            values.append(np.var(lp / lt, ddof=ddof))
    return float(np.mean(values))


CHAIN = [(0, 1), (1, 2), (1, 3), (3, 4)]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("correction", [0, 1])
def test_random_against_reference(dtype, correction):
    gen = torch.Generator().manual_seed(0)
    target = torch.randn(3, 10, 5, 3, generator=gen, dtype=dtype)
    preds = target + 0.1 * torch.randn(3, 10, 5, 3, generator=gen, dtype=dtype)
    expected = reference(preds.double().numpy(), target.double().numpy(), CHAIN, correction)
    value = bone_length_consistency(preds, target, CHAIN, correction=correction)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-4 if dtype == torch.float32 else 1e-10)
    metric = BoneLengthConsistency(CHAIN, correction=correction)
    metric.update(preds[:1], target[:1])
    metric.update(preds[1:], target[1:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


def test_rigid_and_uniformly_scaled_bones_score_zero():
    gen = torch.Generator().manual_seed(1)
    target = torch.randn(8, 5, 3, generator=gen, dtype=torch.float64)
    assert bone_length_consistency(target, target, CHAIN).item() == 0.0
    assert bone_length_consistency(3.0 * target, target, CHAIN).item() == pytest.approx(0.0)


def test_hand_computed():
    target = torch.tensor([[0.0, 0, 0], [0, 1, 0]]).expand(4, 2, 3)
    preds = target * torch.tensor([1.0, 1.0, 1.0, 3.0])[:, None, None]
    # ratios 1, 1, 1, 3: mean 1.5, population variance (3 * 0.25 + 2.25) / 4 = 0.75
    assert bone_length_consistency(preds, target, [(0, 1)]).item() == pytest.approx(0.75)
    assert bone_length_consistency(preds, target, [(0, 1)], correction=1).item() == pytest.approx(
        1.0
    )


@pytest.mark.data
def test_real_clip(lafan_clip):
    motion = sa.read_bvh(lafan_clip)
    target = motion.global_positions()[:100].double()
    bones = motion.skeleton.bones()
    noisy = target + torch.randn(
        target.shape, generator=torch.Generator().manual_seed(2), dtype=torch.float64
    )
    expected = reference(noisy.numpy(), target.numpy(), bones)
    assert bone_length_consistency(noisy, target, bones).item() == pytest.approx(expected)
    # forward kinematics keeps bones rigid
    assert bone_length_consistency(target, target, bones).item() < 1e-20


def test_gradient():
    gen = torch.Generator().manual_seed(3)
    target = torch.randn(4, 3, 3, generator=gen, dtype=torch.float64)
    preds = (
        target + 0.1 * torch.randn(4, 3, 3, generator=gen, dtype=torch.float64)
    ).requires_grad_()
    assert torch.autograd.gradcheck(
        lambda p: bone_length_consistency(p, target, [(0, 1), (1, 2)]), (preds,)
    )


def test_errors():
    x = torch.randn(2, 5, 4, 3)
    with pytest.raises(MotionError, match=r"joints differ: 4 vs 3"):
        bone_length_consistency(x, x[..., :3, :], [(0, 1)])
    with pytest.raises(MotionError, match=r"beyond the 4 joints"):
        bone_length_consistency(x, x, [(0, 4)])
    with pytest.raises(MotionError, match=r"\(parent, child\) pairs"):
        bone_length_consistency(x, x, [(0, 0)])
    with pytest.raises(MotionError, match=r"at least one"):
        BoneLengthConsistency([])
    zero = x.clone()
    zero[:, 2, 3] = zero[:, 2, 1]
    with pytest.raises(MotionError, match=r"target bone \(1, 3\) has zero length"):
        bone_length_consistency(x, zero, [(0, 1), (1, 3)])
    with pytest.raises(MotionError, match=r"more than 1 frame"):
        bone_length_consistency(x[:, :1], x[:, :1], [(0, 1)], correction=1)
    with pytest.raises(MotionError, match=r"preds contains NaN"):
        bone_length_consistency(x * float("nan"), x, [(0, 1)])
    assert BoneLengthConsistency([(0, 1)]).higher_is_better is False
