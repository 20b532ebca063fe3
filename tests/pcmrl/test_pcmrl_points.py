"""Point sampling of PC-MRL (paper Eq. 1 and 3): consistency, proportions, groups, zero-length."""

from __future__ import annotations

import warnings

import pytest
import torch
from skelagnostic_pcmrl.points import (
    ZeroLengthBoneWarning,
    effective_joints,
    global_to_local,
    infer_units,
    positions_from_global,
    sample_layout,
    warn_zero_length_bones,
)

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import SkeletonError
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
        single = type(layout)(layout.heads[b], layout.tails[b], layout.alpha[b], layout.noise[b],
                              layout.groups[b], layout.sigma)
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
    assert all(c in eff for c in range(sk.num_joints) if sk.children(c) and any(
        sk.offsets[k].norm() > 0 for k in sk.children(c)))
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
