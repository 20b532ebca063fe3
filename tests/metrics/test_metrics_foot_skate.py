"""Foot skate: checked against a loop written from the definition, by hand and on real clips."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic.errors import MotionError
from skelagnostic.metrics import FootSkate, FootSkateRatio
from skelagnostic.metrics.functional import foot_skate, foot_skate_ratio


def reference(positions: np.ndarray, contacts: np.ndarray, fps: float, up: int) -> list[float]:
    """Planted-step speeds by explicit loops over sequences, feet and frames."""
    speeds = []
    flat_p = positions.reshape(-1, *positions.shape[-3:])
    flat_c = contacts.reshape(-1, *contacts.shape[-2:])
    for seq_p, seq_c in zip(flat_p, flat_c, strict=True):
        for f in range(seq_p.shape[1]):
            for t in range(seq_p.shape[0] - 1):
                if seq_c[t, f] and seq_c[t + 1, f]:
                    d = seq_p[t + 1, f] - seq_p[t, f]
                    d = np.delete(d, up)
                    speeds.append(float(np.hypot(d[0], d[1])) * fps)
    return speeds


@pytest.mark.parametrize("up_axis,up", [("y", 1), ("z", 2), (0, 0)])
def test_random_batches_match_the_loop(up_axis, up):
    gen = torch.Generator().manual_seed(7)
    positions = torch.randn(3, 2, 9, 4, 3, generator=gen, dtype=torch.float64)
    contacts = torch.rand(3, 2, 9, 4, generator=gen) < 0.5
    speeds = reference(positions.numpy(), contacts.numpy(), 24.0, up)
    assert len(speeds) > 10
    value = foot_skate(positions, contacts, 24.0, up_axis=up_axis)
    assert value.item() == pytest.approx(np.mean(speeds))
    threshold = float(np.median(speeds))
    ratio = foot_skate_ratio(positions, contacts, 24.0, threshold, up_axis=up_axis)
    assert ratio.item() == pytest.approx(np.mean(np.array(speeds) > threshold))


def test_hand_computed_vertical_motion_does_not_skate():
    positions = torch.zeros(5, 2, 3)
    positions[:, 0, 1] = torch.tensor([0.0, 0.5, 1.0, 0.5, 0.0])  # foot 0 lifts straight up
    positions[:, 1, 0] = torch.arange(5.0) * 0.02  # foot 1 slides 0.02 per frame along x
    contacts = torch.ones(5, 2, dtype=torch.bool)
    # foot 0: 4 steps at 0; foot 1: 4 steps at 0.02 * 50 = 1.0 unit/s
    assert foot_skate(positions, contacts, fps=50.0).item() == pytest.approx(0.5)
    assert foot_skate_ratio(positions, contacts, fps=50.0, threshold=0.9).item() == 0.5
    # with z up, foot 0's lift is horizontal motion: 0.5 per frame * 50 = 25 units/s
    assert foot_skate(positions, contacts, fps=50.0, up_axis="z").item() == pytest.approx(13.0)


def test_steps_need_contact_at_both_frames():
    positions = torch.zeros(4, 1, 3)
    positions[:, 0, 0] = torch.tensor([0.0, 1.0, 2.0, 3.0])
    contacts = torch.tensor([[True], [False], [True], [True]])
    assert foot_skate(positions, contacts, fps=1.0).item() == pytest.approx(1.0)  # only 2->3
    none = torch.zeros(4, 1, dtype=torch.bool)
    assert torch.isnan(foot_skate(positions, none, fps=1.0))


def test_feet_select_joints_and_classes_accumulate():
    gen = torch.Generator().manual_seed(3)
    batches = [torch.randn(b, 6, 5, 3, generator=gen) for b in (2, 1, 3)]
    masks = [torch.rand(b, 6, 2, generator=gen) < 0.7 for b in (2, 1, 3)]
    metric, ratio = FootSkate(fps=30.0, feet=[4, 1]), FootSkateRatio(30.0, 20.0, feet=[4, 1])
    for positions, contacts in zip(batches, masks, strict=True):
        metric.update(positions, contacts)
        ratio.update(positions, contacts)
    every = [
        s
        for p, c in zip(batches, masks, strict=True)
        for s in reference(p[..., [4, 1], :].numpy(), c.numpy(), 30.0, 1)
    ]
    assert metric.compute().item() == pytest.approx(np.mean(every), rel=1e-5)
    assert ratio.compute().item() == pytest.approx(np.mean(np.array(every) > 20.0))


@pytest.mark.data
def test_real_clip_planted_feet_barely_move_and_a_slide_is_measured(lafan_clip):
    motion = sa.read_bvh(lafan_clip).to_metres()
    positions = motion.global_positions()[:300].double()
    sk = motion.skeleton
    up = sk.up_index
    # the feet: the two end effectors that are lowest most of the time
    effectors = sk.end_effectors()
    typical = positions[:, effectors, up].median(dim=0).values
    feet = [effectors[i] for i in typical.argsort()[:2].tolist()]
    assert all("Toe" in sk.joint_names[j] or "Foot" in sk.joint_names[j] for j in feet)
    height = positions[..., feet, up]
    speed = torch.zeros_like(height)
    speed[1:] = torch.linalg.vector_norm(positions[1:, feet] - positions[:-1, feet], dim=-1) * 30
    # an independent labelling: low (within 4 cm of the clip's lowest) and slow (< 0.4 m/s)
    contacts = (height < height.min(dim=0).values + 0.04) & (speed < 0.4)
    assert contacts.float().mean() > 0.2
    planted = foot_skate(positions, contacts, fps=motion.fps, up_axis=sk.up_axis, feet=feet)
    assert 0.0 <= planted.item() < 0.25  # m/s: real planted feet barely slide
    slide = positions.clone()
    slide[..., 0] += torch.arange(len(slide), dtype=slide.dtype)[:, None] * (0.5 / motion.fps)
    skating = foot_skate(slide, contacts, fps=motion.fps, up_axis=sk.up_axis, feet=feet)
    assert skating.item() > planted.item() + 0.3  # the 0.5 m/s drift shows
    assert foot_skate_ratio(slide, contacts, motion.fps, 0.3, up_axis=sk.up_axis, feet=feet) > 0.8


def test_gradient():
    gen = torch.Generator().manual_seed(1)
    positions = torch.randn(5, 2, 3, generator=gen, dtype=torch.float64).requires_grad_()
    contacts = torch.ones(5, 2, dtype=torch.bool)
    assert torch.autograd.gradcheck(lambda p: foot_skate(p, contacts, 30.0), (positions,))


def test_errors():
    positions, contacts = torch.zeros(4, 2, 3), torch.ones(4, 2, dtype=torch.bool)
    with pytest.raises(MotionError, match=r"foot_skate: contacts must be a boolean tensor"):
        foot_skate(positions, contacts.float(), 30.0)
    with pytest.raises(MotionError, match=r"contacts must have shape \[4, 2\]"):
        foot_skate(positions, contacts[:, :1], 30.0)
    with pytest.raises(MotionError, match=r"fps must be a finite number > 0, got 0"):
        foot_skate(positions, contacts, 0)
    with pytest.raises(MotionError, match=r"up_axis must be 'x', 'y', 'z'"):
        foot_skate(positions, contacts, 30.0, up_axis="up")
    with pytest.raises(MotionError, match=r"at least 2 frames"):
        foot_skate(positions[:1], contacts[:1], 30.0)
    with pytest.raises(MotionError, match=r"feet \[5\] refer to joints beyond the 2 joints"):
        foot_skate(positions, contacts[:, :1], 30.0, feet=[5])
    bad = positions.clone()
    bad[2, 1, 0] = float("nan")
    with pytest.raises(MotionError, match=r"positions contains NaN"):
        foot_skate(bad, contacts, 30.0)
    with pytest.raises(MotionError, match=r"threshold must be a finite number >= 0"):
        FootSkateRatio(fps=30.0, threshold=float("nan"))
    with pytest.raises(MotionError, match=r"FootSkate: fps must be"):
        FootSkate(fps=-1.0)
