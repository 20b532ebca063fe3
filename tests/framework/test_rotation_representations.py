"""6D and axis-angle local rotations: round trips, gradients, 6D layout, angles near 0 and pi."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import MotionError
from skelagnostic.plugins import get_plugin_manager
from skelagnostic.representations import (
    BUILTIN_REPRESENTATIONS,
    LocalAxisAngle,
    LocalQuaternions,
    LocalRotations6D,
)

REPS = [LocalRotations6D, LocalAxisAngle]


def same_rotations(a: torch.Tensor, b: torch.Tensor, atol: float) -> None:
    """``a`` and ``b`` are the same rotations (quaternions up to sign)."""
    torch.testing.assert_close(Q.to_matrix(a), Q.to_matrix(b), atol=atol, rtol=0)


def assert_round_trip(
    rep: LocalRotations6D | LocalAxisAngle, motion: sa.Motion, atol: float
) -> None:
    feats = rep.encode(motion)
    assert feats.shape == (motion.num_frames, motion.num_joints, len(rep.channels))
    back = rep.decode(feats, motion.skeleton, fps=motion.fps)
    same_rotations(back.rotations, motion.rotations, atol=atol)
    scale = float(motion.skeleton.height())
    err = (back.global_positions() - motion.global_positions()).norm(dim=-1).max()
    assert float(err) <= atol * scale
    torch.testing.assert_close(rep.encode(back), feats, atol=atol * max(scale, 1.0), rtol=0)


@pytest.mark.parametrize("cls", REPS)
@pytest.mark.parametrize(("character", "gait"), [("biped22", "walk"), ("quadruped", "trot")])
def test_round_trip_on_procedural_motion(cls: type, character: str, gait: str) -> None:
    motion, _ = sa.procedural.generate(character, gait, seconds=1.0, fps=30, seed=5)
    assert_round_trip(cls(), motion, atol=1e-5)


@pytest.mark.parametrize("cls", REPS)
@pytest.mark.parametrize(
    "clip", ["human/lafan1/Lafan1_example.bvh", "human/cmu/131_03.bvh", "dog/mann"]
)
def test_round_trip_on_real_clips(shared_data: Path, cls: type, clip: str) -> None:
    path = shared_data / clip
    if path.is_dir():
        path = sorted(path.rglob("*.bvh"))[0]
    motion = sa.read_bvh(path)[:60]
    assert_round_trip(cls(), motion, atol=1e-5)


def test_registered_as_data_representations() -> None:
    pm = get_plugin_manager()
    assert pm.representation("local_rot6d").cls is LocalRotations6D
    assert pm.representation("local_axis_angle").cls is LocalAxisAngle
    assert {LocalRotations6D, LocalAxisAngle} <= set(BUILTIN_REPRESENTATIONS)


@pytest.mark.parametrize(("name", "channels"), [("local_rot6d", 9), ("local_axis_angle", 6)])
def test_selectable_as_data_representation(example_plugin: Path, name: str, channels: int) -> None:
    from skelagnostic.cli import app

    overrides = ["model=example", "run_dir=/tmp/x", "data.seconds=1.0", "data.window=12"]
    cfg = app.compose([*overrides, "data.clips_per_gait=1", f"data.representation={name}"])
    dm = app.build_datamodule(cfg, get_plugin_manager())
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))[0]
    for dataset in batch.values():
        assert dataset["features"].shape[-1] == channels


def test_six_d_layout_is_the_first_two_matrix_columns() -> None:
    # a quarter turn about y then about x, computed by hand: R = Rx(90) Ry(90)
    # Ry(90) = [[0,0,1],[0,1,0],[-1,0,0]], Rx(90) = [[1,0,0],[0,0,-1],[0,1,0]]
    # R = [[0,0,1],[1,0,0],[0,1,0]]: column 0 = (0,1,0), column 1 = (0,0,1)
    h = math.sqrt(0.5)
    qx = torch.tensor([h, h, 0.0, 0.0], dtype=torch.float64)
    qy = torch.tensor([h, 0.0, h, 0.0], dtype=torch.float64)
    q = Q.mul(qx, qy)
    expected = torch.tensor([0.0, 1.0, 0.0, 0.0, 0.0, 1.0], dtype=torch.float64)
    torch.testing.assert_close(Q.to_rot6d(q), expected, atol=1e-12, rtol=0)
    # a turn of 30 degrees about z: column 0 = (c, s, 0), column 1 = (-s, c, 0)
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    qz = torch.tensor([math.cos(math.pi / 12), 0.0, 0.0, math.sin(math.pi / 12)])
    torch.testing.assert_close(Q.to_rot6d(qz), torch.tensor([c, s, 0.0, -s, c, 0.0]))
    # in the features: joint 1 carries it, then its rest offset as the translation
    sk = sa.Skeleton(["root", "arm"], [-1, 0], [[0, 0, 0], [0.0, 2.0, 0.0]])
    rot = torch.stack([Q.identity(2, dtype=torch.float64)] * 3)
    rot[:, 1] = q
    feats = LocalRotations6D().encode(sa.Motion(sk, rot, torch.zeros(3, 3), fps=30))
    torch.testing.assert_close(feats[:, 1, :6], expected.expand(3, 6), atol=1e-12, rtol=0)
    torch.testing.assert_close(feats[:, 1, 6:], torch.tensor([[0.0, 2.0, 0.0]] * 3).double())


def test_six_d_decode_orthonormalises_raw_columns() -> None:
    raw = torch.tensor([[2.0, 0.0, 0.0, 1.0, 3.0, 0.0]])  # not unit, not orthogonal
    m = Q.to_matrix(Q.from_rot6d(raw))
    torch.testing.assert_close(m[0], torch.eye(3), atol=1e-6, rtol=0)


def test_axis_angle_near_zero() -> None:
    axis = torch.nn.functional.normalize(torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64), dim=0)
    for angle in (0.0, 1e-12, 1e-8, 1e-4):
        q = torch.cat([torch.tensor([math.cos(angle / 2)]).double(), math.sin(angle / 2) * axis])
        v = Q.to_rotvec(q)
        torch.testing.assert_close(v, angle * axis, atol=1e-15, rtol=1e-9)
        same_rotations(Q.from_rotvec(v), q, atol=1e-12)  # roma's sinc switches to a series
    v = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    Q.from_rotvec(v).sum().backward()
    assert v.grad is not None and torch.isfinite(v.grad).all()
    q = Q.identity(dtype=torch.float64).requires_grad_(True)
    Q.to_rotvec(q).sum().backward()
    assert q.grad is not None and torch.isfinite(q.grad).all()


def test_axis_angle_near_pi() -> None:
    axis = torch.nn.functional.normalize(torch.tensor([1.0, 2.0, -2.0], dtype=torch.float64), dim=0)
    for angle in (math.pi - 1e-6, math.pi):
        q = torch.cat([torch.tensor([math.cos(angle / 2)]).double(), math.sin(angle / 2) * axis])
        for sign in (1.0, -1.0):  # q and -q are one rotation: one vector, angle <= pi
            v = Q.to_rotvec(sign * q)
            torch.testing.assert_close(v.norm(), torch.tensor(angle).double())
            torch.testing.assert_close(v, angle * axis, atol=1e-12, rtol=0)
            same_rotations(Q.from_rotvec(v), q, atol=1e-12)
    # just past pi the vector takes the opposite axis and the shorter way round
    over = math.pi + 1e-3
    q = torch.cat([torch.tensor([math.cos(over / 2)]).double(), math.sin(over / 2) * axis])
    torch.testing.assert_close(Q.to_rotvec(q), -(2 * math.pi - over) * axis)


@pytest.mark.parametrize("cls", REPS)
def test_gradients_flow_float64(cls: type) -> None:
    sk = sa.Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 0, 0], [0, 1.0, 0], [0.5, 0.5, 0]])
    gen = torch.Generator().manual_seed(0)
    rot = Q.normalize(torch.randn(2, 3, 4, generator=gen, dtype=torch.float64))
    root = torch.randn(2, 3, generator=gen, dtype=torch.float64)
    rep = cls()
    feats = rep.encode(sa.Motion(sk, rot, root, fps=30)).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda f: rep.decode(f, sk).global_positions(), (feats,))

    def encode(q: torch.Tensor) -> torch.Tensor:
        return rep.encode(sa.Motion(sk, q, root, fps=30))

    assert torch.autograd.gradcheck(encode, (rot.clone().requires_grad_(True),))


@pytest.mark.parametrize("cls", REPS)
def test_float32_and_float64_keep_their_dtype(cls: type) -> None:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30, seed=1)
    for dtype in (torch.float32, torch.float64):
        m = sa.Motion(
            motion.skeleton, motion.rotations.to(dtype), motion.root_positions.to(dtype), 30
        )
        feats = cls().encode(m)
        assert feats.dtype == dtype
        assert cls().decode(feats, m.skeleton).rotations.dtype == dtype


@pytest.mark.parametrize("cls", REPS)
def test_decode_checks_the_layout(cls: type) -> None:
    motion, _ = sa.procedural.generate("biped22", "walk", seconds=0.5, fps=30, seed=1)
    with pytest.raises(
        MotionError, match=f"shape \\[T, {motion.num_joints}, {len(cls.channels)}\\]"
    ):
        cls().decode(torch.zeros(4, motion.num_joints + 1, len(cls.channels)), motion.skeleton)


def test_local_quaternions_unchanged_by_the_shared_base() -> None:
    motion, _ = sa.procedural.generate("quadruped", "trot", seconds=0.5, fps=30, seed=2)
    feats = LocalQuaternions().encode(motion)
    torch.testing.assert_close(feats[..., :4], Q.continuity(motion.rotations, dim=-3))
    torch.testing.assert_close(feats[:, 0, 4:], motion.root_positions)
