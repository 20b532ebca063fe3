"""pcmrl.reconstruction: every reported figure recomputed independently in numpy.

The protocol runs on two short LaFAN1 clips with an untrained (seeded) stage-1
model. Each per-clip figure of ``model``, ``original``, ``name_copy``,
``primal_copy``, ``direction_copy`` and ``direction_copy_unscaled_root``
(temporal KNN distance at the five offsets, end-effector error under Eq. 6 and
under the authors' code, x100 in metres) and their means in ``evaluation.json``
are recomputed here with numpy forward kinematics, a brute-force KNN over every
pair of point trajectories (PC-MRL Eq. 5) and hand-picked end-effector pairs
(Eq. 6: hands, feet, head; the authors' ``train_pointcloud.py``: wrists and
toes), and the foot skate (cm/s, and the share of planted steps above 0.05
heights/s) of the target's toes on the source toes' contacts, on the frames the
metrics read, with numpy loops. Only the seeded draw of the points on the bones
(``PointCloud.sample``), the contact detector (``contacts_of_positions``, tested
against an independent rule in ``tests/analysis/test_foot_contacts.py``) and the
methods' own outputs (the retargeted motions) come from the library.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.distance import cdist
from skelagnostic_pcmrl.evaluation import BASELINES, evaluate_pair, reconstruction_protocol
from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner

import skelagnostic as sa
from numpy_reference import foot_skate, global_pose, metres, qrot
from skelagnostic.analysis import contacts_of_positions
from skelagnostic.baselines import direction_copy, name_copy, primal_copy
from skelagnostic.core.motion import UNITS
from skelagnostic.evaluation import HeldOut, write_evaluation
from skelagnostic.representations import PointCloud

SIGMAS = (0.0, 0.01, 0.05, 0.1, 0.2)
MAX_FRAMES, STRIDE = 6, 3
#: End effectors matched by hand, LaFAN1 -> the procedural biped31 (CMU hierarchy): the end
#: of each limb chain and the head (biped31's hands end at their index-finger joints).
END_EFFECTORS = {
    "LeftHand": "LeftHandIndex1",
    "RightHand": "RightHandIndex1",
    "Head": "Head",
    "LeftToe": "LeftToeBase",
    "RightToe": "RightToeBase",
}

#: The authors' end joints (``LeftHand``, ``RightHand``, ``LeftToe[Base]``, ``RightToe[Base]``,
#: no head), LaFAN1 -> biped31, whose hand is the wrist its fingers branch from.
AUTHORS_END_JOINTS = {
    "LeftHand": "LeftHand",
    "RightHand": "RightHand",
    "LeftToe": "LeftToeBase",
    "RightToe": "RightToeBase",
}


def _cloud(motion: sa.Motion, sigma: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``[F, 1024, 3]`` points (every ``STRIDE``-th frame) and their body groups, in metres."""
    scale = metres(motion)
    draw = PointCloud(1024, sigma).sample(
        motion.skeleton.scaled(scale), torch.Generator().manual_seed(seed)
    )
    grot, gpos = global_pose(motion, scale)
    joints = draw.joints.numpy()
    rot, pos = grot[::STRIDE][:, joints], gpos[::STRIDE][:, joints]
    local = np.broadcast_to(draw.local.numpy(), pos.shape)
    return pos + qrot(rot, local), draw.groups.numpy()


def _knn(result: sa.Motion, source: sa.Motion, sigma: float, seed: int, k: int = 8) -> float:
    """Eq. 5 x100: per source point, its k nearest result trajectories of the same group."""
    pa, ga = _cloud(source, sigma, seed)
    pb, gb = _cloud(result, sigma, seed + 1)
    dist = np.zeros((pa.shape[1], pb.shape[1]))
    for frame in range(pa.shape[0]):
        dist += cdist(pa[frame], pb[frame])
    dist[ga[:, None] != gb[None]] = np.inf
    nearest = np.sort(dist, axis=1)[:, :k]
    return 100.0 * float(nearest.sum() / (pa.shape[1] * k * pa.shape[0]))


def _end(result: sa.Motion, source: sa.Motion) -> float:
    """Eq. 6 x100: summed over the matched effectors, mean over the scored frames."""
    pa = global_pose(source)[1][::STRIDE]
    pb = global_pose(result)[1][::STRIDE]
    src, res = source.skeleton, result.skeleton
    return 100.0 * sum(
        float(np.linalg.norm(pb[:, res.index(b)] - pa[:, src.index(a)], axis=-1).mean())
        for a, b in END_EFFECTORS.items()
    )


def _end_authors(result: sa.Motion, source: sa.Motion) -> float:
    """x100: mean of |difference| over frames, the four limb ends and x, y, z, in metres."""
    pa = global_pose(source)[1][::STRIDE]
    pb = global_pose(result)[1][::STRIDE]
    src, res = source.skeleton, result.skeleton
    a = [src.index(j) for j in AUTHORS_END_JOINTS]
    b = [res.index(j) for j in AUTHORS_END_JOINTS.values()]
    return 100.0 * float(np.mean(np.abs(pb[:, b] - pa[:, a])))


def _skate(result: sa.Motion, source: sa.Motion) -> dict[str, float]:
    """Skate of the result's toes on the source toes' contacts, every STRIDE-th frame (cm)."""
    feet = [source.skeleton.index(j) for j in ("LeftToe", "RightToe")]
    toes = ("LeftToe", "RightToe") if result is source else ("LeftToeBase", "RightToeBase")
    res_feet = [result.skeleton.index(j) for j in toes]
    fps = source.fps / STRIDE
    src = global_pose(source)[1][::STRIDE]
    height = source.skeleton.height() * metres(source)
    contacts = contacts_of_positions(
        torch.from_numpy(src[:, feet]), fps, source.skeleton.up_index, height
    ).numpy()
    res = 100 * global_pose(result)[1][::STRIDE]
    threshold = 5 * result.skeleton.height() * metres(result)
    mean, ratio = foot_skate(res, contacts, res_feet, fps, result.skeleton.up_index, threshold)
    return {"foot_skate_cm_s": mean, "foot_skate_ratio": ratio} if np.isfinite(mean) else {}


def _figures(result: sa.Motion, source: sa.Motion, seed: int) -> dict[str, float]:
    out = {f"knn@{s:g}": _knn(result, source, s, seed) for s in SIGMAS} | _skate(result, source)
    # the source against itself: every effector on itself, no error by definition
    if result is source:
        return out | {"end": 0.0, "end_authors": 0.0}
    return out | {"end": _end(result, source), "end_authors": _end_authors(result, source)}


def test_rows_and_means_equal_an_independent_computation(lafan_clip: Path, tmp_path: Path) -> None:
    motion = sa.read_bvh(lafan_clip)
    motion.units = "cm"
    a, b = motion[:14], motion[100:120]
    a.name, b.name = "a", "b"
    torch.manual_seed(0)
    model = PcmrlReconAligner(dim=16, stages=1, target="biped31").eval()
    held = HeldOut("test", [a, b])
    with torch.no_grad():
        out = reconstruction_protocol(model, held, tmp_path, max_frames=MAX_FRAMES, stride=STRIDE)
        target = model.target_skeleton.scaled(1.0 / UNITS[model.target_units])
        assert set(END_EFFECTORS.values()) <= set(target.joint_names)
        assert set(AUTHORS_END_JOINTS.values()) <= set(target.joint_names)
        expected = {}
        for clip in (a, b):
            cut = clip[:MAX_FRAMES]
            expected[clip.name] = {
                "model": _figures(model.retarget(cut, target), cut, 0),
                # an independent cloud (seeds 2 and 3) on the source motion itself
                "original": _figures(cut, cut, 2),
                "name_copy": _figures(name_copy(cut, target), cut, 0),
                "primal_copy": _figures(primal_copy(cut, target), cut, 0),
                "direction_copy": _figures(direction_copy(cut, target), cut, 0),
                "direction_copy_unscaled_root": _figures(
                    direction_copy(cut, target, root="source"), cut, 0
                ),
            }
    assert [r["clip"] for r in out.rows] == ["a", "b"]
    assert [r["frames"] for r in out.rows] == [MAX_FRAMES, MAX_FRAMES]
    # the source plants a foot in at least one clip: the skate columns are exercised
    assert any("foot_skate_cm_s" in want["model"] for want in expected.values())
    for row in out.rows:
        want = expected[row["clip"]]
        assert set(row["values"]) == set(want)
        for method, figures in want.items():
            assert set(row["values"][method]) == set(figures), method
            for metric, value in figures.items():
                got = row["values"][method][metric]
                assert got == pytest.approx(value, rel=1e-6, abs=1e-9), (row["clip"], method)
    # the means written to evaluation.json: plain averages over the two clips
    write_evaluation(
        out,
        tmp_path,
        protocol="pcmrl.reconstruction",
        model="pcmrl",
        description="",
        checkpoint="none",
        data={"source": "lafan1"},
        held=held,
    )
    report = json.loads((tmp_path / "evaluation.json").read_text())
    for method in expected["a"]:
        for metric in expected["a"][method]:
            mean = (expected["a"][method][metric] + expected["b"][method][metric]) / 2
            assert report["mean"][method][metric] == pytest.approx(mean, rel=1e-6, abs=1e-9)
    # sanity of the reference itself: the independent cloud on the source is the closest
    for want in expected.values():
        assert want["original"]["knn@0"] < min(want[m]["knn@0"] for m in want if m != "original")


@pytest.mark.parametrize("factor", [0.8, 1.25])
def test_unscaled_direction_copy_onto_a_scaled_copy_of_its_skeleton(factor: float) -> None:
    """Closed forms on procedural data: the unscaled-root copy onto ``k x`` its own skeleton.

    Every bone keeps its direction and the root its path, so each joint lands at
    ``root + k (p - root)``: an effector is off by ``|k - 1| |p - root|``. Eq. 6 sums that
    over hands, feet and head; the authors' error averages ``|k - 1| |p - root|_1 / 3``
    over the wrists and toes.
    """
    motion = sa.procedural.generate("biped22", "walk", seconds=1.0)[0]
    target = motion.skeleton.scaled(factor)
    copy = BASELINES["direction_copy_unscaled_root"](motion, target)
    # the root path is the source's, exactly
    np.testing.assert_array_equal(
        copy.root_positions.double().numpy(), motion.root_positions.double().numpy()
    )
    pos = global_pose(motion)[1]  # metres
    rel = pos - pos[:, :1]
    index = motion.skeleton.index
    eq6 = [index(n) for n in ("LeftToe", "RightToe", "Head", "LeftHand", "RightHand")]
    ends = [index(n) for n in ("LeftHand", "RightHand", "LeftToe", "RightToe")]
    k = abs(factor - 1.0)
    want_end = 100.0 * k * float(np.linalg.norm(rel[:, eq6], axis=-1).mean(axis=0).sum())
    want_authors = 100.0 * k * float(np.abs(rel[:, ends]).mean())
    got = evaluate_pair(copy, motion, sigmas=(0.0,))
    assert got["end"] == pytest.approx(want_end, rel=1e-6)
    assert got["end_authors"] == pytest.approx(want_authors, rel=1e-6)
    # the same copy with the scaled root rule is further from the source's positions
    scaled = evaluate_pair(BASELINES["direction_copy"](motion, target), motion, sigmas=(0.0,))
    assert scaled["end"] > got["end"] and scaled["knn@0"] > got["knn@0"]
