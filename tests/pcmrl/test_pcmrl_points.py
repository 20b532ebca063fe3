"""Point sampling of PC-MRL (paper Eq. 1 and 3): consistency, proportions, groups, zero-length."""

from __future__ import annotations

import math
import warnings

import pytest
import torch
from skelagnostic_pcmrl.points import (
    ZeroLengthBoneWarning,
    effective_joints,
    global_to_local,
    heading_frames,
    infer_units,
    lateral_direction,
    positions_from_global,
    sample_layout,
    warn_zero_length_bones,
)

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import SkelagnosticError, SkeletonError
from skelagnostic.representations import POINT_GROUPS, PointCloud


@pytest.fixture
def walk() -> sa.Motion:
    return procedural.generate("biped22", "walk", seconds=1.0, fps=30)[0].convert_units("m")


def _segment_distance(p: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    ab = b - a
    t = ((p - a) * ab).sum(-1, keepdim=True) / ab.square().sum(-1, keepdim=True).clamp_min(1e-12)
    return (p - (a + t.clamp(0, 1) * ab)).norm(dim=-1)


def test_points_keep_their_place_on_the_bone_in_every_frame(walk: sa.Motion) -> None:
    layout = sample_layout(walk.skeleton, 300, 0.05, generator=torch.Generator().manual_seed(1))
    grot, gpos = walk.global_rotations().float(), walk.global_positions().float()
    pts = layout.points(grot, gpos, walk.skeleton.offsets.float())  # [T, P, 3]
    assert pts.shape == (walk.num_frames, 300, 3)
    # each point, expressed in its head joint's frame, is the same in every frame (Eq. 3)
    local = Q.rotate(Q.inv(grot[:, layout.heads]), pts - gpos[:, layout.heads])
    assert torch.allclose(local, local[:1].expand_as(local), atol=1e-5)
    # with sigma = 0 every point lies on its bone segment, at the same alpha in every frame
    flat = sample_layout(walk.skeleton, 300, 0.0, generator=torch.Generator().manual_seed(1))
    pts0 = flat.points(grot, gpos, walk.skeleton.offsets.float())
    dist = _segment_distance(pts0, gpos[:, flat.heads], gpos[:, flat.tails])
    assert float(dist.max()) < 1e-5
    seg = gpos[:, flat.tails] - gpos[:, flat.heads]
    alpha = ((pts0 - gpos[:, flat.heads]) * seg).sum(-1) / seg.square().sum(-1)
    assert torch.allclose(alpha, flat.alpha[:, 0].expand_as(alpha), atol=1e-4)


def test_layout_matches_the_core_point_cloud(walk: sa.Motion) -> None:
    """Without a batch, the layout equals the core PointCloud's sampling of the same seed."""
    sk = walk.skeleton
    ref = PointCloud(128, 0.05).sample(sk, torch.Generator().manual_seed(3))
    layout = sample_layout(sk, 128, 0.05, generator=torch.Generator().manual_seed(3))
    assert torch.equal(layout.heads, ref.joints)
    assert torch.equal(layout.groups, ref.groups)
    assert torch.allclose(layout.local(sk.offsets), ref.local.float(), atol=1e-6)


def test_bone_choice_is_proportional_to_length(walk: sa.Motion) -> None:
    sk = walk.skeleton
    n = 40000
    layout = sample_layout(sk, n, 0.05, generator=torch.Generator().manual_seed(0))
    lengths = sk.bone_lengths()
    tails = [c for _, c in sk.bones()]
    expected = torch.tensor([float(lengths[c]) for c in tails])
    expected = expected / expected.sum() * n
    counts = torch.bincount(layout.tails, minlength=sk.num_joints)[tails].double()
    chi2 = float(((counts - expected) ** 2 / expected).sum())
    # chi-square with len(tails) - 1 = 20 dof: the 99.9 % quantile is 45.3
    assert chi2 < 45.3, chi2
    assert int(counts.sum()) == n


def test_groups_are_one_hot_of_the_bone_group(walk: sa.Motion) -> None:
    sk = walk.skeleton
    layout = sample_layout(sk, 500, 0.05, batch=(3,), generator=torch.Generator().manual_seed(0))
    onehot = layout.onehot()
    assert onehot.shape == (3, 500, len(POINT_GROUPS))
    assert torch.equal(onehot.sum(-1), torch.ones(3, 500))
    names = [POINT_GROUPS[g] for g in layout.groups[0].tolist()]
    bone_groups = [sk.body_groups[c] for c in layout.tails[0].tolist()]
    assert names == [g if g in POINT_GROUPS else "spine" for g in bone_groups]
    assert set(names) == set(POINT_GROUPS)
    # clouds of a batch are independent draws
    assert not torch.equal(layout.tails[0], layout.tails[1])


def test_batched_layout_with_per_clip_offsets(walk: sa.Motion) -> None:
    sk = walk.skeleton
    layout = sample_layout(sk, 64, 0.02, batch=(2,), generator=torch.Generator().manual_seed(0))
    offsets = torch.stack([sk.offsets, 1.5 * sk.offsets]).float()
    grot = walk.global_rotations().float().expand(2, -1, -1, -1)
    gpos = walk.global_positions().float().expand(2, -1, -1, -1)
    pts = layout.points(grot, gpos, offsets)
    for b in range(2):
        single = type(layout)(
            layout.heads[b],
            layout.tails[b],
            layout.alpha[b],
            layout.noise[b],
            layout.groups[b],
            layout.sigma,
        )
        assert torch.allclose(pts[b], single.points(grot[b], gpos[b], offsets[b]), atol=1e-6)


def test_positions_from_global_rotations_match_forward_kinematics(walk: sa.Motion) -> None:
    sk = walk.skeleton
    grot = walk.global_rotations()
    pos = positions_from_global(grot, walk.root_positions, sk.offsets, sk.parents)
    assert torch.allclose(pos, walk.global_positions(), atol=1e-6)
    local = global_to_local(grot, sk.parents)
    back = sa.Motion(sk, local, walk.root_positions, walk.fps)
    assert torch.allclose(back.global_positions(), walk.global_positions(), atol=1e-6)


def test_zero_length_bones_warn_and_are_never_sampled() -> None:
    sk = procedural.skeleton("biped31")  # LHipJoint, RHipJoint, LowerBack have zero length
    with pytest.warns(ZeroLengthBoneWarning, match="LHipJoint, RHipJoint, LowerBack"):
        names = warn_zero_length_bones(sk, "target skeleton")
    assert names == ["LHipJoint", "RHipJoint", "LowerBack"]
    zero = {sk.index(n) for n in names}
    layout = sample_layout(sk, 5000, 0.05, generator=torch.Generator().manual_seed(0))
    assert not zero & set(layout.tails.tolist())
    # the joints those bones start from still carry other, non-zero bones
    eff = effective_joints(sk)
    assert sk.index("Hips") in eff
    assert all(
        c in eff
        for c in range(sk.num_joints)
        if sk.children(c) and any(sk.offsets[k].norm() > 0 for k in sk.children(c))
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert warn_zero_length_bones(procedural.skeleton("biped22")) == []


def test_all_zero_skeleton_is_an_error() -> None:
    sk = sa.Skeleton(["root", "a", "b"], [-1, 0, 1], torch.zeros(3, 3))
    with pytest.raises(SkeletonError, match="no bone of non-zero length"):
        warn_zero_length_bones(sk)
    with pytest.raises(SkeletonError, match="no bone of non-zero length"):
        sample_layout(sk, 10, 0.05)


def test_infer_units_of_real_skeletons(shared_data) -> None:
    lafan = sa.read_bvh(shared_data / "human" / "lafan1" / "Lafan1_example.bvh")
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh")
    assert infer_units(lafan.skeleton) == "cm"
    assert infer_units(cmu.skeleton, "cmu") == "cmu"
    assert infer_units(procedural.skeleton("biped22").scaled(0.01)) == "m"


def _walk_cloud(walk: sa.Motion, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    layout = sample_layout(walk.skeleton, 256, 0.05, (1,), torch.Generator().manual_seed(seed))
    pts = layout.points(
        walk.global_rotations().float()[None],
        walk.global_positions().float()[None],
        walk.skeleton.offsets,
    )
    return pts - pts.mean(dim=2, keepdim=True), layout.groups


def test_heading_follows_a_turn_of_the_cloud_exactly(walk) -> None:
    pts, groups = _walk_cloud(walk)
    angle = 2.5
    turn = torch.tensor([math.cos(angle / 2), 0.0, math.sin(angle / 2), 0.0])
    before = heading_frames(pts, groups, up=1)
    after = heading_frames(Q.rotate(turn, pts), groups, up=1)
    expected = Q.mul(turn, before)
    # same rotation up to the quaternion sign
    assert torch.allclose((after * expected).sum(-1).abs(), torch.ones(()), atol=1e-5)
    # headings are rotations about the up axis only
    assert torch.allclose(after[..., [1, 3]], torch.zeros(()), atol=1e-6)


def test_heading_is_the_left_minus_right_direction(walk) -> None:
    """The procedural walk heads along +z with its left side at +x."""
    pts, groups = _walk_cloud(walk)
    lateral = lateral_direction(pts, groups, up=1)
    assert (lateral[..., 0] > 0.2).all() and torch.allclose(lateral[..., 1], torch.zeros(()))
    canonical = torch.tensor([0.0, 0.0, 1.0])  # (up + 1) % 3 = z for y-up
    mapped = Q.rotate(heading_frames(pts, groups, up=1, width=1), canonical)
    cos = torch.nn.functional.cosine_similarity(mapped, lateral, dim=-1)
    assert torch.allclose(cos, torch.ones(()), atol=1e-5)
    # the moving average removes most of the gait's side-to-side swing
    per_frame = Q.yaw(heading_frames(pts, groups, width=1), forward=2)
    smooth = Q.yaw(heading_frames(pts, groups, width=15), forward=2)

    def spread(q: torch.Tensor) -> float:
        return float(2 * torch.atan2(q[..., 2], q[..., 0]).std())

    assert spread(smooth) < spread(per_frame)


def test_heading_without_left_and_right_points_is_the_identity(walk) -> None:
    pts, groups = _walk_cloud(walk)
    spine = torch.zeros_like(groups)  # every point on the spine: no side to tell
    assert torch.equal(heading_frames(pts, spine), Q.identity(1, walk.num_frames))
    with pytest.raises(SkelagnosticError, match="at least 1 frame"):
        heading_frames(pts, groups, width=0)
