"""skelagnostic.baselines against values computed independently (numpy, closed forms)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from skelagnostic import procedural
from skelagnostic.baselines import (
    direction_copy,
    joint_key,
    key_brackets,
    lerp_slerp,
    mean_pose,
    mean_pose_on_trajectory,
    name_copy,
    name_match,
    primal_copy,
    primal_match,
    primal_skeleton,
)
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import MotionError


def _rz(angle: float) -> list[float]:
    return [math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]


class TestPose:
    def test_mean_pose_is_the_numpy_mean(self) -> None:
        x = torch.randn(2, 7, 5, 3, generator=torch.Generator().manual_seed(0))
        expected = np.repeat(x.numpy().mean(axis=1, keepdims=True), 7, axis=1)
        np.testing.assert_allclose(mean_pose(x).numpy(), expected, rtol=1e-6)

    def test_on_trajectory_keeps_the_root_and_the_mean_offsets(self) -> None:
        x = torch.randn(9, 4, 3, generator=torch.Generator().manual_seed(1)).double()
        out = mean_pose_on_trajectory(x).numpy()
        xn = x.numpy()
        np.testing.assert_allclose(out[:, 0], xn[:, 0])
        offsets = (xn - xn[:, :1]).mean(axis=0)
        np.testing.assert_allclose(out[3], xn[3, 0] + offsets)

    def test_bad_shape(self) -> None:
        with pytest.raises(ValueError, match=r"\[\.\.\., T, J, 3\]"):
            mean_pose(torch.zeros(4, 2))


class TestKeyframes:
    def _motion(self) -> Motion:
        sk = Skeleton(["root", "a"], [-1, 0], [[0, 0, 0], [1, 0, 0]])
        t = 11
        rot = torch.tensor(
            [[_rz(0.1 * f), _rz(0.2 * f * f / 10)] for f in range(t)], dtype=torch.float64
        )
        root = torch.tensor([[f * f * 0.1, 0.0, 2.0 * f] for f in range(t)], dtype=torch.float64)
        return Motion(sk, rot, root, 30.0)

    def test_brackets(self) -> None:
        keys = torch.tensor([[True, False, False, True, False]])
        prev, nxt, w = key_brackets(keys)
        assert prev.tolist() == [[0, 0, 0, 3, 3]]
        assert nxt.tolist() == [[0, 3, 3, 3, 3]]
        np.testing.assert_allclose(w.numpy(), [[0, 1 / 3, 2 / 3, 0, 0]])

    def test_frame_zero_must_be_a_key(self) -> None:
        with pytest.raises(ValueError, match="frame 0"):
            lerp_slerp(self._motion(), [3, 10])

    def test_keys_exact_and_in_between_closed_form(self) -> None:
        m = self._motion()
        out = lerp_slerp(m, [0, 4, 10])
        for k in (0, 4, 10):
            torch.testing.assert_close(out.root_positions[k], m.root_positions[k])
            torch.testing.assert_close(out.rotations[k].abs(), m.rotations[k].abs())
        # frame 7 is 3/6 of the way from key 4 to key 10
        r4, r10 = m.root_positions[4].numpy(), m.root_positions[10].numpy()
        np.testing.assert_allclose(out.root_positions[7].numpy(), (r4 + r10) / 2)
        a4, a10 = 0.2 * 16 / 10, 0.2 * 100 / 10  # angles about z of joint "a"
        expected = _rz(a4 + (a10 - a4) / 2)
        np.testing.assert_allclose(out.rotations[7, 1].numpy(), expected, atol=1e-12)
        np.testing.assert_allclose(out.rotations[2, 0].numpy(), _rz(0.2), atol=1e-12)

    def test_out_of_range(self) -> None:
        with pytest.raises(ValueError, match="outside"):
            lerp_slerp(self._motion(), [0, 11])


class TestNames:
    @pytest.mark.parametrize(
        ("name", "key"),
        [
            ("mixamorig:LeftUpLeg", (1, "upleg")),
            ("UpLeg_L", (1, "upleg")),
            ("arm.r", (-1, "arm")),
            ("lfemur", (1, "femur")),
            ("RightHand", (-1, "hand")),
            ("rhand", (-1, "hand")),
            ("LHipJoint", (1, "hipjoint")),
            ("lowerback", (0, "lowerback")),
            ("RingFinger1", (0, "ringfinger1")),
        ],
    )
    def test_key(self, name: str, key: tuple[int, str]) -> None:
        assert joint_key(name) == key

    def test_match_across_naming_conventions(self) -> None:
        src = Skeleton(
            ["Hips", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg", "Spine"],
            [-1, 0, 1, 0, 3, 0],
            torch.ones(6, 3),
        )
        dst = Skeleton(
            ["pelvis", "Spine", "UpLeg_R", "Leg_R", "UpLeg_L", "Leg_L", "tail"],
            [-1, 0, 0, 2, 0, 4, 0],
            torch.ones(7, 3),
        )
        assert name_match(src, dst) == [0, 5, 3, 4, 1, 2, None]

    def test_sides_never_cross(self) -> None:
        src = Skeleton(["Hips", "LeftHand"], [-1, 0], torch.ones(2, 3))
        dst = Skeleton(["Hips", "RightHand"], [-1, 0], torch.ones(2, 3))
        assert name_match(src, dst) == [0, None]

    def test_copy_onto_itself_is_exact(self) -> None:
        m, _ = procedural.dataset(
            kinds=("biped22",), gaits=("walk",), clips_per_gait=1, seconds=1.0
        )[0]
        out = name_copy(m, m.skeleton, "cm", "cm")
        torch.testing.assert_close(out.rotations, m.rotations)
        torch.testing.assert_close(out.root_positions, m.root_positions)


class TestPrimal:
    def _chain(self, split: bool) -> Skeleton:
        if split:  # the bone a -> b cut in two colinear halves at m
            return Skeleton(
                ["root", "a", "m", "b"],
                [-1, 0, 1, 2],
                [[0, 0, 0], [0, 1, 0], [0.5, 0, 0], [0.5, 0, 0]],
            )
        return Skeleton(["root", "a", "b"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [1, 0, 0]])

    def test_primal_joints_and_chains(self) -> None:
        assert primal_skeleton(self._chain(False)) == {0: [0], 2: [1, 2]}
        assert primal_skeleton(self._chain(True)) == {0: [0], 3: [1, 2, 3]}

    def test_human_rigs_match_their_limbs(self) -> None:
        a, b = procedural.skeleton("biped22"), procedural.skeleton("biped17")
        match = primal_match(a, b)
        assert match[0] == 0
        for t, s in match.items():
            assert a.body_groups[s] == b.body_groups[t]
        groups = {b.body_groups[t] for t in match}
        assert {"left_arm", "right_arm", "left_leg", "right_leg"} <= groups

    def test_split_bone_keeps_the_positions(self) -> None:
        src = self._chain(False)
        frames = 5
        rot = torch.tensor(
            [[_rz(0.1 * f), _rz(0.3 * f), [1.0, 0, 0, 0]] for f in range(frames)],
            dtype=torch.float64,
        )
        root = torch.zeros(frames, 3, dtype=torch.float64)
        m = Motion(src, rot, root, 30.0, units="m")
        out = primal_copy(m, self._chain(True), "m", "m")
        # closed form: a at (0, 1, 0) rotated by the root's rz(0.1 f); b one unit further
        # along x rotated by the global rotation of a, rz(0.4 f)
        for f in range(frames):
            a = np.array([-math.sin(0.1 * f), math.cos(0.1 * f), 0.0])
            b = a + np.array([math.cos(0.4 * f), math.sin(0.4 * f), 0.0])
            pos = out.global_positions()[f].numpy()
            np.testing.assert_allclose(pos[1], a, atol=1e-9)
            np.testing.assert_allclose(pos[3], b, atol=1e-9)


@pytest.mark.parametrize("copy", [name_copy, primal_copy, direction_copy])
def test_root_rule_keeps_the_start_and_scales_height_and_displacement(copy) -> None:
    """A clip that starts 5.8 m from the origin: the copy starts where it starts."""
    m, _ = procedural.dataset(kinds=("biped22",), gaits=("walk",), clips_per_gait=1, seconds=1.0)[0]
    m = Motion(
        m.skeleton,
        m.rotations,
        m.root_positions + torch.tensor([500.0, 0.0, -300.0], dtype=m.root_positions.dtype),
        m.fps,
    )
    src = m.root_positions.double().numpy()
    assert np.linalg.norm(src[0, [0, 2]]) > 500  # y is up: x, z are the ground
    expected = src.copy()
    expected[:, [0, 2]] = src[0, [0, 2]] + 2.0 * (src[:, [0, 2]] - src[0, [0, 2]])
    expected[:, 1] = 2.0 * src[:, 1]
    out = copy(m, m.skeleton.scaled(2.0), "cm", "cm").root_positions.double().numpy()
    np.testing.assert_allclose(out, expected, atol=1e-9)
    # the ratio is taken in metres and the result is in the target's units
    in_m = copy(m, m.skeleton.scaled(0.02), "cm", "m").root_positions.double().numpy()
    np.testing.assert_allclose(in_m, expected / 100.0, atol=1e-9)


@pytest.mark.parametrize("copy", [name_copy, primal_copy, direction_copy])
def test_source_root_keeps_the_source_root_path(copy) -> None:
    """``root="source"``: the source's root positions unchanged (only converted to units)."""
    m, _ = procedural.dataset(kinds=("biped22",), gaits=("walk",), clips_per_gait=1, seconds=1.0)[0]
    src = m.root_positions.double().numpy() + np.array([500.0, 0.0, -300.0])
    m = Motion(m.skeleton, m.rotations, torch.from_numpy(src).to(m.rotations.dtype), m.fps)
    src = m.root_positions.double().numpy()
    out = copy(m, m.skeleton.scaled(2.0), "cm", "cm", root="source")
    np.testing.assert_array_equal(out.root_positions.double().numpy(), src)
    in_m = copy(m, m.skeleton.scaled(0.02), "cm", "m", root="source").root_positions
    np.testing.assert_allclose(in_m.double().numpy(), src / 100.0, rtol=1e-6)
    # the default is unchanged: the scaled rule
    scaled = copy(m, m.skeleton.scaled(2.0), "cm", "cm").root_positions.double().numpy()
    assert not np.allclose(scaled, src)


def test_source_root_moves_only_the_root_of_the_copy() -> None:
    """The unscaled copy is the scaled copy translated, frame by frame, by the root difference."""
    m, _ = procedural.dataset(kinds=("biped22",), gaits=("run",), clips_per_gait=1, seconds=1.0)[0]
    target = m.skeleton.scaled(0.8)
    scaled = direction_copy(m, target, "cm", "cm")
    source = direction_copy(m, target, "cm", "cm", root="source")
    torch.testing.assert_close(source.rotations, scaled.rotations)
    shift = (m.root_positions - scaled.root_positions)[:, None]
    torch.testing.assert_close(
        source.global_positions(), scaled.global_positions() + shift, rtol=0, atol=1e-4
    )


def test_unknown_root_rule_is_an_error() -> None:
    m, _ = procedural.dataset(kinds=("biped22",), gaits=("walk",), clips_per_gait=1, seconds=0.2)[0]
    with pytest.raises(MotionError, match="root='origin'"):
        name_copy(m, m.skeleton, "cm", "cm", root="origin")


def test_baselines_stay_in_the_core_layer() -> None:
    """``skelagnostic.baselines`` imports no lightning, hydra or pluggy (core: numpy + torch)."""
    import subprocess
    import sys

    code = (
        "import sys, skelagnostic.baselines\n"
        "print([m for m in ('lightning', 'hydra', 'pluggy') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
