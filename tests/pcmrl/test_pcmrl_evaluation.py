"""Table 2 protocol: metrics, the retargeting baselines, the pcmrl.reconstruction protocol."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from skelagnostic_pcmrl.evaluation import (
    TABLE2_METRICS,
    evaluate_clips,
    evaluate_pair,
    format_table,
    limb_end_pairs,
    reconstruction_protocol,
)
from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner

import skelagnostic as sa
from skelagnostic.baselines import (
    direction_copy,
    name_copy,
    name_match,
    primal_copy,
    primal_match,
)
from skelagnostic.core.motion import UNITS
from skelagnostic.evaluation import EvaluationError, HeldOut
from skelagnostic.representations import PointCloud


@pytest.fixture
def lafan(lafan_clip) -> sa.Motion:
    m = sa.read_bvh(lafan_clip)[:30]
    m.units = "cm"
    return m


def test_name_copy_onto_the_same_skeleton_is_the_identity(lafan) -> None:
    copy = name_copy(lafan, lafan.skeleton)
    assert torch.allclose(
        copy.global_positions().double(), lafan.global_positions().double(), atol=1e-4
    )
    scores = evaluate_pair(copy, lafan, sigmas=(0.0,), num_points=256, seed=0)
    assert scores["end"] == pytest.approx(0.0, abs=1e-6)
    # two independent 256-point clouds on the same motion: only the sampling differs
    assert 0.0 < scores["knn@0"] < 5.0


def test_end_effector_error_is_summed_over_effectors_in_cm(lafan) -> None:
    moved = sa.Motion(
        lafan.skeleton,
        lafan.rotations,
        lafan.root_positions + torch.tensor([10.0, 0.0, 0.0]).double(),
        lafan.fps,
        units="cm",
    )
    scores = evaluate_pair(moved, lafan, sigmas=(0.0, 0.1), num_points=256)
    assert scores["end"] == pytest.approx(5 * 10.0, rel=1e-6)  # 5 effectors, 0.1 m, x100
    # the authors' code: mean |difference| over the 4 limb ends and x, y, z: (10 + 0 + 0) / 3
    assert scores["end_authors"] == pytest.approx(10.0 / 3, rel=1e-6)
    skate = {"foot_skate_cm_s", "foot_skate_ratio"}
    assert set(scores) == {"knn@0", "knn@0.1", "end", "end_authors", *skate}
    # a constant shift does not move a planted foot: the source's own skate
    own = evaluate_pair(lafan, lafan, sigmas=(0.0,), num_points=256)
    assert {k: scores[k] for k in skate} == pytest.approx({k: own[k] for k in skate}, rel=1e-9)


def test_limb_ends_are_the_authors_end_joints(lafan, shared_data) -> None:
    """The wrists and toes: the authors' LeftHand/RightHand/LeftToe[Base]/RightToe[Base].

    Their CMU rig (cgspeed) calls the wrist ``LeftHand``; the shared 3dsMax export
    calls it ``LeftWrist``, the joint its fingers and thumb branch from.
    """
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    src = lafan.skeleton
    names = [(src.joint_names[a], cmu.joint_names[b]) for a, b in limb_end_pairs(src, cmu)]
    assert names == [
        ("LeftHand", "LeftWrist"),
        ("RightHand", "RightWrist"),
        ("LeftToe", "LeftToe"),
        ("RightToe", "RightToe"),
    ]
    assert len(cmu.children(cmu.index("LeftWrist"))) == 2


def test_baselines_lafan_to_cmu(lafan, shared_data) -> None:
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    src = lafan.skeleton
    by_name = {
        cmu.joint_names[t]: (None if s is None else src.joint_names[s])
        for t, s in enumerate(name_match(src, cmu))
    }
    assert by_name["Hips"] == "Hips" and by_name["Head"] == "Head"
    assert by_name["LeftToe"] == "LeftToe"
    # CMU's 3dsMax leg names differ from LaFAN1's: the primal skeleton pairs the legs anyway
    primal = {cmu.joint_names[t]: src.joint_names[s] for t, s in primal_match(src, cmu).items()}
    leg = [n for n in primal if cmu.body_groups[cmu.index(n)] == "left_leg"]
    assert leg and all(src.body_groups[src.index(primal[n])] == "left_leg" for n in leg)
    result = evaluate_clips([lafan], cmu, sigmas=(0.0,), num_points=256)
    assert set(result["rows"]) == {
        "original",
        "name_copy",
        "primal_copy",
        "direction_copy",
        "direction_copy_unscaled_root",
    }
    assert result["rows"]["original"]["knn@0"] < result["rows"]["name_copy"]["knn@0"]
    assert format_table(result).count("\n") == 6


def test_reconstruction_protocol_rows(lafan, tmp_path) -> None:
    torch.manual_seed(0)
    model = PcmrlReconAligner(dim=16, stages=1, target="biped31").eval()
    lafan.name = "clip"
    with torch.no_grad():
        out = reconstruction_protocol(model, HeldOut("test", [lafan[:12]]), tmp_path)
    (row,) = out.rows
    assert row["clip"] == "clip" and row["frames"] == 12
    assert out.methods == [
        "model",
        "original",
        "name_copy",
        "primal_copy",
        "direction_copy",
        "direction_copy_unscaled_root",
    ]
    assert set(row["values"]["model"]) == set(TABLE2_METRICS)
    assert row["values"]["original"]["end"] == row["values"]["original"]["end_authors"] == 0.0


def _quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate ``v [..., 3]`` by unit quaternions ``q [..., 4]`` (w, x, y, z), by the matrix."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    return np.einsum("...ij,...j->...i", m, v)


def _brute_force_knn(
    result: sa.Motion, source: sa.Motion, sigma: float, seed: int, k: int, points: int, stride: int
) -> float:
    """Table 2's KNN distance x100 by brute force: every trajectory pair, numpy only.

    Only the random draw of the points (bone, place, offset) comes from the library.
    """
    clouds = []
    for motion, s in ((source, seed), (result, seed + 1)):
        m = motion.to_metres().double()
        draw = PointCloud(points, sigma).sample(m.skeleton, torch.Generator().manual_seed(s))
        rot = m.global_rotations().numpy()[::stride][:, draw.joints.numpy()]
        pos = m.global_positions().numpy()[::stride][:, draw.joints.numpy()]
        local = np.broadcast_to(draw.local.numpy(), (*rot.shape[:-1], 3))
        clouds.append((pos + _quat_rotate(rot, local), draw.groups.numpy()))
    (pa, ga), (pb, gb) = clouds
    frames, total = pa.shape[0], 0.0
    for i in range(pa.shape[1]):  # every source point: its k nearest result trajectories
        same = np.flatnonzero(gb == ga[i])
        delta = np.linalg.norm(pb[:, same] - pa[:, i : i + 1], axis=-1).sum(axis=0)
        total += np.sort(delta)[:k].sum()
    return 100.0 * total / (pa.shape[1] * k * frames)


def test_table2_figures_equal_a_brute_force_computation(lafan, shared_data) -> None:
    """knn@sigma (Eq. 5 per point, neighbour and frame, x100) and L_end against numpy."""
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    clip = lafan[:8]
    result = primal_copy(clip, cmu.scaled(1.0))
    options = {"num_points": 96, "k": 3, "seed": 7, "stride": 2}
    scores = evaluate_pair(result, clip, sigmas=(0.0, 0.05), **options)
    for sigma in (0.0, 0.05):
        expected = _brute_force_knn(result, clip, sigma, 7, 3, 96, 2)
        assert scores[f"knn@{sigma:g}"] == pytest.approx(expected, rel=1e-9)
    # L_end: hands, feet and head matched by hand-picked names, metres x100, summed
    src, res = clip.to_metres().double(), result.to_metres().double()
    # CMU's hands end at LFingers / RFingers (its lhand / rhand bones have zero length)
    pairs = {
        "LeftHand": "LFingers",
        "RightHand": "RFingers",
        "Head": "Head",
        "LeftToe": "LeftToe",
        "RightToe": "RightToe",
    }
    pa = src.global_positions().numpy()[::2]
    pb = res.global_positions().numpy()[::2]
    end = sum(
        np.linalg.norm(pb[:, cmu.index(b)] - pa[:, clip.skeleton.index(a)], axis=-1).mean()
        for a, b in pairs.items()
    )
    assert scores["end"] == pytest.approx(100.0 * end, rel=1e-9)


def test_reconstruction_protocol_rows_are_per_clip_figures(lafan, shared_data, tmp_path) -> None:
    """Each held-out clip's row holds its own Table 2 figures, for the model and baselines."""
    torch.manual_seed(0)
    model = PcmrlReconAligner(dim=16, stages=1, target="biped31").eval()
    a, b = lafan[:14], lafan[14:24]
    a.name, b.name = "a", "b"
    with torch.no_grad():
        held = HeldOut("test", [a, b])
        out = reconstruction_protocol(model, held, tmp_path, max_frames=8, stride=2)
        target = model.target_skeleton.scaled(1.0 / UNITS[model.target_units])
        for row, clip in zip(out.rows, (a[:8], b[:8]), strict=True):
            assert row["frames"] == 8
            for name, result in (
                ("name_copy", name_copy(clip, target)),
                ("primal_copy", primal_copy(clip, target)),
                ("direction_copy", direction_copy(clip, target)),
                ("model", model.retarget(clip, target)),
            ):
                assert row["values"][name] == evaluate_pair(result, clip, stride=2), name
        assert [r["clip"] for r in out.rows] == ["a", "b"]
        assert out.extra["options"] == {"stride": 2, "max_frames": 8}
        with pytest.raises(EvaluationError, match="stride"):
            reconstruction_protocol(model, held, tmp_path, stride=0)


def test_clip_means_skip_clips_without_a_planted_foot() -> None:
    """The foot skate needs a planted foot: a clip without one has no skate figure, and
    the mean is over the clips that have it (the other figures over every clip)."""
    walk = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=3)[0]
    run = sa.procedural.generate("biped22", "run", seconds=1.0, fps=30, seed=5)[0]
    target = sa.procedural.skeleton("biped31")
    result = evaluate_clips([walk, run], target, sigmas=(0.0,), num_points=256)
    walk_rows, run_rows = (clip["rows"] for clip in result["per_clip"])
    assert "foot_skate_cm_s" in walk_rows["name_copy"]
    assert "foot_skate_cm_s" not in run_rows["name_copy"]
    for method, mean in result["rows"].items():
        assert mean["foot_skate_cm_s"] == walk_rows[method]["foot_skate_cm_s"]
        both = (walk_rows[method]["knn@0"] + run_rows[method]["knn@0"]) / 2
        assert mean["knn@0"] == pytest.approx(both)
    assert "nan" not in format_table(result)
