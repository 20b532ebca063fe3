import math

import pytest
import torch

import skelagnostic as sa
from skelagnostic.core import quaternion as Q


@pytest.fixture
def walk():
    motion, info = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=3)
    return motion, info


def test_shapes_and_basic_properties(walk):
    m, _ = walk
    assert m.num_frames == 61 and m.num_joints == 22 and m.fps == 30
    assert m.rotations.shape == (61, 22, 4) and m.root_positions.shape == (61, 3)
    assert m.global_positions().shape == (61, 22, 3)
    assert m.global_rotations().shape == (61, 22, 4)
    assert m.duration == pytest.approx(2.0)
    torch.testing.assert_close(m.global_positions()[:, 0], m.root_positions)


@pytest.mark.parametrize(
    ("field", "shape", "message"),
    [
        ("rotations", (5, 3, 4), r"rotations must have shape \[T, 22, 4\]"),
        ("root_positions", (4, 3), r"root_positions must have shape \[5, 3\]"),
    ],
)
def test_shape_errors(walk, field, shape, message):
    m, _ = walk
    kwargs = {"rotations": m.rotations[:5], "root_positions": m.root_positions[:5]}
    kwargs[field] = torch.zeros(shape, dtype=torch.float64)
    with pytest.raises(sa.MotionError, match=message):
        sa.Motion(m.skeleton, fps=30, **kwargs)


def test_nan_and_zero_quaternions_are_named(walk):
    m, _ = walk
    rot = m.rotations.clone()
    rot[7, 4, 2] = float("nan")
    with pytest.raises(sa.MotionError, match="frame 7, joint 'LeftToe'"):
        sa.Motion(m.skeleton, rot, m.root_positions, 30)
    rot = m.rotations.clone()
    rot[2, 1] = 0.0
    with pytest.raises(sa.MotionError, match="zero quaternion at frame 2, joint 'LeftUpLeg'"):
        sa.Motion(m.skeleton, rot, m.root_positions, 30)
    root = m.root_positions.clone()
    root[3, 0] = float("inf")
    with pytest.raises(sa.MotionError, match="root_positions has a NaN/inf value at frame 3"):
        sa.Motion(m.skeleton, m.rotations, root, 30)
    with pytest.raises(sa.MotionError, match="fps"):
        sa.Motion(m.skeleton, m.rotations, m.root_positions, 0)


def test_numpy_inputs_and_dtype(walk):
    m, _ = walk
    n = sa.Motion(m.skeleton, m.rotations.numpy(), m.root_positions.numpy(), 30)
    torch.testing.assert_close(n.global_positions(), m.global_positions())
    f = m.float()
    assert f.dtype == torch.float32 and f.global_positions().dtype == torch.float32


def test_slicing(walk):
    m, _ = walk
    part = m[10:20]
    assert part.num_frames == 10
    torch.testing.assert_close(part.global_positions(), m.global_positions()[10:20])
    every_other = m[::2]
    assert every_other.fps == 15 and every_other.num_frames == 31
    assert m[-1].num_frames == 1
    with pytest.raises(IndexError):
        m[100]


def test_resample_slerps_and_keeps_time(walk):
    m, _ = walk
    up = m.resample(60)
    assert up.num_frames == 121 and up.fps == 60
    # every other frame of the upsampled motion is an original frame
    torch.testing.assert_close(up.rotations[::2], m.rotations, atol=1e-9, rtol=0)
    # midpoints are slerps: equal angle to both neighbours
    a, mid, b = m.rotations[0], up.rotations[1], m.rotations[1]
    d1 = (a * mid).sum(-1).abs()
    d2 = (b * mid).sum(-1).abs()
    torch.testing.assert_close(d1, d2)
    down = up.resample(30)
    torch.testing.assert_close(down.global_positions(), m.global_positions(), atol=1e-6, rtol=0)
    with pytest.raises(sa.MotionError):
        m.resample(-1)


def test_root_local_velocities_follow_the_character(walk):
    for turn in (0.0, 90.0):
        m, info = sa.procedural.generate(
            "biped22", "walk", seconds=4, fps=30, seed=1, turn_rate=turn
        )
        vel = m.root_local_velocities()
        # the root moves forward (+Z in the facing frame) at the generated speed on average
        assert vel[:, 0, 2].mean() == pytest.approx(info["speed"], rel=0.05)
        assert vel[:, 0, 0].mean().abs() < 0.05 * info["speed"]
        assert vel[:, 0, 1].mean().abs() < 0.05 * info["speed"]


def test_mirror(walk):
    m, _ = walk
    mir = m.mirror()
    mapping = m.skeleton.mirror_map()
    pos = m.global_positions()
    flipped = pos[:, mapping] * torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    torch.testing.assert_close(mir.global_positions(), flipped, atol=1e-9, rtol=0)
    torch.testing.assert_close(mir.mirror().rotations, m.rotations)
    lone = sa.Motion(
        sa.Skeleton(["Root", "Spine"], [-1, 0], [[0, 0, 0], [0, 1, 0]]),
        Q.identity(2, 2, dtype=torch.float64),
        torch.zeros(2, 3),
        30,
    )
    with pytest.raises(sa.MotionError, match="no left/right"):
        lone.mirror()


def test_units(walk):
    m, _ = walk
    assert m.units == "cm"
    metres = m.convert_units("m")
    assert metres.units == "m"
    torch.testing.assert_close(metres.global_positions(), m.global_positions() / 100)
    assert metres.skeleton.height() == pytest.approx(m.skeleton.height() / 100)
    cmu = m.convert_units("cmu")
    assert cmu.skeleton.height() == pytest.approx(m.skeleton.height() / (2.54 / 0.45))
    with pytest.raises(sa.MotionError, match="unknown units"):
        m.convert_units("furlong")
    raw = sa.Motion(m.skeleton, m.rotations, m.root_positions, 30)
    with pytest.raises(sa.MotionError, match="units are unknown"):
        raw.convert_units("m")


def _stick(height: float, units: str | None) -> sa.Motion:
    """A two-bone figure standing ``height`` tall (in its own units), one frame."""
    sk = sa.Skeleton(
        ["hips", "spine", "head"], [-1, 0, 1], [[0, 0, 0], [0, height / 2, 0], [0, height / 2, 0]]
    )
    rot = torch.tensor([[[1.0, 0, 0, 0]] * 3])
    return sa.Motion(sk, rot, torch.tensor([[0.0, height / 2, 0]]), 30, units=units)


@pytest.mark.parametrize(
    ("height", "units", "given", "metres"),
    [
        (170.0, "cm", None, 1.70),  # the motion's own unit
        (1800.0, None, None, 1.80),  # guessed: mm
        (1.65, None, None, 1.65),  # guessed: already metres
        (68.0, None, "inch", 68 * 0.0254),  # given, not guessed (a guess would say cm)
        (100.0, "cm", "cmu", 100 * 0.0254 / 0.45),  # given overrides the motion's unit
    ],
)
def test_to_metres(height, units, given, metres):
    out = _stick(height, units).to_metres(given)
    assert out.units == "m"
    assert out.skeleton.height() == pytest.approx(metres)
    assert float(out.global_positions()[0, 2, 1]) == pytest.approx(metres * 1.5)


def test_to_metres_errors():
    with pytest.raises(sa.SkelagnosticError, match="furlong"):
        _stick(1.0, None).to_metres("furlong")
    flat = sa.Motion(
        sa.Skeleton(["a"], [-1], [[0.0, 0, 0]]),
        torch.tensor([[[1.0, 0, 0, 0]]]),
        torch.zeros(1, 3),
        30,
    )
    with pytest.raises(sa.SkelagnosticError, match="height is 0"):
        flat.to_metres()


def test_facing_matches_heading_of_turning_walk():
    m, _ = sa.procedural.generate("quadruped", "trot", seconds=2, fps=30, seed=0, turn_rate=45)
    h = m.facing()
    fwd = Q.rotate(h, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(m.num_frames, 3))
    angle = torch.atan2(fwd[:, 0], fwd[:, 2])
    expected = torch.deg2rad(45.0 * torch.arange(m.num_frames, dtype=torch.float64) / 30)
    diff = torch.remainder(angle - expected + math.pi, 2 * math.pi) - math.pi
    assert diff.abs().max() < math.radians(8)
