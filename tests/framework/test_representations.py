"""Motion representations: layouts, decoding, FOQ, point clouds, normalisation."""

from __future__ import annotations

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import MotionError, NotInvertibleError, SkelagnosticError
from skelagnostic.representations import (
    FirstFrameOffsetQuaternions,
    GlobalPositions,
    LocalQuaternions,
    PointCloud,
    RootLocalVelocities,
    inverse_kinematics,
    rotation_between,
)


@pytest.fixture(scope="module")
def walk() -> sa.Motion:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=3)
    return motion.convert_units("m")


@pytest.fixture(scope="module")
def dog() -> sa.Motion:
    motion, _ = sa.procedural.generate("quadruped", "trot", seconds=1.0, fps=30, seed=4)
    return motion.convert_units("m")


@pytest.mark.parametrize(
    ("rep", "channels"),
    [
        (GlobalPositions(), 3),
        (GlobalPositions("root"), 3),
        (RootLocalVelocities(), 3),
        (LocalQuaternions(), 7),
        (FirstFrameOffsetQuaternions(), 7),
    ],
)
def test_joint_layouts(walk: sa.Motion, rep, channels: int) -> None:
    feats = rep.encode(walk)
    assert feats.shape == (walk.num_frames, walk.num_joints, channels)
    assert len(rep.channels) == channels


def test_local_quaternions_round_trip_exactly(walk: sa.Motion) -> None:
    rep = LocalQuaternions()
    back = rep.decode(rep.encode(walk), walk.skeleton, fps=walk.fps)
    torch.testing.assert_close(back.global_positions(), walk.global_positions())


def test_world_positions_decode_by_ik(walk: sa.Motion) -> None:
    rep = GlobalPositions()
    back = rep.decode(rep.encode(walk), walk.skeleton)
    err = (back.global_positions() - walk.global_positions()).norm(dim=-1)
    assert float(err.max()) < 1e-6


def test_root_frame_is_translation_and_heading_invariant(walk: sa.Motion) -> None:
    turn = Q.normalize(torch.tensor([0.8, 0.0, 0.6, 0.0], dtype=walk.dtype))
    rot = walk.rotations.clone()
    rot[:, 0] = Q.mul(turn, rot[:, 0])
    moved = sa.Motion(
        walk.skeleton,
        rot,
        Q.rotate(turn, walk.root_positions) + torch.tensor([3.0, 0.0, -2.0], dtype=walk.dtype),
        walk.fps,
    )
    rep = GlobalPositions("root")
    torch.testing.assert_close(rep.encode(moved), rep.encode(walk), atol=1e-6, rtol=0)


def test_ik_handles_opposite_and_zero_directions() -> None:
    u = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]])
    v = torch.tensor([[-1.0, 0, 0], [0, 2.0, 0], [1.0, 0, 0]])
    q = rotation_between(u, v)
    torch.testing.assert_close(Q.rotate(q[:2], u[:2]), torch.nn.functional.normalize(v[:2]))
    torch.testing.assert_close(q[2], torch.tensor([1.0, 0, 0, 0]))
    sk = sa.Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1, 0]])
    rot, _ = inverse_kinematics(torch.tensor([[0.0, 0, 0], [0, -1, 0]]), sk)
    torch.testing.assert_close(
        Q.rotate(rot[0], torch.tensor([0.0, 1, 0])), torch.tensor([0.0, -1, 0]), atol=1e-6, rtol=0
    )


@pytest.mark.parametrize("rep", [RootLocalVelocities(), PointCloud(num_points=16)])
def test_not_invertible(walk: sa.Motion, rep) -> None:
    with pytest.raises(NotInvertibleError, match=type(rep).__name__):
        rep.decode(rep.encode(walk), walk.skeleton)


def test_foq_first_frame_identity_and_reference_decode(walk: sa.Motion) -> None:
    rep = FirstFrameOffsetQuaternions()
    feats = rep.encode(walk)
    torch.testing.assert_close(feats[0, :, :4], Q.identity(walk.num_joints, dtype=walk.dtype))
    with pytest.raises(NotInvertibleError, match="reference"):
        rep.decode(feats, walk.skeleton)
    back = rep.decode(feats, walk.skeleton, fps=walk.fps, reference=walk)
    torch.testing.assert_close(back.global_positions(), walk.global_positions())
    with pytest.raises(MotionError, match="reference must give"):
        rep.decode(feats, walk.skeleton, reference=torch.zeros(3, 4))


def test_foq_is_roll_invariant(walk: sa.Motion) -> None:
    # a constant extra rotation r after every global rotation: q_t r (q_0 r)^-1 == q_t q_0^-1
    r = Q.normalize(torch.tensor([0.9, 0.3, -0.2, 0.1], dtype=walk.dtype))
    grot = walk.global_rotations()
    foq = Q.mul(grot, Q.inv(grot[:1]))
    rolled = Q.mul(Q.mul(grot, r), Q.inv(Q.mul(grot[:1], r)))
    torch.testing.assert_close(rolled, foq)
    encoded = FirstFrameOffsetQuaternions().encode(walk)[..., :4]
    torch.testing.assert_close(Q.continuity(foq), encoded)


def test_point_cloud_is_temporally_consistent(dog: sa.Motion) -> None:
    rep = PointCloud(num_points=64, sigma=0.0, seed=1)
    feats = rep.encode(dog)
    assert feats.shape == (dog.num_frames, 64, 8)
    samples = rep.sample(dog.skeleton)
    # with sigma 0 every point stays on its bone at a fixed distance from the head joint
    head = dog.global_positions()[:, samples.joints]
    dist = (feats[..., :3] - head).norm(dim=-1)
    torch.testing.assert_close(dist, dist[:1].expand_as(dist), atol=1e-6, rtol=0)
    onehot = feats[..., 3:]
    assert torch.equal(onehot.sum(-1), torch.ones(dog.num_frames, 64, dtype=feats.dtype))
    assert torch.equal(onehot[0], onehot[-1])
    assert set(samples.groups.tolist()) == {0, 1, 2, 3, 4}  # tail folded into spine
    torch.testing.assert_close(rep.encode(dog), feats)  # seeded: same points every call


def test_point_cloud_picks_bones_by_length() -> None:
    sk = sa.Skeleton(["r", "long", "short"], [-1, 0, 0], [[0, 0, 0], [0, 3.0, 0], [1.0, 0, 0]])
    samples = PointCloud(num_points=4000, sigma=0.0).sample(sk)
    share = float((samples.local[:, 1] > 0).double().mean())
    assert abs(share - 0.75) < 0.03


def test_point_cloud_rejects_bad_options() -> None:
    with pytest.raises(SkelagnosticError, match="num_points"):
        PointCloud(num_points=0)
    with pytest.raises(SkelagnosticError, match="sigma"):
        PointCloud(sigma=-1)


def test_normalisation_streaming_matches_full(walk: sa.Motion) -> None:
    feats = GlobalPositions().encode(walk).float()
    full, chunked = GlobalPositions(), GlobalPositions()
    full.fit_normalization(feats)
    chunked.fit_normalization([feats[:10], feats[10:]])
    torch.testing.assert_close(full.mean, chunked.mean)
    torch.testing.assert_close(full.std, chunked.std)
    torch.testing.assert_close(full.denormalize(full.normalize(feats)), feats)
    z = full.normalize(feats)
    torch.testing.assert_close(
        z.mean(0)[1:], torch.zeros(walk.num_joints - 1, 3), atol=1e-4, rtol=0
    )


def test_normalisation_guards_constants_and_one_hot(dog: sa.Motion) -> None:
    rep = PointCloud(num_points=8)
    feats = rep.encode(dog)
    rep.fit_normalization(feats, per_element=False)
    assert rep.mean.shape == (1, 8)
    assert torch.equal(rep.std[0, 3:], torch.ones(5))
    assert torch.equal(rep.mean[0, 3:], torch.zeros(5))
    const = LocalQuaternions()
    const.fit_normalization(torch.ones(5, 2, 7))
    assert torch.equal(const.std, torch.ones(2, 7))
    state = const.normalization_state()
    fresh = LocalQuaternions()
    with pytest.raises(SkelagnosticError, match="fit_normalization"):
        fresh.normalize(torch.ones(5, 2, 7))
    fresh.load_normalization_state(state)
    assert fresh.is_fitted
    with pytest.raises(MotionError, match=r"shape \[\.\.\., N, 7\]"):
        fresh.normalize(torch.ones(5, 2, 3))
