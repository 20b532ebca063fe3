import pickle

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core.names import infer_body_groups
from skelagnostic.core.skeleton import BODY_GROUPS

NAMES = ["Hips", "Spine", "Head", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg"]
PARENTS = [-1, 0, 1, 0, 3, 0, 5]
OFFSETS = [[0, 90, 0], [0, 20, 0], [0, 30, 0], [10, -5, 0], [0, -40, 0], [-10, -5, 0], [0, -40, 0]]


def make():
    return sa.Skeleton(NAMES, PARENTS, OFFSETS, name="tiny")


def test_basic_properties():
    s = make()
    assert s.num_joints == 7 and s.joint_names == NAMES and s.parents == PARENTS
    assert s.offsets.shape == (7, 3) and s.offsets.dtype == torch.float64
    assert s.bones() == [(0, 1), (1, 2), (0, 3), (3, 4), (0, 5), (5, 6)]
    assert s.children("Hips") == [1, 3, 5]
    assert s.body_groups == [
        "spine",
        "spine",
        "spine",
        "left_leg",
        "left_leg",
        "right_leg",
        "right_leg",
    ]
    assert s.mirror_map() == [0, 1, 2, 5, 6, 3, 4]
    assert s.depth("LeftLeg") == 2
    assert torch.allclose(s.bone_lengths()[4], torch.tensor(40.0, dtype=torch.float64))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"joint_names": ["A", "A"], "parents": [-1, 0], "offsets": [[0, 0, 0]] * 2}, "duplicate"),
        ({"joint_names": ["A", "B"], "parents": [-1, 1], "offsets": [[0, 0, 0]] * 2}, "before"),
        ({"joint_names": ["A", "B"], "parents": [-1, -1], "offsets": [[0, 0, 0]] * 2}, "root"),
        ({"joint_names": ["A", "B"], "parents": [-1], "offsets": [[0, 0, 0]] * 2}, "parents"),
        ({"joint_names": ["A", "B"], "parents": [-1, 0], "offsets": [[0, 0, 0]]}, "shape"),
        ({"joint_names": [], "parents": [], "offsets": torch.zeros(0, 3)}, "no joints"),
        (
            {
                "joint_names": ["A", "B"],
                "parents": [-1, 0],
                "offsets": [[0, 0, 0], [float("nan"), 0, 0]],
            },
            "'B' is not finite",
        ),
    ],
)
def test_invalid_skeletons(kwargs, message):
    with pytest.raises(sa.SkeletonError, match=message):
        sa.Skeleton(**kwargs)


def test_unknown_joint_suggests_close_names():
    with pytest.raises(sa.SkeletonError, match="did you mean 'LeftLeg'"):
        make().index("LeftLg")


def test_body_group_override_and_validation():
    s = sa.Skeleton(NAMES, PARENTS, OFFSETS, body_groups={"Head": "other"})
    assert s.body_groups[2] == "other"
    with pytest.raises(sa.SkeletonError, match="not one of"):
        sa.Skeleton(NAMES, PARENTS, OFFSETS, body_groups=["bogus"] * 7)


def test_body_groups_from_geometry_when_names_lack_side():
    names = ["root", "hip_a", "knee_a", "hip_b", "knee_b"]
    groups = infer_body_groups(
        names, [-1, 0, 1, 0, 3], [[0, 0, 0], [10, 0, 0], [0, -40, 0], [-10, 0, 0], [0, -40, 0]]
    )
    assert groups == ["spine", "left_leg", "left_leg", "right_leg", "right_leg"]
    assert set(groups) <= set(BODY_GROUPS)


def test_subset_reparents_and_composes_offsets():
    s = make()
    sub = s.subset(["Hips", "Head", "LeftLeg", "RightUpLeg"])
    assert sub.joint_names == ["Hips", "Head", "LeftLeg", "RightUpLeg"]
    assert sub.parents == [-1, 0, 0, 0]
    # rest positions of kept joints do not move
    full = s.rest_positions()
    torch.testing.assert_close(sub.rest_positions(), full[[0, 2, 4, 5]])
    with pytest.raises(sa.SkeletonError, match="root"):
        s.subset(["Head"])
    with pytest.raises(sa.SkeletonError, match="unknown joint"):
        s.subset(["Hips", "Tail"])


def test_template_is_canonical_and_keeps_bone_lengths():
    s = make()
    t = s.template()
    torch.testing.assert_close(t[0], torch.zeros(3, dtype=torch.float64))
    for p, c in s.bones():
        assert torch.isclose((t[c] - t[p]).norm(), s.offsets[c].norm())
    # spine up, legs down, left leg on +X; the hip bones keep their 5-unit drop
    assert t[2, 1] > 0 and t[4, 1] < 0 and t[3, 0] > 0 and t[5, 0] < 0
    assert s.height() == pytest.approx(50 + 5 + 40)


def test_template_ignores_rest_pose_orientation():
    """A rest pose rotated arbitrarily (like the MANN dog's) gives the same template."""
    s = make()
    rot = sa.core.quaternion.euler_to_quat(
        torch.tensor([30.0, 70.0, -20.0], dtype=torch.float64), "XYZ"
    )
    rotated = sa.Skeleton(
        NAMES, PARENTS, sa.core.quaternion.rotate(rot, s.offsets), body_groups=s.body_groups
    )
    torch.testing.assert_close(rotated.template(), s.template())


def test_equality_hash_scaling_and_serialisation():
    s = make()
    assert s == make() and hash(s) == hash(make())
    big = s.scaled(2.0)
    assert big != s and big.same_topology(s) and hash(big) == hash(s)
    assert big.height() == pytest.approx(2 * s.height())
    assert sa.Skeleton.from_dict(s.to_dict()) == s
    clone = pickle.loads(pickle.dumps(s))
    assert clone == s and clone.body_groups == s.body_groups
    with pytest.raises(sa.SkeletonError, match="parents"):
        sa.Skeleton.from_dict({"joint_names": ["A"], "offsets": [[0, 0, 0]]})


def test_unpickling_does_not_infer_the_groups_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """Groups given in full (``from_dict``, unpickling a batch's skeleton) are not re-inferred."""
    s = sa.Skeleton(NAMES, PARENTS, torch.randn(7, 3))
    data = pickle.dumps(s)

    def refuse(*args: object, **kwargs: object) -> list[str]:
        raise AssertionError("infer_body_groups called")

    monkeypatch.setattr("skelagnostic.core.skeleton.infer_body_groups", refuse)
    clone = pickle.loads(data)
    assert clone == s and clone.body_groups == s.body_groups
    with pytest.raises(AssertionError, match="infer_body_groups called"):
        sa.Skeleton(NAMES, PARENTS, torch.randn(7, 3), body_groups={"Head": "spine"})


@pytest.mark.data
@pytest.mark.parametrize(
    ("rel", "left_arm_joint", "left_leg_joint", "effectors"),
    [
        ("human/xia_cmu/neutral_01_000.bvh", "LThumb", "LHipJoint", 5),
        ("human/cmu/131_01.bvh", "lhand", "LeftHip", 5),
        ("human/lafan1/Lafan1_example.bvh", "LeftShoulder", "LeftToe", 5),
        ("dog/mann/D1_007_KAN01_001.bvh", "LeftHand", "LeftFoot", 6),
    ],
)
def test_real_skeleton_groups(shared_data, rel, left_arm_joint, left_leg_joint, effectors):
    s = sa.read_bvh(shared_data / rel).skeleton
    groups = dict(zip(s.joint_names, s.body_groups, strict=True))
    assert groups[left_arm_joint] == "left_arm"
    assert groups[left_leg_joint] == "left_leg"
    assert "other" not in s.body_groups
    assert len(s.end_effectors()) == effectors
    mapping = s.mirror_map()
    assert all(mapping[mapping[j]] == j for j in range(s.num_joints))
    assert s.morphology == ("quadruped" if "dog" in rel else "biped")


def test_joint_name_heuristics_are_public() -> None:
    """The name rules the baselines and the template use (skelagnostic.core.names)."""
    from skelagnostic.core.names import (
        counterpart_names,
        is_middle_joint,
        is_toe_joint,
        is_twist_joint,
        name_side,
        name_words,
    )

    assert name_words("LeftUpLeg") == ["left", "up", "leg"]
    assert name_words("LHipJoint") == ["l", "hip", "joint"]
    sides = [name_side(n) for n in ("LeftArm", "RightFoot", "arm_L", "r_hand", "lfemur", "Neck")]
    assert sides == [1, -1, 1, -1, 1, 0]
    assert "RightHand" in counterpart_names("LeftHand")
    assert "hand.R" in counterpart_names("hand.L")
    assert is_middle_joint("LeftForeArm", "arm") and is_middle_joint("RightLeg", "leg")
    assert not is_middle_joint("RightUpLeg", "leg")
    assert is_twist_joint("LeftForeArmRoll") and is_toe_joint("RightToeBase")
    assert not is_twist_joint("LeftForeArm") and not is_toe_joint("RightFoot")
