"""L2P (LaFAN1 normalised global-position error): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import L2P
from skelagnostic.metrics.functional import l2p


def reference(preds: np.ndarray, target: np.ndarray, mean, std, mask=None) -> float:
    """The LaFAN1 benchmark lines: [B, J*3, T] layout, norm over channels, mean over frames."""
    b, t, j, _ = preds.shape
    p = (preds.reshape(b, t, j * 3).transpose(0, 2, 1) - mean) / std
    g = (target.reshape(b, t, j * 3).transpose(0, 2, 1) - mean) / std
    per_frame = np.sqrt(np.sum((p - g) ** 2.0, axis=1))  # [B, T]
    if mask is not None:
        per_frame = per_frame[mask]
    return float(np.mean(per_frame))


def random_case(seed=0, dtype=torch.float64, shape=(4, 9, 5)):
    gen = torch.Generator().manual_seed(seed)
    b, t, j = shape
    target = 50 * torch.randn(b, t, j, 3, generator=gen, dtype=dtype)
    preds = target + 10 * torch.randn(b, t, j, 3, generator=gen, dtype=dtype)
    mean = 20 * torch.randn(1, j * 3, 1, generator=gen, dtype=dtype)  # LaFAN1 layout
    std = 30 + 5 * torch.rand(1, j * 3, 1, generator=gen, dtype=dtype)
    return preds, target, mean, std


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_matches_benchmark_transcription(dtype):
    preds, target, mean, std = random_case(dtype=dtype)
    expected = reference(*(x.double().numpy() for x in (preds, target, mean, std)))
    value = l2p(preds, target, mean, std)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-12)
    # the statistics may also be given flat [J*3] or per joint [J, 3]
    assert l2p(preds, target, mean.flatten(), std.reshape(-1, 3)).item() == pytest.approx(
        expected, rel=1e-5
    )


def test_mask_selects_transition_frames():
    preds, target, mean, std = random_case(seed=1)
    mask = torch.zeros(4, 9, dtype=torch.bool)
    mask[:, 3:7] = True
    mask[2, 7] = True
    expected = reference(*(x.numpy() for x in (preds, target, mean, std)), mask=mask.numpy())
    assert l2p(preds, target, mean, std, mask).item() == pytest.approx(expected)
    assert l2p(preds, target, mean, std, mask.long()).item() == pytest.approx(expected)

    metric = L2P(mean, std)
    metric.update(preds[:1], target[:1], mask[:1])
    metric.update(preds[1:], target[1:], mask[1:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-6)


def test_hand_computed():
    target = torch.zeros(1, 2, 2, 3)
    preds = target.clone()
    preds[0, 0, 1] = torch.tensor([3.0, 0.0, 4.0])  # frame 0: distance 5 before scaling
    std = torch.tensor([1.0, 1.0, 1.0, 0.5, 1.0, 0.5])  # joint 1: x and z halved -> (6, 0, 8)
    assert l2p(preds, target, 0.0, std).item() == pytest.approx((10.0 + 0.0) / 2)
    # the mean cancels out in the difference
    assert l2p(preds, target, torch.arange(6.0), std).item() == pytest.approx(5.0)


@pytest.mark.data
def test_real_clip_against_reference(lafan_clip):
    pos = sa.read_bvh(lafan_clip).global_positions()[:200].double()
    windows = pos.unfold(0, 40, 40).permute(0, 3, 1, 2)  # [5, 40, J, 3]
    target, preds = windows[:, 1:], windows[:, :-1]  # previous frame as the prediction
    flat = pos.reshape(len(pos), -1)
    mean, std = flat.mean(0), flat.std(0)
    expected = reference(
        preds.numpy(), target.numpy(), mean.numpy()[None, :, None], std.numpy()[None, :, None]
    )
    assert l2p(preds, target, mean, std).item() == pytest.approx(expected, rel=1e-10)


def test_gradient():
    preds, target, mean, std = random_case(seed=2, shape=(2, 3, 2))
    preds.requires_grad_()
    assert torch.autograd.gradcheck(lambda p: l2p(p, target, mean, std), (preds,))


def test_errors():
    x = torch.zeros(2, 3, 4, 3)
    mean, std = torch.zeros(12), torch.ones(12)
    with pytest.raises(MotionError, match=r"frames differ: 3 vs 5"):
        l2p(x, torch.zeros(2, 5, 4, 3), mean, std)
    with pytest.raises(MotionError, match=r"joints differ: 4 vs 2"):
        l2p(x, torch.zeros(2, 3, 2, 3), mean, std)
    with pytest.raises(MotionError, match=r"\[B, T, J, 3\]"):
        l2p(x[0], x[0], mean, std)
    with pytest.raises(MotionError, match=r"preds contains NaN"):
        l2p(x.clone().fill_(float("nan")), x, mean, std)
    with pytest.raises(MotionError, match=r"mean must have J\*3 = 12 values"):
        l2p(x, x, torch.zeros(11), std)
    with pytest.raises(MotionError, match=r"std must be > 0"):
        l2p(x, x, mean, torch.zeros(12))
    with pytest.raises(MotionError, match=r"mask must have shape \[B, T\]"):
        l2p(x, x, mean, std, mask=torch.ones(2, 4, dtype=torch.bool))
    with pytest.raises(MotionError, match=r"mask selects no frame"):
        l2p(x, x, mean, std, mask=torch.zeros(2, 3, dtype=torch.bool))
    with pytest.raises(MotionError, match=r"only contain 0 and 1"):
        l2p(x, x, mean, std, mask=torch.full((2, 3), 2))
    with pytest.raises(MotionError, match=r"std must be > 0"):
        L2P(mean, -std)
    with pytest.raises(MotionError, match=r"finite"):
        L2P(mean * float("nan"), std)


def test_metric_class_properties():
    metric = L2P(torch.zeros(6), torch.ones(6))
    assert metric.higher_is_better is False and metric.is_differentiable is True
    assert "mean" not in metric.state_dict()  # statistics are configuration, not state
    with pytest.warns(UserWarning, match="before the ``update``"):
        assert torch.isnan(metric.compute())  # nothing accumulated yet
