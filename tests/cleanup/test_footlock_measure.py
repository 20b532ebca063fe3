"""foot_lock_figures and ``evaluate cleanup=footlock``: the measurement of the foot lock.

The figures are recomputed with numpy loops on the motions before and after
``foot_lock`` (the method under test); the contacts come from the library's
detector (tested against an independent rule in ``tests/analysis``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from numpy_reference import foot_skate
from skelagnostic import procedural
from skelagnostic.analysis import foot_contacts
from skelagnostic.cleanup import FOOT_LOCK_METRICS, foot_lock, foot_lock_figures
from skelagnostic.cli.evaluate import measure_cleanup
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import MODEL, Evaluation, EvaluationError, mean_rows


def _largest_acceleration(positions: np.ndarray, fps: float) -> float:
    """Largest joint acceleration (the positions' units / s^2), numpy loops over joints."""
    return (
        max(
            float(np.linalg.norm(positions[t + 1, j] - 2 * positions[t, j] + positions[t - 1, j]))
            for t in range(1, len(positions) - 1)
            for j in range(positions.shape[1])
        )
        * fps**2
    )


def test_figures_equal_an_independent_computation() -> None:
    walk, _ = procedural.generate("biped22", "walk", seconds=3.0, fps=30, seed=0)
    assert walk.units == "cm"
    contacts, feet = foot_contacts(walk)
    locked = foot_lock(walk, contacts, feet)
    before = walk.global_positions().double().numpy()
    after = locked.global_positions().double().numpy()
    up, fps = walk.skeleton.up_index, walk.fps
    skate_in = foot_skate(before, contacts.numpy(), feet, fps, up, math.inf)[0]
    skate_out = foot_skate(after, contacts.numpy(), feet, fps, up, math.inf)[0]
    want = {
        "footlock_skate_before_cm_s": skate_in,
        "footlock_skate_after_cm_s": skate_out,
        "footlock_skate_reduction_pct": 100 * (1 - skate_out / skate_in),
        "footlock_mpjpe_cm": float(np.linalg.norm(after - before, axis=-1).mean()),
        "footlock_accel_max_input": _largest_acceleration(before, fps) / 100,
        "footlock_accel_max_locked": _largest_acceleration(after, fps) / 100,
    }
    want["footlock_new_accel_spike"] = float(
        want["footlock_accel_max_locked"] > 1.05 * want["footlock_accel_max_input"]
    )
    got = foot_lock_figures(walk)
    assert set(got) == set(FOOT_LOCK_METRICS)
    assert got == pytest.approx(want, rel=1e-6)
    # the targets on a clean procedural walk
    assert got["footlock_skate_reduction_pct"] >= 70
    assert got["footlock_mpjpe_cm"] <= 1
    assert got["footlock_new_accel_spike"] == 0


def test_a_one_frame_contact_between_solved_frames_does_not_make_the_knee_jump() -> None:
    """A contact of one frame pins the foot where it is (zero offset); its frame is solved
    like its neighbours, else the IK's own small changes stop there for one frame."""
    walk, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
    contacts, feet = foot_contacts(walk)
    right = feet.index(walk.skeleton.index("RightToe"))
    assert contacts[7, right] and not contacts[6, right] and not contacts[8, right]
    locked = foot_lock(walk, contacts, feet)
    knee = walk.skeleton.index("RightLeg")
    near = locked.global_positions().double()[3:12, knee : knee + 1].numpy()
    largest_input = _largest_acceleration(walk.global_positions().double().numpy(), walk.fps)
    assert _largest_acceleration(near, walk.fps) <= largest_input  # was 2.5 x before the fix


def test_evaluate_cleanup_adds_the_figures_to_the_model_column() -> None:
    walk, _ = procedural.generate("biped22", "walk", seconds=3.0, fps=30, seed=0)
    dog, _ = procedural.generate("quadruped", "walk", seconds=3.0, fps=30, seed=1)
    result = Evaluation(
        {"mpjpe_cm": "error"},
        [{"clip": "walk", "values": {MODEL: {"mpjpe_cm": 1.0}, "baseline": {"mpjpe_cm": 2.0}}}],
        outputs={"walk": lambda: walk, "dog": lambda: dog},
    )
    measure_cleanup(result, "test.protocol")
    assert [row["clip"] for row in result.rows] == ["walk", "dog"]  # a row for a new clip
    walk_values = result.rows[0]["values"]
    assert walk_values[MODEL] == {"mpjpe_cm": 1.0, **foot_lock_figures(walk)}
    assert walk_values["baseline"] == {"mpjpe_cm": 2.0}
    assert set(FOOT_LOCK_METRICS) <= set(result.metrics)
    mean = mean_rows(result.rows)[MODEL]
    both = [foot_lock_figures(m)["footlock_mpjpe_cm"] for m in (walk, dog)]
    assert mean["footlock_mpjpe_cm"] == pytest.approx(sum(both) / 2)
    assert any("cleanup=footlock" in note for note in result.notes)


def test_evaluate_cleanup_errors() -> None:
    with pytest.raises(EvaluationError, match="hands over no output motion"):
        measure_cleanup(Evaluation({}, [{"clip": "a", "values": {MODEL: {}}}]), "x.y")

    def no_legs() -> None:
        raise SkelagnosticError("foot contacts: no foot found on skeleton 'arm'")

    broken = Evaluation({}, [{"clip": "a", "values": {MODEL: {}}}], outputs={"a": no_legs})
    with pytest.raises(EvaluationError, match="cleanup=footlock: clip 'a': foot contacts"):
        measure_cleanup(broken, "x.y")


def test_ik_keeps_the_pose_where_the_ankle_stays() -> None:
    """A target at the ankle's own place changes nothing, even on a leg whose knee plane
    turns from frame to frame (a network's output): the IK keeps each frame's own plane
    (the averaged hinge plane of the clip moved such knees by up to 16 cm)."""
    from skelagnostic.cleanup import leg_chain
    from skelagnostic.cleanup.footlock import _solve_leg
    from skelagnostic.core import quaternion as quat

    walk, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
    hip, knee, ankle = leg_chain(walk, walk.skeleton.index("LeftToe"))
    generator = torch.Generator().manual_seed(0)
    axis = torch.randn(walk.num_frames, 3, generator=generator, dtype=torch.float64)
    angle = 0.4 * torch.rand(walk.num_frames, 1, generator=generator, dtype=torch.float64)
    axis = axis / axis.norm(dim=-1, keepdim=True)
    half = angle / 2
    twist = torch.cat([half.cos(), half.sin() * axis], dim=-1).to(walk.rotations)
    rotations = walk.rotations.clone()
    rotations[:, hip] = quat.mul(rotations[:, hip], twist)  # the knee plane wanders
    noisy = walk._replace(rotations=rotations)
    positions = noisy.global_positions()
    frames = torch.arange(walk.num_frames)
    solved = _solve_leg(noisy, rotations, (hip, knee, ankle), positions[:, ankle], frames)
    moved = noisy._replace(rotations=solved).global_positions()
    assert float((moved - positions).norm(dim=-1).amax()) < 1e-3  # cm
