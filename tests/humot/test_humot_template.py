import pytest
import torch
from skelagnostic_humot.data import Topology
from skelagnostic_humot.template import (
    from_model_frame,
    major_joints,
    median_bone_lengths,
    motion_positions,
    skeleton_template,
    to_model_frame,
)

import skelagnostic as sa
from skelagnostic.errors import SkeletonError

EXPECTED = {
    "biped22": ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftArm", "LeftForeArm", "LeftHand"],
    "biped31": ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftArm", "LeftForeArm", "LeftHand"],
    "biped17": ["LHip", "LKnee", "LFoot", "LShoulder", "LElbow", "LWrist"],
}
KEYS = ["left_hip", "left_knee", "left_ankle", "left_shoulder", "left_elbow", "left_wrist"]


@pytest.mark.parametrize("kind", list(EXPECTED))
def test_major_joints_of_procedural_topologies(kind):
    sk = sa.procedural.generate(kind, "walk", seconds=0.1)[0].skeleton
    major = major_joints(sk)
    assert len(major) == 12
    assert [sk.joint_names[major[k]] for k in KEYS] == EXPECTED[kind]


@pytest.mark.data
def test_major_joints_of_real_skeletons(shared_data):
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    major = major_joints(cmu)
    # 3dsMax-style names: "LeftShoulder" is the upper arm, found by geometry
    assert [cmu.joint_names[major[k]] for k in KEYS] == [
        "LeftHip",
        "LeftKnee",
        "LeftAnkle",
        "LeftShoulder",
        "LeftElbow",
        "LeftWrist",
    ]
    lafan = sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh").skeleton
    assert lafan.joint_names[major_joints(lafan)["right_knee"]] == "RightLeg"


def test_template_axes():
    sk = sa.procedural.generate("biped22", "walk", seconds=0.1)[0].skeleton
    t = skeleton_template(sk)
    names = sk.joint_names
    assert torch.allclose(t[0], torch.zeros(3, dtype=t.dtype))  # pelvis at the origin
    assert t[names.index("Head"), 2] > 0 > t[names.index("LeftFoot"), 2]  # Z up
    assert t[names.index("LeftUpLeg"), 0] > 0 > t[names.index("RightUpLeg"), 0]  # X left
    toe = t[names.index("LeftToe")] - t[names.index("LeftFoot")]
    assert toe[1] < 0  # facing -Y: the coronal plane is XZ


def test_model_frame_round_trip_and_handedness():
    x = torch.randn(5, 3)
    for up in "xyz":
        assert torch.allclose(from_model_frame(to_model_frame(x, up), up), x, atol=1e-6)
    assert torch.allclose(to_model_frame(torch.tensor([0.0, 1.0, 0.0])), torch.tensor([0, 0, 1.0]))
    with pytest.raises(SkeletonError, match="up_axis"):
        to_model_frame(x, "w")


def test_template_uses_median_bone_lengths():
    motion = sa.procedural.generate("biped17", "walk", seconds=0.5)[0]
    pos = motion.global_positions()
    assert torch.allclose(
        median_bone_lengths(pos, motion.skeleton), motion.skeleton.bone_lengths(), atol=1e-6
    )
    stretched = pos * 2.0
    t2 = skeleton_template(motion.skeleton, stretched)
    assert torch.allclose(t2, 2 * skeleton_template(motion.skeleton), atol=1e-5)
    with pytest.raises(SkeletonError, match="positions"):
        median_bone_lengths(pos[:, :3], motion.skeleton)


@pytest.mark.parametrize("kind", list(EXPECTED))
def test_topology_templates_match_skeleton_template(kind):
    motion = sa.procedural.generate(kind, "run", seconds=0.3)[0]
    topo = Topology.of(motion.skeleton)
    pos = motion_positions(motion)
    lengths = median_bone_lengths(pos, motion.skeleton)
    assert torch.allclose(
        topo.templates(lengths.float()), skeleton_template(motion.skeleton, pos).float(), atol=1e-4
    )
