"""End-effector error (PC-MRL Eq. 6): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import EndEffectorError
from skelagnostic.metrics.functional import end_effector_error


def reference(preds, target, pairs, reduction="sum") -> float:
    """Eq. 6 per sequence: sum over pairs of the mean over frames, then mean over sequences."""
    preds = preds.reshape(-1, *preds.shape[-3:])
    target = target.reshape(-1, *target.shape[-3:])
    values = []
    for p, t in zip(preds, target, strict=True):
        per_pair = [np.mean(np.linalg.norm(p[:, b] - t[:, a], axis=-1)) for a, b in pairs]
        values.append(np.sum(per_pair) if reduction == "sum" else np.mean(per_pair))
    return float(np.mean(values))


@pytest.mark.parametrize("reduction", ["sum", "mean"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_random_two_skeletons(reduction, dtype):
    gen = torch.Generator().manual_seed(0)
    target = torch.randn(3, 7, 6, 3, generator=gen, dtype=dtype)  # skeleton A: 6 joints
    preds = torch.randn(3, 7, 4, 3, generator=gen, dtype=dtype)  # skeleton B: 4 joints
    pairs = [(5, 3), (2, 1), (0, 0)]  # (target joint, preds joint)
    idx_t, idx_p = [a for a, _ in pairs], [b for _, b in pairs]
    expected = reference(preds.double().numpy(), target.double().numpy(), pairs, reduction)
    value = end_effector_error(
        preds, target, preds_indices=idx_p, target_indices=idx_t, reduction=reduction
    )
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-12)
    metric = EndEffectorError(idx_p, idx_t, reduction=reduction)
    metric.update(preds[:2], target[:2])
    metric.update(preds[2:], target[2:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_mean_abs_is_the_authors_flat_mean(dtype):
    """``distance="mean_abs", reduction="mean"``: one mean of |difference| over everything.

    The PC-MRL authors' ``train_pointcloud.py`` takes the mean absolute difference over
    sequences, frames, effectors and coordinates at once (sequences of equal length).
    """
    gen = torch.Generator().manual_seed(2)
    target = torch.randn(3, 7, 6, 3, generator=gen, dtype=dtype)
    preds = torch.randn(3, 7, 4, 3, generator=gen, dtype=dtype)
    pairs = [(5, 3), (2, 1), (0, 0), (1, 2)]
    idx_t, idx_p = [a for a, _ in pairs], [b for _, b in pairs]
    p, t = preds.double().numpy(), target.double().numpy()
    expected = float(np.mean(np.abs(p[:, :, idx_p] - t[:, :, idx_t])))
    value = end_effector_error(
        preds,
        target,
        preds_indices=idx_p,
        target_indices=idx_t,
        reduction="mean",
        distance="mean_abs",
    )
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-12)
    # summed over pairs: the number of pairs times the mean
    summed = end_effector_error(
        preds, target, preds_indices=idx_p, target_indices=idx_t, distance="mean_abs"
    )
    assert summed.item() == pytest.approx(len(pairs) * expected, rel=1e-5)
    metric = EndEffectorError(idx_p, idx_t, reduction="mean", distance="mean_abs")
    metric.update(preds[:1], target[:1])
    metric.update(preds[1:], target[1:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


def test_mean_abs_hand_computed():
    target = torch.zeros(2, 2, 3)
    preds = torch.zeros(2, 2, 3)
    preds[0, 1] = torch.tensor([3.0, 4.0, 0.0])  # Euclidean 5, mean |d| 7 / 3
    euclid = end_effector_error(preds, target, reduction="mean")
    mean_abs = end_effector_error(preds, target, reduction="mean", distance="mean_abs")
    assert euclid.item() == pytest.approx(5.0 / 4)  # one of 2 frames x 2 effectors
    assert mean_abs.item() == pytest.approx(7.0 / 3 / 4)


def test_hand_computed():
    target = torch.zeros(2, 5, 3)
    preds = torch.zeros(2, 3, 3)
    preds[1, 2, 1] = 4.0
    value = end_effector_error(preds, target, preds_indices=[1, 2], target_indices=[3, 4])
    assert value.item() == pytest.approx(2.0)  # pair (4, 2): (0 + 4) / 2 frames
    same = end_effector_error(preds, target[:, :3])  # all joints, one-to-one
    assert same.item() == pytest.approx(2.0)
    assert end_effector_error(preds, target[:, :3], reduction="mean").item() == pytest.approx(2 / 3)


@pytest.mark.data
def test_real_clip_end_effectors(lafan_clip):
    motion = sa.read_bvh(lafan_clip)
    pos = motion.global_positions()[:90].double()
    effectors = motion.skeleton.end_effectors()
    assert len(effectors) == 5
    target, preds = pos[:-3], pos[3:]
    pairs = [(j, j) for j in effectors]
    expected = reference(preds.numpy(), target.numpy(), pairs)
    value = end_effector_error(preds, target, preds_indices=effectors, target_indices=effectors)
    assert value.item() == pytest.approx(expected)


def test_gradient():
    gen = torch.Generator().manual_seed(1)
    target = torch.randn(4, 3, 3, generator=gen, dtype=torch.float64)
    preds = torch.randn(4, 3, 3, generator=gen, dtype=torch.float64).requires_grad_()
    assert torch.autograd.gradcheck(lambda p: end_effector_error(p, target), (preds,))


def test_errors():
    target = torch.zeros(2, 5, 3)
    with pytest.raises(MotionError, match=r"distance must be one of"):
        end_effector_error(torch.zeros(2, 5, 3), target, distance="l1")
    with pytest.raises(MotionError, match=r"distance must be one of"):
        EndEffectorError(distance="l1")
    with pytest.raises(MotionError, match=r"3 predicted vs 5 target end effectors"):
        end_effector_error(torch.zeros(2, 3, 3), target)
    with pytest.raises(MotionError, match=r"sequence and frame dimensions"):
        end_effector_error(torch.zeros(3, 5, 3), target)
    with pytest.raises(MotionError, match=r"target_indices \[7\] out of range for 5 joints"):
        end_effector_error(torch.zeros(2, 5, 3), target, preds_indices=[0], target_indices=[7])
    with pytest.raises(MotionError, match=r"preds_indices must be a non-empty"):
        EndEffectorError(preds_indices=[])
    with pytest.raises(MotionError, match=r"reduction must be one of"):
        EndEffectorError(reduction="max")
    with pytest.raises(MotionError, match=r"target contains NaN"):
        end_effector_error(target, target * float("nan"))
