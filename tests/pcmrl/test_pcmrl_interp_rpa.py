"""Rest pose augmentation (PC-MRL Alg. 1) against hand computations."""

from __future__ import annotations

import math

import pytest
import torch
from skelagnostic_pcmrl.interp.rpa import (
    augment_rest_pose,
    bone_tails,
    max_real_quaternion,
    random_tail_offsets,
)

from skelagnostic import Motion, Skeleton, procedural
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import local_from_global
from skelagnostic.representations import FirstFrameOffsetQuaternions


def _hamilton(a: list[float], b: list[float]) -> list[float]:
    """Hamilton product written out by hand (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]


def _algorithm1(tail: list[float], target: list[float]) -> list[float]:
    """Algorithm 1 line by line (no normalisation, as printed in the paper)."""
    n_t = math.sqrt(sum(v * v for v in tail))
    n_p = math.sqrt(sum(v * v for v in target))
    eta = [v / n_t for v in tail]
    omega = [v / n_p for v in target]
    q_min = [0.0] + [(e + o) / 2 for e, o in zip(eta, omega, strict=True)]
    return _hamilton(q_min, [0.0, *eta])


def test_alg1_x_to_y_is_a_quarter_turn_about_z() -> None:
    # by hand: q_min = (0, .5, .5, 0); q_min * (0, 1, 0, 0) = (-.5, 0, 0, -.5)
    assert _algorithm1([2.0, 0, 0], [0, 3.0, 0]) == pytest.approx([-0.5, 0.0, 0.0, -0.5])
    q = max_real_quaternion(torch.tensor([2.0, 0, 0]), torch.tensor([0, 3.0, 0]))
    s = math.sqrt(0.5)
    assert q.tolist() == pytest.approx([s, 0.0, 0.0, s], abs=1e-6)


def test_alg1_45_degrees_about_y() -> None:
    # z onto (x + z)/sqrt(2): a 45 degree turn about +y
    q = max_real_quaternion(torch.tensor([0.0, 0, 1]), torch.tensor([1.0, 0, 1]))
    c, s = math.cos(math.pi / 8), math.sin(math.pi / 8)
    assert q.tolist() == pytest.approx([c, 0.0, s, 0.0], abs=1e-6)
    # the paper's unnormalised output is the same rotation scaled by cos(theta/2), sign flipped
    raw = _algorithm1([0.0, 0, 1], [1.0, 0, 1])
    assert [-v / math.cos(math.pi / 8) for v in raw] == pytest.approx(q.tolist(), abs=1e-6)


def test_alg1_random_directions_have_maximum_real_part() -> None:
    gen = torch.Generator().manual_seed(0)
    eta = torch.randn(64, 3, generator=gen, dtype=torch.float64)
    omega = torch.randn(64, 3, generator=gen, dtype=torch.float64)
    q = max_real_quaternion(eta, omega)
    assert torch.allclose(q.norm(dim=-1), torch.ones(64, dtype=torch.float64))
    unit = eta / eta.norm(dim=-1, keepdim=True)
    target = omega / omega.norm(dim=-1, keepdim=True)
    assert torch.allclose(Q.rotate(q, unit), target, atol=1e-9)
    for i in range(8):
        expected = _algorithm1(eta[i].tolist(), omega[i].tolist())
        norm = math.sqrt(sum(v * v for v in expected))
        assert [-v / norm for v in expected] == pytest.approx(q[i].tolist(), abs=1e-9)
    # every other rotation taking eta to omega (q followed by a twist about eta) has a
    # smaller real part
    for phi in (0.3, 1.0, 2.5, -0.7):
        twist = torch.cat(
            [torch.full((64, 1), math.cos(phi / 2), dtype=torch.float64), math.sin(phi / 2) * unit],
            -1,
        )
        other = Q.mul(q, twist)
        assert torch.allclose(Q.rotate(other, unit), target, atol=1e-9)
        assert torch.all(other[:, 0].abs() < q[:, 0] - 1e-6)


def test_alg1_degenerate_cases() -> None:
    q = max_real_quaternion(torch.tensor([1.0, 0, 0]), torch.tensor([-2.0, 0, 0]))
    assert abs(float(q[0])) < 1e-6  # a half turn
    assert torch.allclose(
        Q.rotate(q, torch.tensor([1.0, 0, 0])), torch.tensor([-1.0, 0, 0]), atol=1e-6
    )
    ident = max_real_quaternion(torch.zeros(3), torch.tensor([0.0, 1, 0]))
    assert ident.tolist() == [1.0, 0.0, 0.0, 0.0]
    same = max_real_quaternion(torch.tensor([0.0, 3, 0]), torch.tensor([0.0, 1, 0]))
    assert same.tolist() == pytest.approx([1.0, 0.0, 0.0, 0.0])


def test_bone_tails_follow_the_main_child() -> None:
    sk = procedural.skeleton("biped31")
    info = bone_tails(sk)
    chest = sk.index("Spine1")
    # the chest's tail continues the spine (same body group), not a clavicle
    assert sk.joint_names[int(info.child[chest])] == "Neck"
    # the CMU hips only has zero-length children: no bone (the paper ignores those)
    hips = sk.index("Hips")
    assert int(info.child[hips]) == -1
    assert torch.equal(info.tails[hips], torch.zeros(3, dtype=sk.offsets.dtype))
    left_leg = sk.index("LeftLeg")
    assert torch.equal(info.tails[left_leg], sk.offsets[sk.index("LeftFoot")])
    # a leaf takes its End Site
    head = sk.index("Head")
    assert int(info.child[head]) == -1
    assert torch.allclose(
        info.tails[head], torch.tensor(sk.end_sites[head][0], dtype=sk.offsets.dtype)
    )


def test_rpa_keeps_bone_directions_and_foq() -> None:
    motion, _ = procedural.generate("biped31", "run", seconds=0.5, fps=30, seed=1)
    motion = motion.convert_units("m").double()
    sk = motion.skeleton
    delta = random_tail_offsets(
        sk.num_joints, 0.1, torch.Generator().manual_seed(4), dtype=torch.float64
    )
    grot = motion.global_rotations()
    offsets, grot_aug, tails = augment_rest_pose(sk, grot, delta)
    # offsets moved by delta, except the root and zero-length bones
    nonzero = sk.offsets.norm(dim=-1) > 1e-6
    nonzero[0] = False
    assert torch.allclose(offsets[nonzero], sk.offsets[nonzero] + delta[nonzero])
    assert torch.equal(offsets[~nonzero], sk.offsets[~nonzero])
    # the augmented motion, through plain FK on the augmented skeleton
    aug_sk = Skeleton(sk.joint_names, sk.parents, offsets, end_sites=sk.end_sites)
    aug = Motion(aug_sk, local_from_global(grot_aug, sk.parents), motion.root_positions, motion.fps)
    assert torch.allclose(aug.global_rotations(), grot_aug, atol=1e-9)
    pos, pos_aug = motion.global_positions(), aug.global_positions()
    child = bone_tails(sk).child
    for j in range(sk.num_joints):
        c = int(child[j])
        if c < 0:
            continue
        old = pos[:, c] - pos[:, j]
        new = pos_aug[:, c] - pos_aug[:, j]
        # every main bone keeps its direction in every frame, with the new length
        old_u = old / old.norm(dim=-1, keepdim=True)
        assert torch.allclose(new, old_u * offsets[c].norm(), atol=1e-9), sk.joint_names[j]
    # the correction is constant, so FOQ is unchanged
    rep = FirstFrameOffsetQuaternions()
    assert torch.allclose(rep.encode(aug)[..., :4], rep.encode(motion)[..., :4], atol=1e-9)
    # tails: the main child's new offset
    has = child >= 0
    assert torch.allclose(tails[has], offsets[child[has]])


def test_rpa_rejects_bad_shapes() -> None:
    from skelagnostic.errors import SkeletonError

    sk = procedural.skeleton("biped31")
    with pytest.raises(SkeletonError, match="delta"):
        augment_rest_pose(sk, torch.zeros(2, sk.num_joints, 4), torch.zeros(3, 3))
