"""example.reconstruction: every per-clip figure and its mean recomputed independently in numpy.

Two LaFAN1 clips and the untrained (seeded) example aligner. The model's
encode-decode output is the method under test; the test recomputes, with numpy
forward kinematics in metres, the MPJPE of the model and of both baselines (the
clip's temporal mean pose; its mean root-relative pose along the true root path)
over the frames both motions have, and MPJPE / height; and the foot skate (cm/s)
and skate ratio of each, and of the clip itself (``ground_truth``), on the clip's
contacts. Taken from the library: the skeleton's height (:meth:`Skeleton.height`,
the extent of its canonical template, a rig-reading construction not re-derived
here) and the contact detector (``foot_contacts``, tested against an independent
rule in ``tests/analysis/test_foot_contacts.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import skelagnostic as sa
from numpy_reference import foot_skate, global_pose, metres, mpjpe
from skelagnostic import plugins
from skelagnostic.analysis import foot_contacts
from skelagnostic.evaluation import HeldOut, mean_rows


def _expected(aligner: object, clip: sa.Motion) -> dict[str, dict[str, float]]:
    with torch.no_grad():
        pred = aligner.decode(aligner.encode(clip), clip.skeleton)
    assert pred.fps == clip.fps
    truth = global_pose(clip)[1]
    guess = global_pose(pred)[1]
    frames = min(len(truth), len(guess))
    truth, guess = truth[:frames], guess[:frames]
    height = clip.skeleton.height() * metres(clip)
    root = truth[:, :1]
    contacts, feet = foot_contacts(clip[:frames])
    up = clip.skeleton.up_index

    def skate(positions: np.ndarray) -> dict[str, float]:
        mean, ratio = foot_skate(100 * positions, contacts.numpy(), feet, clip.fps, up, 5 * height)
        return {"foot_skate_cm_s": mean, "foot_skate_ratio": ratio}

    out = {}
    for method, positions in (
        ("model", guess),
        ("mean_pose", np.broadcast_to(truth.mean(axis=0), truth.shape)),
        ("mean_pose_on_trajectory", (truth - root).mean(axis=0) + root),
    ):
        err = mpjpe(positions, truth)
        out[method] = {"mpjpe_cm": 100.0 * err, "mpjpe_over_height": err / height}
        out[method] |= skate(positions)
    out["ground_truth"] = skate(truth)
    return out


def test_rows_and_means_equal_an_independent_computation(
    example_plugin: Path, lafan_clip: Path, tmp_path: Path
) -> None:
    from skelagnostic_example.plugin import reconstruction

    torch.manual_seed(0)
    aligner = plugins.load_aligner("example", hidden=32, latent=8).eval()
    motion = sa.read_bvh(lafan_clip)
    motion.units = "cm"
    a, b = motion[:40], motion[150:210]
    a.name, b.name = "a", "b"
    out = reconstruction(aligner, HeldOut("test", [a, b]), tmp_path)
    expected = {c.name: _expected(aligner, c) for c in (a, b)}
    assert [r["clip"] for r in out.rows] == ["a", "b"]
    assert [r["frames"] for r in out.rows] == [40, 60]
    for row in out.rows:
        want = expected[row["clip"]]
        assert set(row["values"]) == set(want)
        for method, figures in want.items():
            for metric, value in figures.items():
                got = row["values"][method][metric]
                assert got == pytest.approx(value, rel=1e-6), (row["clip"], method, metric)
    mean = mean_rows(out.rows)
    for method, figures in expected["a"].items():
        for metric, value in figures.items():
            average = (value + expected["b"][method][metric]) / 2
            assert mean[method][metric] == pytest.approx(average, rel=1e-6)
    # sanity of the reference: following the true root path beats a static mean pose; the
    # clips have planted feet, a static pose never skates, the untrained model does
    for want in expected.values():
        assert want["mean_pose_on_trajectory"]["mpjpe_cm"] < want["mean_pose"]["mpjpe_cm"]
        assert want["mean_pose"]["foot_skate_cm_s"] == 0.0
        assert want["model"]["foot_skate_cm_s"] > want["ground_truth"]["foot_skate_cm_s"]
