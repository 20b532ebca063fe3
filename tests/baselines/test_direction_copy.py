"""baselines.direction_copy: identity, rest-pose independence, a real cross-rig copy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.baselines import direction_copy, direction_match, name_copy
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import global_from_local, local_from_global
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton


def _walk(kind: str = "biped22", seconds: float = 1.0) -> Motion:
    return procedural.generate(kind, "walk", seconds=seconds, seed=4)[0].double()


def _reposed(motion: Motion, convention: dict[int, torch.Tensor]) -> Motion:
    """The same global motion on a rig whose rest pose turns joint ``j`` by ``convention[j]``.

    Rest offsets of ``j``'s children are rotated by ``C_j``, global rotations become
    ``G_j C_j^-1``: every global joint position stays where it was.
    """
    sk = motion.skeleton
    conv = Q.identity(sk.num_joints, dtype=torch.float64)
    for j, q in convention.items():
        conv[j] = q
    offsets = sk.offsets.clone()
    for c, p in enumerate(sk.parents):
        if p >= 0:
            offsets[c] = Q.rotate(conv[p], sk.offsets[c])
    reposed = Skeleton(sk.joint_names, sk.parents, offsets, name=sk.name)
    glob = Q.mul(global_from_local(motion.rotations, sk.parents), Q.inv(conv))
    return Motion(
        reposed,
        local_from_global(glob, sk.parents),
        motion.root_positions,
        motion.fps,
        units=motion.units,
    )


def _a_pose(motion: Motion) -> Motion:
    """``motion`` on its rig with the arms lowered 45 degrees at the shoulder (an A pose)."""
    sk = motion.skeleton
    convention = {}
    for side, sign in (("Left", -1.0), ("Right", 1.0)):
        down = torch.tensor(
            [math.cos(math.pi / 8), 0.0, 0.0, sign * math.sin(math.pi / 8)], dtype=torch.float64
        )
        for name in ("Arm", "ForeArm", "Hand"):  # the upper arm and everything below it
            convention[sk.index(f"{side}{name}")] = down
    return _reposed(motion, convention)


class TestSameSkeleton:
    def test_match_pairs_every_bone_with_itself(self) -> None:
        sk = procedural.skeleton("biped31")
        match = direction_match(sk, sk)
        bones = {c for c in range(1, sk.num_joints) if float(sk.bone_lengths()[c]) > 0}
        assert set(match) == bones
        for c, (start, end) in match.items():
            assert start == (sk.parents[c], c, 0.0) and end == (sk.parents[c], c, 1.0)

    @pytest.mark.parametrize("kind", ["biped22", "biped17", "biped31", "quadruped"])
    def test_copy_onto_itself_reproduces_the_global_positions(self, kind: str) -> None:
        m = procedural.generate(kind, "trot" if kind == "quadruped" else "run", seconds=1.0)[0]
        out = direction_copy(m.double(), m.skeleton, "cm", "cm")
        torch.testing.assert_close(
            out.global_positions(), m.double().global_positions(), atol=1e-6, rtol=0
        )


def test_unpaired_bones_keep_their_parents_rotation() -> None:
    """biped22's hands are leaves: biped31's hands (finger and thumb bones) follow the forearm."""
    target = procedural.skeleton("biped31")
    out = direction_copy(_walk(), target, "cm", "cm")
    glob = out.global_rotations()
    match = direction_match(_walk().skeleton, target)
    for side in ("Left", "Right"):
        hand, forearm = target.index(f"{side}Hand"), target.index(f"{side}ForeArm")
        kids = target.children(hand)
        assert len(kids) == 2 and not set(kids) & set(match)
        dots = (glob[:, hand] * glob[:, forearm]).sum(-1).abs()
        torch.testing.assert_close(dots, torch.ones_like(dots))


class TestRestPoseConvention:
    def test_a_pose_rig_holds_the_same_motion(self) -> None:
        m = _walk()
        a = _a_pose(m)
        rest = a.skeleton.rest_positions()
        sk = a.skeleton
        # the rest pose really is an A pose: hands below the shoulders, left and right
        for side in ("Left", "Right"):
            assert rest[sk.index(f"{side}Hand"), 1] < rest[sk.index(f"{side}Arm"), 1] - 20
        torch.testing.assert_close(a.global_positions(), m.global_positions())

    def test_source_convention_does_not_change_the_copy(self) -> None:
        m = _walk()
        target = procedural.skeleton("biped31")  # its arm joints have biped22's names
        from_t = direction_copy(m, target, "cm", "cm").global_positions()
        from_a = direction_copy(_a_pose(m), target, "cm", "cm").global_positions()
        torch.testing.assert_close(from_a, from_t, atol=1e-6, rtol=0)
        # the local-rotation copy does depend on it (what this baseline is for)
        naive_t = name_copy(m, target, "cm", "cm").global_positions()
        naive_a = name_copy(_a_pose(m), target, "cm", "cm").global_positions()
        assert float((naive_a - naive_t).norm(dim=-1).max()) > 10.0

    def test_target_convention_does_not_change_the_copy(self) -> None:
        m = _walk("biped31")
        target_t = _walk("biped22", 0.1)
        target_a = _a_pose(target_t).skeleton
        on_t = direction_copy(m, target_t.skeleton, "cm", "cm").global_positions()
        on_a = direction_copy(m, target_a, "cm", "cm").global_positions()
        torch.testing.assert_close(on_a, on_t, atol=1e-6, rtol=0)


def _chain_directions(
    positions: np.ndarray, lengths: np.ndarray, src: list[int], dst_lengths: np.ndarray
) -> np.ndarray:
    """Unit chord directions ``[T, n, 3]`` of the target bones along one source chain, numpy.

    ``src`` lists the source chain's joints from its primal parent down, ``lengths`` their
    rest bone lengths (entry ``k`` the bone ending at ``src[k]``), ``dst_lengths`` the target
    chain's rest bone lengths; both chains are parametrised by arc length in [0, 1].
    """
    s_arc = np.concatenate([[0.0], np.cumsum(lengths[src[1:]])]) / lengths[src[1:]].sum()
    t_arc = np.concatenate([[0.0], np.cumsum(dst_lengths)]) / dst_lengths.sum()
    pts = positions[:, src]  # [T, n + 1, 3]
    at = np.stack(
        [[np.interp(t_arc, s_arc, pts[f, :, x]) for x in range(3)] for f in range(len(pts))]
    ).transpose(0, 2, 1)  # [T, m + 1, 3]
    chords = at[:, 1:] - at[:, :-1]
    return chords / np.maximum(np.linalg.norm(chords, axis=-1, keepdims=True), 1e-12)


@pytest.mark.data
def test_lafan1_onto_cmu_bone_directions(lafan_clip, shared_data) -> None:
    """Each CMU limb bone of a single-child joint points along LaFAN1's chain chord (numpy)."""
    clip = sa.read_bvh(lafan_clip)[100:160]
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    out = direction_copy(clip, cmu, "cm", "cm")
    src_pos = clip.global_positions().double().numpy()
    out_pos = out.global_positions().double().numpy()
    src_len = np.linalg.norm(clip.skeleton.offsets.double().numpy(), axis=-1)
    dst_len = np.linalg.norm(cmu.offsets.double().numpy(), axis=-1)
    chains = {  # source chain from its primal parent down -> the target's, by hand
        ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe"): (
            "Hips", "LHipJoint", "LeftHip", "LeftKnee", "LeftAnkle", "LeftToe",
        ),
        ("Hips", "RightUpLeg", "RightLeg", "RightFoot", "RightToe"): (
            "Hips", "RHipJoint", "RightHip", "RightKnee", "RightAnkle", "RightToe",
        ),
        ("Spine2", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"): (
            "Chest2", "LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist",
        ),
    }  # fmt: skip
    checked = 0
    for src_names, dst_names in chains.items():
        src = [clip.skeleton.index(n) for n in src_names]
        dst = [cmu.index(n) for n in dst_names]
        expected = _chain_directions(src_pos, src_len, src, dst_len[dst[1:]])
        for k in range(1, len(dst)):
            parent, child = dst[k - 1], dst[k]
            # bones from a joint with several children are a best fit (Kabsch), not exact
            if parent == 0 or len(cmu.children(parent)) != 1 or dst_len[child] == 0:
                continue
            got = out_pos[:, child] - out_pos[:, parent]
            got /= np.linalg.norm(got, axis=-1, keepdims=True)
            np.testing.assert_allclose(got, expected[:, k - 1], atol=1e-6)
            checked += 1
    assert checked >= 9
    # LaFAN1's hand is a leaf: CMU's wrist has no paired bone below it and keeps the
    # elbow's global rotation (so its hand and thumb follow the forearm)
    glob = out.global_rotations().double()
    wrist, elbow = cmu.index("LeftWrist"), cmu.index("LeftElbow")
    assert "lhand" in [cmu.joint_names[c] for c in cmu.children(wrist)]
    dots = (glob[:, wrist] * glob[:, elbow]).sum(-1).abs()
    torch.testing.assert_close(dots, torch.ones_like(dots))
    # the bone lengths are the target's, the root starts where the source's starts
    lengths = np.linalg.norm(out_pos[:, 1:] - out_pos[:, cmu.parents[1:]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(dst_len[1:], lengths.shape), atol=1e-6)
    src_root = clip.root_positions[0].double().numpy()
    out_root = out.root_positions[0].double().numpy()
    np.testing.assert_allclose(out_root[[0, 2]], src_root[[0, 2]], atol=1e-6)
