"""NPSS (LaFAN1 fast_npss, real-part and magnitude power): both interfaces."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import NPSS
from skelagnostic.metrics.functional import feature_npss, npss


def fast_npss_np(gt_seq: np.ndarray, pred_seq: np.ndarray, power: str = "real") -> float:
    """Transcription of the published formula on [B, T, D] arrays."""
    if power == "real":
        gt_power = np.square(np.real(np.fft.fft(gt_seq, axis=1)))
        pred_power = np.square(np.real(np.fft.fft(pred_seq, axis=1)))
    else:
        gt_power = np.square(np.abs(np.fft.fft(gt_seq, axis=1)))
        pred_power = np.square(np.abs(np.fft.fft(pred_seq, axis=1)))
    gt_total = np.sum(gt_power, axis=1)
    pred_total = np.sum(pred_power, axis=1)
    cdf_gt = np.cumsum(gt_power / gt_total[:, None, :], axis=1)
    cdf_pred = np.cumsum(pred_power / pred_total[:, None, :], axis=1)
    emd = np.linalg.norm(cdf_pred - cdf_gt, ord=1, axis=1)
    return float(np.average(emd, weights=gt_total))


def remove_flips_np(q: torch.Tensor) -> torch.Tensor:
    """The benchmark's loop over time on [B, T, J, 4]: negate when the dot product is < 0."""
    q = q.numpy().copy()
    for i in range(1, q.shape[1]):
        flip = np.sum(q[:, i - 1] * q[:, i], axis=-1) < 0
        q[:, i] = np.where(flip[..., None], -q[:, i], q[:, i])
    return torch.from_numpy(q)


def flat(q: torch.Tensor) -> np.ndarray:
    return q.double().numpy().reshape(q.shape[0], q.shape[1], -1)


def smooth_pair(seed=0, dtype=torch.float64, batch=3, frames=16, joints=5):
    gen = torch.Generator().manual_seed(seed)
    base = torch.randn(batch, 1, joints, 4, generator=gen, dtype=dtype)
    drift = 0.1 * torch.randn(batch, frames, joints, 4, generator=gen, dtype=dtype).cumsum(1)
    target = torch.nn.functional.normalize(base + drift, dim=-1)
    noise = 0.2 * torch.randn(batch, frames, joints, 4, generator=gen, dtype=dtype)
    preds = torch.nn.functional.normalize(target + noise, dim=-1)
    return preds, target


@pytest.mark.parametrize("power", ["real", "abs"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_matches_fast_npss_transcription(power, dtype):
    preds, target = smooth_pair(dtype=dtype)
    expected = fast_npss_np(flat(target), flat(preds), power)
    value = npss(preds, target, power)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-4 if dtype == torch.float32 else 1e-10)


def test_real_and_abs_powers_differ():
    preds, target = smooth_pair(seed=1)
    assert npss(preds, target, "real").item() != pytest.approx(npss(preds, target, "abs").item())


def test_accumulation_is_the_weighted_average_over_all_sequences():
    """Batches of different sizes: the class equals one fast_npss call on everything."""
    preds, target = smooth_pair(seed=2, batch=5)
    expected = fast_npss_np(flat(target), flat(preds))
    metric = NPSS()
    metric.update(preds[:1], target[:1])
    metric.update(preds[1:], target[1:])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-6)
    # averaging per-batch values (what a per-rank mean would do) gives a different number
    per_batch = (npss(preds[:1], target[:1]) + npss(preds[1:], target[1:])) / 2
    assert per_batch.item() != pytest.approx(expected, rel=1e-6)


def test_mask_runs_of_different_lengths():
    preds, target = smooth_pair(seed=3, batch=4, frames=20)
    starts, lengths = [10, 10, 3, 0], [5, 8, 5, 20]
    mask = torch.zeros(4, 20, dtype=torch.bool)
    for row, (s, n) in enumerate(zip(starts, lengths, strict=True)):
        mask[row, s : s + n] = True
    # reference: weighted sums per sequence, combined
    num = den = 0.0
    for row, (s, n) in enumerate(zip(starts, lengths, strict=True)):
        gt, pr = flat(target[row : row + 1, s : s + n]), flat(preds[row : row + 1, s : s + n])
        weight = np.sum(np.square(np.real(np.fft.fft(gt, axis=1))), axis=1).sum()
        num += fast_npss_np(gt, pr) * weight
        den += weight
    assert npss(preds, target, mask=mask).item() == pytest.approx(num / den)
    metric = NPSS()
    metric.update(preds, target, mask)
    assert metric.compute().item() == pytest.approx(num / den, rel=1e-6)


def test_hand_computed_cases():
    t = torch.arange(8.0, dtype=torch.float64)
    target = torch.stack([torch.cos(t), torch.sin(t), 0 * t, 0 * t], -1)[None, :, None]
    assert npss(target, target).item() == pytest.approx(0.0)
    # a constant signal has all its power at f=0 (CDF = 1 everywhere); a single
    # non-zero frame has a flat spectrum (CDF = (f+1)/T): EMD = sum_f (1 - (f+1)/T) = (T-1)/2
    const = torch.ones(1, 8, 1, 4, dtype=torch.float64)
    impulse = torch.zeros(1, 8, 1, 4, dtype=torch.float64)
    impulse[0, 0] = 1.0
    assert npss(impulse, const, continuity=False).item() == pytest.approx(3.5)
    assert npss(impulse, const, "abs", continuity=False).item() == pytest.approx(3.5)


def test_zero_power_channels_do_not_produce_nan():
    preds, target = smooth_pair(seed=4)
    target[..., 3] = 0.0
    preds[..., 3] = 0.0
    value = npss(preds, target, continuity=False)
    assert torch.isfinite(value)
    keep = [c for c in range(20) if c % 4 != 3]
    expected = fast_npss_np(flat(target)[..., keep], flat(preds)[..., keep])
    assert value.item() == pytest.approx(expected)


def test_sign_flips_are_removed_first():
    preds, target = smooth_pair(seed=5)
    flipped = target.clone()
    flipped[:, 7:] *= -1
    assert npss(preds, flipped).item() == pytest.approx(npss(preds, target).item())


@pytest.mark.data
def test_real_clip_against_reference(lafan_clip):
    quats = sa.read_bvh(lafan_clip).global_rotations()[:300].double()
    windows = quats.unfold(0, 30, 30).permute(0, 3, 1, 2)  # [10, 30, J, 4]
    target, preds = windows[:, 3:], windows[:, :-3]
    # read_bvh keeps the file's quaternion signs: the benchmark removes the flips first
    expected = fast_npss_np(flat(remove_flips_np(target)), flat(remove_flips_np(preds)))
    assert npss(preds, target).item() == pytest.approx(expected, rel=1e-9)
    without = fast_npss_np(flat(target), flat(preds))
    assert npss(preds, target, continuity=False).item() == pytest.approx(without, rel=1e-9)


def test_gradient():
    preds, target = smooth_pair(seed=6, batch=1, frames=6, joints=1)
    preds.requires_grad_()
    assert torch.autograd.gradcheck(lambda p: npss(p, target, "abs"), (preds,))


def test_errors():
    preds, target = smooth_pair(seed=7)
    with pytest.raises(MotionError, match=r"power must be one of"):
        npss(preds, target, "complex")
    with pytest.raises(MotionError, match=r"power must be one of"):
        NPSS(power="mag")
    with pytest.raises(MotionError, match=r"joints differ: 5 vs 4"):
        npss(preds, target[:, :, :4])
    with pytest.raises(MotionError, match=r"preds contains NaN"):
        npss(preds * float("nan"), target)
    mask = torch.zeros(3, 16, dtype=torch.bool)
    mask[:, [2, 3, 6]] = True
    with pytest.raises(MotionError, match=r"one contiguous run"):
        npss(preds, target, mask=mask)
    mask[1] = False
    with pytest.raises(MotionError, match=r"no frame in sequence 1"):
        npss(preds, target, mask=mask)
    metric = NPSS()
    assert metric.higher_is_better is False and metric.full_state_update is False


@pytest.mark.parametrize("power", ["real", "abs"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_feature_npss_matches_fast_npss_transcription_on_any_channels(power, dtype):
    """Positions and rotations side by side (PC-MRL's Table 1 layout), no quaternion rule."""
    gen = torch.Generator().manual_seed(8)
    target = torch.randn(3, 20, 7, generator=gen, dtype=torch.float64).cumsum(1)
    preds = target + 0.3 * torch.randn(3, 20, 7, generator=gen, dtype=torch.float64)
    expected = fast_npss_np(target.numpy(), preds.numpy(), power)
    value = feature_npss(preds.to(dtype), target.to(dtype), power)
    assert value.dtype == dtype
    assert value.item() == pytest.approx(expected, rel=1e-5 if dtype == torch.float32 else 1e-9)
    # no continuity step: negating a channel of both inputs changes nothing, of one input it does
    flipped = preds.clone()
    flipped[:, 5:, 0] *= -1
    assert feature_npss(flipped, target, power).item() == pytest.approx(
        fast_npss_np(target.numpy(), flipped.numpy(), power), rel=1e-9
    )


def test_feature_npss_errors():
    x = torch.randn(2, 8, 3)
    with pytest.raises(MotionError, match=r"power must be one of"):
        feature_npss(x, x, "complex")
    with pytest.raises(MotionError, match=r"channels differ: 3 vs 2"):
        feature_npss(x, x[..., :2])
    with pytest.raises(MotionError, match=r"shape \[B, T, D\]"):
        feature_npss(x[None], x[None])
    with pytest.raises(MotionError, match=r"preds contains NaN"):
        feature_npss(x * float("nan"), x)
