"""Foot contacts for any rig (skelagnostic.analysis.foot_contacts, issue #50 item 3).

The detector is compared frame by frame with contacts labelled by a simpler rule
written here with numpy (a foot near its clip's lowest level and nearly still, with a
forward difference for the speed), on real clips of a human (CMU, LaFAN1) and a dog
(MANN), and on the procedural generator, whose quadruped walk has known contact
timing (each foot once per stride, the legs a known share of the stride apart).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.analysis import contact_joints, foot_contacts
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError

#: Clips of steady motion: walks, runs and a dog's gaits (not lying or sitting).
REAL_CLIPS = [
    "human/cmu/131_01.bvh",
    "human/cmu/131_03.bvh",
    "human/lafan1/Lafan1_example.bvh",
    "human/lafan1/walk4_subject1.bvh",
    "human/lafan1/obstacles1_subject5.bvh",
    "dog/mann/D1_007_KAN01_001.bvh",
    "dog/mann/D1_008_KAN01_001.bvh",
    "dog/mann/D1_009_KAN01_001.bvh",
    "dog/mann/D1_053_KAN01_001.bvh",
]


def labelled(motion: sa.Motion, feet: list[int], height: float = 0.05, speed: float = 0.6):
    """The test's own rule: near the clip's lowest level (1st percentile) and slow."""
    pos = motion.global_positions()[:, feet].double().numpy()
    scale = motion.skeleton.height()
    level = pos[..., motion.skeleton.up_index]
    low = level - np.percentile(level, 1, axis=0) <= height * scale
    step = np.linalg.norm(np.diff(pos, axis=0, append=pos[-1:]), axis=-1) * motion.fps
    return low & (step <= speed * scale)


@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_contacts_agree_with_a_simple_rule_on_real_clips(shared_data: Path, clip: str) -> None:
    motion = sa.read_bvh(shared_data / clip)
    contacts, feet = foot_contacts(motion)
    assert contacts.dtype == torch.bool and tuple(contacts.shape) == (motion.num_frames, len(feet))
    agreement = (contacts.numpy() == labelled(motion, feet)).mean()
    assert agreement >= 0.9, f"{clip}: {agreement:.3f} of frames agree"
    assert bool(contacts.any()), f"{clip}: no contact at all"


@pytest.mark.parametrize(
    ("clip", "names"),
    [
        ("human/cmu/131_01.bvh", ["LeftToe", "RightToe"]),
        ("human/lafan1/Lafan1_example.bvh", ["LeftToe", "RightToe"]),
        ("dog/mann/D1_007_KAN01_001.bvh", ["LeftFoot", "RightFoot", "LeftHand", "RightHand"]),
    ],
)
def test_feet_come_from_the_body_groups(shared_data: Path, clip: str, names: list[str]) -> None:
    skeleton = sa.read_bvh(shared_data / clip).skeleton
    assert [skeleton.joint_names[j] for j in contact_joints(skeleton)] == names


def test_contacts_do_not_depend_on_the_length_unit(shared_data: Path) -> None:
    motion = sa.read_bvh(shared_data / "human/lafan1/Lafan1_example.bvh")
    scaled = sa.Motion(
        motion.skeleton.scaled(0.01), motion.rotations, motion.root_positions * 0.01, motion.fps
    )
    assert torch.equal(foot_contacts(motion).contacts, foot_contacts(scaled).contacts)


@pytest.mark.parametrize(
    ("kind", "gait"),
    [
        ("biped22", "walk"),
        ("biped31", "walk"),
        ("biped17", "walk"),
        ("quadruped", "walk"),
        ("quadruped", "trot"),
        ("quadruped", "gallop"),
    ],
)
@pytest.mark.parametrize("seed", [0, 1])
def test_contacts_agree_with_a_simple_rule_on_procedural_gaits(
    kind: str, gait: str, seed: int
) -> None:
    motion, _ = procedural.generate(kind, gait, seconds=6.0, fps=30, seed=seed)
    contacts, feet = foot_contacts(motion)
    agreement = (contacts.numpy() == labelled(motion, feet, 0.04, 0.5)).mean()
    assert agreement >= 0.9, f"{kind} {gait} seed {seed}: {agreement:.3f}"


def test_idle_feet_stay_in_contact() -> None:
    motion, _ = procedural.generate("quadruped", "idle", seconds=4.0, fps=30, seed=0)
    assert bool(foot_contacts(motion).contacts.all())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quadruped_walk_contacts_keep_the_generator_timing(seed: int) -> None:
    """Each paw touches down once per stride, the legs a quarter stride apart (LH RF ... )."""
    motion, info = procedural.generate("quadruped", "walk", seconds=6.0, fps=30, seed=seed)
    contacts, feet = foot_contacts(motion)
    phase = info["phase"].double().numpy()
    stride = motion.fps / info["frequency"]
    onset_phase = []
    for n in range(len(feet)):
        onsets = np.flatnonzero(np.diff(contacts[:, n].numpy().astype(int)) == 1) + 1
        assert len(onsets) >= 4
        assert np.median(np.diff(onsets)) == pytest.approx(stride, rel=0.1)
        angles = np.exp(2j * np.pi * phase[onsets])
        onset_phase.append(np.angle(angles.mean()) / (2 * np.pi))
    # feet: left hind, right hind, left front, right front; the generator's leg phase
    # offsets are 0.0, 0.5, 0.25, 0.75: a touch-down comes that much earlier in the cycle
    offsets = np.array([0.0, 0.5, 0.25, 0.75])
    gaps = (np.array(onset_phase) + offsets - onset_phase[0]) % 1.0
    assert np.all(np.minimum(gaps, 1 - gaps) < 0.1), gaps


def test_a_skeleton_without_feet_is_named_in_the_error() -> None:
    skeleton = Skeleton(
        ["Root", "Spine", "Head"],
        [-1, 0, 1],
        torch.tensor([[0.0, 0, 0], [0, 10, 0], [0, 10, 0]]),
        name="snake",
    )
    with pytest.raises(SkelagnosticError, match=r"snake.*left_leg, right_leg.*left_arm"):
        contact_joints(skeleton)


def test_thresholds_must_be_positive() -> None:
    motion, _ = procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=0)
    with pytest.raises(SkelagnosticError, match="positive"):
        foot_contacts(motion, height=0.0)
