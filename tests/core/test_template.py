"""`Skeleton.template()` against the poses real characters stand in (issue #26, item 8).

The template must put the head and the upper-arm joints within 10 % of the standing
height of where upright frames of real clips put them, relative to the pelvis, in the
heading-free frame (Y up, facing +Z, left +X).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.core import quaternion as Q
from skelagnostic.core.template import template_from_lengths

TOLERANCE = 0.10  # of the standing height


def _heading_frame(motion: sa.Motion, left: torch.Tensor, fwd: torch.Tensor) -> torch.Tensor:
    """``[T, J, 3]`` positions relative to the root in per-frame (left, up, forward) axes."""
    g = motion.global_positions().double()
    up = torch.zeros(3, dtype=g.dtype)
    up[motion.skeleton.up_index] = 1.0
    basis = torch.stack([left, up.expand_as(left), fwd], -1)
    return torch.einsum("tjc,tcd->tjd", g - g[:, :1], basis)


def _horizontal(v: torch.Tensor, up: torch.Tensor) -> torch.Tensor:
    v = v - (v @ up)[:, None] * up
    return v / v.norm(dim=-1, keepdim=True)


def upright_biped(motion: sa.Motion, head: str, hips: tuple[str, str]) -> torch.Tensor:
    """``[J, 3]`` median pose of the frames whose head stands highest above the pelvis.

    Heading from the hips (right to left hip is +X); frames kept: head-above-pelvis
    at least 97 % of its 99th percentile (robust to a few outliers).
    """
    sk = motion.skeleton
    g = motion.global_positions().double()
    up = torch.zeros(3, dtype=g.dtype)
    up[sk.up_index] = 1.0
    left = _horizontal(g[:, sk.index(hips[0])] - g[:, sk.index(hips[1])], up)
    fwd = torch.linalg.cross(left, up.expand_as(left))
    loc = _heading_frame(motion, left, fwd)
    rise = loc[:, sk.index(head), 1]
    keep = rise >= 0.97 * torch.quantile(rise, 0.99)
    assert keep.sum() >= 10, "too few upright frames"
    return loc[keep].median(0).values


def upright_quadruped(
    motion: sa.Motion,
    chest: str,
    head: str,
    shoulders: tuple[str, str],
    hips: tuple[str, str],
    front_feet: tuple[str, str],
) -> torch.Tensor:
    """``[J, 3]`` median pose of the frames where a quadruped stands square.

    Heading from the body axis (pelvis to ``chest``, projected on the ground). A
    frame's score adds the spine's tilt, the left/right asymmetry of shoulders and
    hips, the head's sideways turn (all relative to the pelvis-chest distance) and
    how far the front legs are from their longest reach; the best 5 % are kept.
    """
    sk = motion.skeleton
    g = motion.global_positions().double()
    up = torch.zeros(3, dtype=g.dtype)
    up[sk.up_index] = 1.0
    axis = g[:, sk.index(chest)] - g[:, 0]
    fwd = _horizontal(axis, up)
    left = torch.linalg.cross(up.expand_as(fwd), fwd)
    loc = _heading_frame(motion, left, fwd)
    size = axis.norm(dim=-1)

    def at(name: str) -> torch.Tensor:
        return loc[:, sk.index(name)]

    tilt = (axis @ up).abs() / size
    asym = (
        (at(shoulders[0])[:, 0] + at(shoulders[1])[:, 0]).abs()
        + (at(hips[0])[:, 0] + at(hips[1])[:, 0]).abs()
    ) / size
    turn = at(head)[:, 0].abs() / size
    reach = at(chest)[:, 1] - (at(front_feet[0])[:, 1] + at(front_feet[1])[:, 1]) / 2
    score = tilt + asym + turn + (1 - reach / reach.max())
    keep = score <= torch.quantile(score, 0.05)
    assert keep.sum() >= 5, "too few standing frames"
    return loc[keep].median(0).values


def worst_error(template: torch.Tensor, reference: torch.Tensor, joints: list[int]) -> float:
    """Largest distance between template and reference over ``joints``."""
    return float((template[joints] - reference[joints]).norm(dim=-1).max())


BIPEDS = [
    # clip, head, upper arms, hips (left first)
    (
        "human/lafan1/Lafan1_example.bvh",
        "Head",
        ("LeftArm", "RightArm"),
        ("LeftUpLeg", "RightUpLeg"),
    ),
    (
        "human/lafan1/obstacles1_subject5.bvh",
        "Head",
        ("LeftArm", "RightArm"),
        ("LeftUpLeg", "RightUpLeg"),
    ),
    (
        "human/xia_cmu/neutral_01_000.bvh",
        "Head",
        ("LeftArm", "RightArm"),
        ("LeftUpLeg", "RightUpLeg"),
    ),
    # 3dsMax-style CMU names: "LeftShoulder" is the upper arm here
    ("human/cmu/131_01.bvh", "Head", ("LeftShoulder", "RightShoulder"), ("LeftHip", "RightHip")),
]
DOGS = [
    "dog/mann/D1_007_KAN01_001.bvh",
    "dog/mann/D1_008_KAN01_001.bvh",
    "dog/mann/D1_009_KAN01_001.bvh",
]
DOG_JOINTS = {
    "chest": "Spine1",
    "head": "Head",
    "shoulders": ("LeftArm", "RightArm"),
    "hips": ("LeftUpLeg", "RightUpLeg"),
    "front_feet": ("LeftHand", "RightHand"),
}


@pytest.mark.data
@pytest.mark.parametrize(("rel", "head", "arms", "hips"), BIPEDS)
def test_human_template_stands_like_upright_frames(shared_data: Path, rel, head, arms, hips):
    motion = sa.read_bvh(shared_data / rel)
    sk = motion.skeleton
    reference = upright_biped(motion, head, hips)
    joints = [sk.index(n) for n in (head, *arms)]
    height = sk.height()
    assert worst_error(sk.template(), reference, joints) < TOLERANCE * height
    # the standing height itself: head above the lowest joint of upright frames
    assert sk.height() == pytest.approx(
        float(reference[:, 1].max() - reference[:, 1].min()), rel=TOLERANCE
    )


@pytest.mark.data
def test_the_check_fails_on_the_length_only_template(shared_data: Path):
    """The previous construction (limbs' first bones sideways) misses LaFAN1's upper arms."""
    motion = sa.read_bvh(shared_data / "human/lafan1/Lafan1_example.bvh")
    sk = motion.skeleton
    reference = upright_biped(motion, "Head", ("LeftUpLeg", "RightUpLeg"))
    arms = [sk.index("LeftArm"), sk.index("RightArm")]
    old = template_from_lengths(sk)
    assert worst_error(old, reference, arms) > 0.15 * sk.height()  # 27-29 cm, mostly low
    assert worst_error(sk.template(), reference, arms) < 0.06 * sk.height()


@pytest.mark.data
@pytest.mark.parametrize("rel", DOGS)
def test_dog_template_stands_like_standing_frames(shared_data: Path, rel):
    motion = sa.read_bvh(shared_data / rel)
    sk = motion.skeleton
    assert sk.morphology == "quadruped"
    reference = upright_quadruped(motion, **DOG_JOINTS)
    joints = [sk.index(n) for n in ("Head", "LeftArm", "RightArm")]
    t = sk.template()
    assert worst_error(t, reference, joints) < TOLERANCE * sk.height()
    # spine forward, all four feet below the hips and shoulders, tail behind
    assert t[sk.index("Head"), 2] > t[sk.index("Spine1"), 2] > 0
    for foot in ("LeftHand", "RightHand", "LeftFoot", "RightFoot"):
        assert t[sk.index(foot), 1] < -0.5 * sk.height()
    assert t[sk.index("Tail1"), 2] < 0


@pytest.mark.parametrize("kind", procedural.KINDS)
def test_procedural_template_stands_like_its_motion(kind):
    motion = procedural.generate(kind, "idle", seconds=4.0)[0]
    sk = motion.skeleton
    names = sk.joint_names
    if sk.morphology == "quadruped":
        reference = upright_quadruped(motion, **DOG_JOINTS)
        joints = ["Head", "LeftArm", "RightArm"]
    else:
        left = "LHip" if "LHip" in names else "LeftUpLeg"
        right = "RHip" if "RHip" in names else "RightUpLeg"
        reference = upright_biped(motion, "Head", (left, right))
        joints = [
            "Head",
            *(["LShoulder", "RShoulder"] if "LShoulder" in names else ["LeftArm", "RightArm"]),
        ]
    idx = [sk.index(n) for n in joints]
    assert worst_error(sk.template(), reference, idx) < TOLERANCE * sk.height()


@pytest.mark.parametrize("kind", ["biped22", "biped31", "biped17"])
def test_procedural_heights_are_their_known_dimensions(kind):
    """Procedural bipeds rest upright with hanging legs: the height is the rest pose's."""
    sk = procedural.skeleton(kind)
    rest = sk.rest_positions()
    known = float(rest[:, 1].max() - rest[:, 1].min())
    assert sk.height() == pytest.approx(known, rel=1e-9)
    assert sk.scaled(0.01).height() == pytest.approx(known * 0.01, rel=1e-9)


@pytest.mark.data
@pytest.mark.parametrize(
    ("rel", "low", "high"),
    [
        ("human/lafan1/Lafan1_example.bvh", 120.0, 180.0),  # cm, head joint of an adult
        ("human/xia_cmu/neutral_01_000.bvh", 120 / 5.644, 180 / 5.644),  # CMU units
        ("human/cmu/131_01.bvh", 120 / 5.644, 180 / 5.644),
        ("dog/mann/D1_007_KAN01_001.bvh", 30.0, 60.0),  # cm
    ],
)
def test_real_heights_are_plausible(shared_data: Path, rel, low, high):
    assert low < sa.read_bvh(shared_data / rel).skeleton.height() < high


# ---------------------------------------------------------------------------- an unseen rig
#: LaFAN1 joint -> Unreal-style name; twist joints are inserted on the upper arms and thighs.
UE_NAMES = {
    "Hips": "pelvis",
    "LeftUpLeg": "thigh_l",
    "LeftLeg": "calf_l",
    "LeftFoot": "foot_l",
    "LeftToe": "ball_l",
    "RightUpLeg": "thigh_r",
    "RightLeg": "calf_r",
    "RightFoot": "foot_r",
    "RightToe": "ball_r",
    "Spine": "spine_01",
    "Spine1": "spine_02",
    "Spine2": "spine_03",
    "Neck": "neck_01",
    "Head": "head",
    "LeftShoulder": "clavicle_l",
    "LeftArm": "upperarm_l",
    "LeftForeArm": "lowerarm_l",
    "LeftHand": "hand_l",
    "RightShoulder": "clavicle_r",
    "RightArm": "upperarm_r",
    "RightForeArm": "lowerarm_r",
    "RightHand": "hand_r",
}
TWISTS = {
    "LeftForeArm": "upperarm_twist_01_l",
    "RightForeArm": "upperarm_twist_01_r",
    "LeftLeg": "thigh_twist_01_l",
    "RightLeg": "thigh_twist_01_r",
}


def unseen_rig(sk: sa.Skeleton, rotation: torch.Tensor) -> tuple[sa.Skeleton, dict[str, str]]:
    """``sk`` renamed Unreal-style, with a twist joint halfway along each upper arm and
    thigh, and its rest pose turned by ``rotation``; also new name -> source name."""
    names, parents, offsets, source = [], [], [], {}
    new_index: dict[int, int] = {}
    for j, name in enumerate(sk.joint_names):
        p = sk.parents[j]
        parent = -1 if p < 0 else new_index[p]
        off = sk.offsets[j]
        if name in TWISTS:  # split the bone ending at j in two
            names.append(TWISTS[name])
            parents.append(parent)
            offsets.append(off / 2)
            parent, off = len(names) - 1, off / 2
        new_index[j] = len(names)
        names.append(UE_NAMES[name])
        parents.append(parent)
        offsets.append(off)
        source[UE_NAMES[name]] = name
    off = Q.rotate(rotation, torch.stack(offsets))
    return sa.Skeleton(names, parents, off), source


@pytest.mark.data
def test_unseen_rig_template_stands_like_the_clip_it_was_built_from(shared_data: Path):
    motion = sa.read_bvh(shared_data / "human/lafan1/Lafan1_example.bvh")
    reference = upright_biped(motion, "Head", ("LeftUpLeg", "RightUpLeg"))
    rotation = Q.euler_to_quat(torch.tensor([40.0, -75.0, 120.0], dtype=torch.float64), "XYZ")
    rig, source = unseen_rig(motion.skeleton, rotation)
    assert rig.body_groups[rig.index("upperarm_twist_01_l")] == "left_arm"
    t = rig.template()
    height = rig.height()
    assert height == pytest.approx(motion.skeleton.height(), rel=1e-6)
    for name in ("head", "upperarm_l", "upperarm_r"):
        ref = reference[motion.skeleton.index(source[name])]
        assert float((t[rig.index(name)] - ref).norm()) < TOLERANCE * height, name
    # the twist joints stay on the straight, hanging upper arm and thigh
    for twist, top, bottom in (
        ("upperarm_twist_01_l", "upperarm_l", "lowerarm_l"),
        ("thigh_twist_01_r", "thigh_r", "calf_r"),
    ):
        torch.testing.assert_close(
            t[rig.index(twist)], (t[rig.index(top)] + t[rig.index(bottom)]) / 2
        )
        assert t[rig.index(bottom), 1] < t[rig.index(top), 1]
    # feet point forward although the rest pose lays the toes along the shins
    assert (
        t[rig.index("ball_l"), 2]
        > t[rig.index("foot_l"), 2] + 0.5 * rig.bone_lengths()[rig.index("ball_l")]
    )


# ---------------------------------------------------------------------------- construction
def _chain(offsets: list[list[float]], names: list[str], parents: list[int]) -> sa.Skeleton:
    return sa.Skeleton(names, parents, offsets)


def test_template_keeps_clavicle_and_torso_and_hangs_the_limbs():
    """A T-pose with raised clavicles: clavicles kept, upper arms and thighs turned down."""
    names = (
        "Hips Spine Head LeftShoulder LeftArm LeftForeArm LeftHand RightShoulder "
        "RightArm RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot RightUpLeg RightLeg RightFoot"
    ).split()
    parents = [-1, 0, 1, 1, 3, 4, 5, 1, 7, 8, 9, 0, 11, 12, 0, 14, 15]
    offsets = [
        [0, 100, 0],
        [0, 40, 0],
        [0, 25, 0],
        [3, 8, 0],
        [12, 2, 0],
        [28, 0, 0],
        [22, 0, 0],
        [-3, 8, 0],
        [-12, 2, 0],
        [-28, 0, 0],
        [-22, 0, 0],
        [9, -4, 0],
        [20, -40, 0],
        [0, -40, 0],
        [-9, -4, 0],
        [-20, -40, 0],
        [0, -40, 0],
    ]
    sk = _chain(offsets, names, parents)
    t = sk.template()
    # clavicle as in the rest pose
    torch.testing.assert_close(
        t[sk.index("LeftArm")], torch.tensor([15.0, 50.0, 0.0], dtype=torch.float64)
    )
    # the arm hangs straight down from the shoulder, the leg from the hip
    for a, b in (("LeftArm", "LeftHand"), ("RightArm", "RightHand"), ("LeftUpLeg", "LeftLeg")):
        d = t[sk.index(b)] - t[sk.index(a)]
        torch.testing.assert_close(
            d / d.norm(), torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64)
        )
    # the bent knee stays bent by the same angle
    thigh = t[sk.index("LeftLeg")] - t[sk.index("LeftUpLeg")]
    shin = t[sk.index("LeftFoot")] - t[sk.index("LeftLeg")]
    rest_thigh, rest_shin = sk.offsets[sk.index("LeftLeg")], sk.offsets[sk.index("LeftFoot")]
    cos = float(thigh @ shin / thigh.norm() / shin.norm())
    assert cos == pytest.approx(
        float(rest_thigh @ rest_shin / rest_thigh.norm() / rest_shin.norm())
    )
    for p, c in sk.bones():
        assert float((t[c] - t[p]).norm()) == pytest.approx(float(sk.bone_lengths()[c]))


def test_template_falls_back_without_a_body_frame():
    """No left/right limbs: the length-only construction (spine up)."""
    sk = sa.Skeleton(["root", "a", "b"], [-1, 0, 1], [[0, 0, 0], [5, 0, 0], [0, 0, 3]])
    torch.testing.assert_close(sk.template(), template_from_lengths(sk))
    torch.testing.assert_close(sk.template()[2], torch.tensor([0.0, 8.0, 0.0], dtype=torch.float64))


def test_collinear_clavicle_points_sideways():
    """A clavicle lying along the spine in the rest (as LaFAN1's does) is laid sideways."""
    names = (
        "Hips Spine Head LeftShoulder LeftArm LeftForeArm RightShoulder RightArm "
        "RightForeArm LeftUpLeg LeftLeg RightUpLeg RightLeg"
    ).split()
    parents = [-1, 0, 1, 1, 3, 4, 1, 6, 7, 0, 9, 0, 11]
    # everything along +X (the rest's up), left along +Z
    offsets = [
        [0, 0, 0],
        [40, 0, 0],
        [25, 0, 0],
        [5, 0, 2],
        [10, 0, 0],
        [28, 0, 0],
        [5, 0, -2],
        [10, 0, 0],
        [28, 0, 0],
        [0, 0, 9],
        [40, 0, 0],
        [0, 0, -9],
        [40, 0, 0],
    ]
    sk = _chain(offsets, names, parents)
    t = sk.template()
    torch.testing.assert_close(
        t[sk.index("LeftArm")], torch.tensor([12.0, 45.0, 0.0], dtype=torch.float64)
    )
    torch.testing.assert_close(
        t[sk.index("RightForeArm")], torch.tensor([-12.0, 17.0, 0.0], dtype=torch.float64)
    )
    assert sk.height() == pytest.approx(65 + 40)


def test_limb_without_elbow_names_hangs_from_the_end_of_its_first_bone():
    """Arm joints with no elbow word: the limb turns at the end of its first non-zero bone."""
    names = "root chest head l_arm1 l_arm2 l_arm3 r_arm1 r_arm2 r_arm3".split()
    parents = [-1, 0, 1, 1, 3, 4, 1, 6, 7]
    offsets = [[0, 0, 0], [0, 50, 0], [0, 20, 0], [6, 0, 0], [25, 0, 0], [20, 0, 0]]
    offsets += [[-x, y, z] for x, y, z in offsets[3:]]
    sk = _chain(offsets, names, parents)
    assert sk.body_groups[3:6] == ["left_arm"] * 3
    torch.testing.assert_close(
        sk.template()[3:6],
        torch.tensor([[6.0, 50.0, 0.0], [6.0, 25.0, 0.0], [6.0, 5.0, 0.0]], dtype=torch.float64),
    )
