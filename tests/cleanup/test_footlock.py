"""Foot lock: planted feet stop sliding, the rest of the motion barely moves, nothing pops.

Skating is made on real clips by turning the upper legs with a smooth sway (the kind
of error a network's output has); contacts are labelled on the clean clip by an
independent rule (a foot low and slow), as a contact detector would on ground truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.analysis import foot_contacts
from skelagnostic.cleanup import contact_runs, foot_lock, leg_chain
from skelagnostic.core import quaternion as quat
from skelagnostic.errors import MotionError
from skelagnostic.metrics.functional import foot_skate, mpjpe


def lowest_effectors(motion: sa.Motion, count: int) -> list[int]:
    """The ``count`` end effectors that are lowest most of the time: the feet."""
    sk = motion.skeleton
    effectors = sk.end_effectors()
    typical = motion.global_positions()[:, effectors, sk.up_index].median(dim=0).values
    return [effectors[i] for i in typical.argsort()[:count].tolist()]


def low_and_slow(motion: sa.Motion, feet: list[int]) -> torch.Tensor:
    """Contacts: within 4 % of the height of the foot's lowest, slower than 35 % of it /s."""
    sk = motion.skeleton
    pos = motion.global_positions().double()
    height = sk.height()
    low = pos[:, feet, sk.up_index]
    speed = torch.zeros_like(low)
    speed[1:] = torch.linalg.vector_norm(pos[1:, feet] - pos[:-1, feet], dim=-1) * motion.fps
    return (low < low.min(dim=0).values + 0.04 * height) & (speed < 0.35 * height)


def swayed(motion: sa.Motion, amplitude: float = 0.08) -> sa.Motion:
    """The upper legs (parents of the knees) turned by a smooth sway: the feet skate."""
    sk = motion.skeleton
    rotations = motion.rotations.clone()
    t = torch.arange(motion.num_frames, dtype=rotations.dtype) / motion.fps
    feet = lowest_effectors(motion, 4 if sk.morphology == "quadruped" else 2)
    hips = {leg_chain(motion, foot)[0] for foot in feet}
    axis = torch.zeros(3, dtype=rotations.dtype)
    axis[0 if sk.up_index != 0 else 1] = 1.0
    for k, hip in enumerate(sorted(hips)):
        angle = amplitude * torch.sin(2 * math.pi * 1.3 * t + k)
        turn = torch.cat([torch.cos(angle / 2)[:, None], torch.sin(angle / 2)[:, None] * axis], -1)
        rotations[:, hip] = quat.mul(rotations[:, hip], turn)
    return motion._replace(rotations=rotations)


def peak_acceleration(positions: torch.Tensor, fps: float) -> float:
    second = positions[2:] - 2 * positions[1:-1] + positions[:-2]
    return float(torch.linalg.vector_norm(second, dim=-1).amax()) * fps**2


def check_cleanup(clean: sa.Motion, feet: list[int], scale: float = 1.0) -> dict[str, float]:
    """Lock the feet of a swayed ``clean``; ``scale`` turns its units into metres."""
    contacts = low_and_slow(clean, feet)
    assert contacts.float().mean() > 0.15
    skating = swayed(clean)
    locked = foot_lock(skating, contacts, feet)
    sk = clean.skeleton
    before, after = skating.global_positions().double(), locked.global_positions().double()
    kw = {"fps": clean.fps, "up_axis": sk.up_axis, "feet": feet}
    skate_before = foot_skate(before, contacts, **kw).item()
    skate_after = foot_skate(after, contacts, **kw).item()
    figures = {
        "skate_reduction": 1 - skate_after / skate_before,
        "mpjpe_change_m": mpjpe(after, before).item() * scale,
        "peak_ratio": peak_acceleration(after, clean.fps) / peak_acceleration(before, clean.fps),
    }
    assert figures["skate_reduction"] >= 0.7, figures
    assert figures["mpjpe_change_m"] <= 0.01, figures  # <= 1 cm
    assert figures["peak_ratio"] <= 1.05, figures  # no new acceleration spike
    # the root and every joint off the legs are untouched
    legs = {j for foot in feet for j in leg_chain(clean, foot)}
    moved = set(legs)
    for j in range(sk.num_joints):  # parents come before children
        if sk.parents[j] in moved:
            moved.add(j)
    others = [j for j in range(sk.num_joints) if j not in moved]
    assert torch.allclose(locked.rotations[:, others], skating.rotations[:, others], atol=1e-6)
    assert torch.equal(locked.root_positions, skating.root_positions)
    return figures


@pytest.mark.data
def test_lafan_clip(lafan_clip: Path):
    clean = sa.read_bvh(lafan_clip).to_metres()
    check_cleanup(clean, lowest_effectors(clean, 2))


@pytest.mark.data
def test_dog_clip(shared_data: Path):
    path = sorted((shared_data / "dog" / "mann").glob("*.bvh"))[0]
    clean = sa.read_bvh(path).to_metres()
    feet = lowest_effectors(clean, 4)
    assert len({leg_chain(clean, f)[0] for f in feet}) == 4  # four legs, four hips
    check_cleanup(clean, feet)


@pytest.mark.data
def test_cmu_clip_in_its_own_units(shared_data: Path):
    path = sorted((shared_data / "human" / "cmu").glob("*.bvh"))[0]
    clean = sa.read_bvh(path)
    assert clean.units != "m"
    metres = clean.to_metres().root_positions.norm() / clean.root_positions.norm()
    check_cleanup(clean, lowest_effectors(clean, 2), scale=float(metres))


def test_without_contacts_nothing_changes():
    motion, _ = procedural.generate("biped22", "walk", seconds=1.0, seed=0)
    feet = lowest_effectors(motion, 2)
    none = torch.zeros(motion.num_frames, 2, dtype=torch.bool)
    assert torch.allclose(foot_lock(motion, none, feet).rotations, motion.rotations, atol=1e-6)


def test_contact_runs():
    mask = torch.tensor([True, True, False, False, True, False, True])
    assert contact_runs(mask) == [(0, 1), (4, 4), (6, 6)]
    assert contact_runs(torch.zeros(3, dtype=torch.bool)) == []


def test_errors():
    motion, _ = procedural.generate("biped22", "walk", seconds=1.0, seed=0)
    frames = motion.num_frames
    ok = torch.zeros(frames, 1, dtype=torch.bool)
    with pytest.raises(MotionError, match=r"contacts must be a boolean tensor"):
        foot_lock(motion, ok.float(), [3])
    with pytest.raises(MotionError, match=rf"contacts must have shape \[{frames}, 2\]"):
        foot_lock(motion, ok, [3, 4])
    with pytest.raises(MotionError, match=r"halflife must be a finite number > 0, got 0"):
        foot_lock(motion, ok, [3], halflife=0)
    with pytest.raises(MotionError, match=r"foot 99 is not a joint index"):
        foot_lock(motion, ok, [99])
    head = motion.skeleton.index("Head")
    with pytest.raises(MotionError, match=r"joint 'Head' .* no hip and knee above it in a leg"):
        leg_chain(motion, head)


@pytest.mark.data
def test_contacts_detected_when_not_given(lafan_clip: Path):
    skating = swayed(sa.read_bvh(lafan_clip).to_metres())
    contacts, feet = foot_contacts(skating)
    assert [skating.skeleton.joint_names[j] for j in feet] == ["LeftToe", "RightToe"]
    locked = foot_lock(skating)  # the same detection inside
    kw = {"fps": skating.fps, "up_axis": skating.skeleton.up_axis, "feet": feet}
    before = foot_skate(skating.global_positions(), contacts, **kw)
    after = foot_skate(locked.global_positions(), contacts, **kw)
    assert after < 0.3 * before
