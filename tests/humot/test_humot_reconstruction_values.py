"""humot.reconstruction: every per-clip figure and its mean recomputed independently in numpy.

Two LaFAN1 clips (30 fps, cm) and an untrained seeded small HuMoT. The test
cuts its own 1 s chunks from numpy forward kinematics (metres), centres them on
the mean of the major joints, rotates them into the model's Z-up frame, runs the
network itself and computes MPJPE in numpy for the model and the three
baselines (the chunk's mean pose, the neutral template at the chunk centre, the
mean root-relative pose along the true root path), and the foot skate (cm/s)
and skate ratio of each and of the chunks themselves (``ground_truth``) with
numpy loops, inside each chunk. Taken from the library: the network (the
method), the per-chunk templates it is given (median bone lengths on the
skeleton's template, :meth:`Topology.templates`), the major-joint mask, the
fixed Y-up -> Z-up axis matrix and the contact detector (``foot_contacts`` on
the clip in metres, tested against an independent rule in
``tests/analysis/test_foot_contacts.py``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import prepare_chunks
from skelagnostic_humot.evaluation.reconstruction import reconstruction_protocol

import skelagnostic as sa
from numpy_reference import foot_skate, global_pose, humot_chunks, mpjpe
from skelagnostic.analysis import foot_contacts
from skelagnostic.evaluation import HeldOut, mean_rows


def _expected(model: HumotAligner, clip: sa.Motion) -> dict[str, Any]:
    """The row of one 30 fps clip: model and baselines, cm (and model MPJPE / height)."""
    topo = model.topology(clip.skeleton)
    major = topo.major.numpy()
    chunks = humot_chunks(global_pose(clip)[1], major)  # metres
    count = len(chunks)
    # the templates the protocol gives the network (the library's, from median bone lengths)
    _, tmpl = prepare_chunks(torch.from_numpy(chunks).float(), topo)
    with torch.no_grad():
        out = model.net(torch.from_numpy(chunks).float(), tmpl, tmpl, None).double().numpy()
    tmpl = tmpl.double().numpy()
    err = np.linalg.norm(out - chunks, axis=-1).mean(axis=(1, 2))
    height = float((tmpl[..., 2].max(-1) - tmpl[..., 2].min(-1)).mean())
    mean_pose = chunks.mean(axis=1, keepdims=True)
    root = chunks[:, :, :1]
    on_trajectory = (chunks - root).mean(axis=1, keepdims=True) + root
    template = (tmpl - tmpl[:, major].mean(axis=1, keepdims=True))[:, None]
    contacts, feet = foot_contacts(clip.to_metres()[: count * 30])
    contacts = contacts.numpy().reshape(count, 30, len(feet))

    def skate(positions: np.ndarray) -> dict[str, float]:  # Z up in the model frame
        mean, ratio = foot_skate(100 * positions, contacts, feet, 30.0, 2, 5 * height)
        return {"foot_skate_cm_s": mean, "foot_skate_ratio": ratio}

    skates = {
        "model": skate(out),
        "mean_pose": skate(np.broadcast_to(mean_pose, chunks.shape)),
        "template": skate(np.broadcast_to(template, chunks.shape)),
        "mean_pose_on_trajectory": skate(on_trajectory),
        "ground_truth": skate(chunks),
    }
    return {
        "skates": skates,
        "chunks": count,
        "model": 100 * float(err.mean()),
        "model_over_height": float(err.mean()) / height,
        "mean_pose": 100 * mpjpe(np.broadcast_to(mean_pose, chunks.shape), chunks),
        "template": 100 * mpjpe(np.broadcast_to(template, chunks.shape), chunks),
        "mean_pose_on_trajectory": 100 * mpjpe(on_trajectory, chunks),
    }


def test_rows_and_means_equal_an_independent_computation(
    lafan_clip: Path, tmp_path: Path, humot_small: dict[str, int]
) -> None:
    motion = sa.read_bvh(lafan_clip)
    motion.units = "cm"
    a, b = motion[:75], motion[200:290]  # 2 and 3 whole chunks (a drops 15 frames)
    a.name, b.name = "a", "b"
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    with torch.no_grad():
        out = reconstruction_protocol(model, HeldOut("test", [a, b]), tmp_path)
    expected = {c.name: _expected(model, c) for c in (a, b)}
    assert [r["clip"] for r in out.rows] == ["a", "b"]
    for row in out.rows:
        want = expected[row["clip"]]
        assert row["chunks"] == want["chunks"]
        values = row["values"]
        assert values["model"]["mpjpe_cm"] == pytest.approx(want["model"], rel=1e-4)
        assert values["model"]["mpjpe_over_height"] == pytest.approx(
            want["model_over_height"], rel=1e-4
        )
        for baseline in ("mean_pose", "template", "mean_pose_on_trajectory"):
            assert values[baseline]["mpjpe_cm"] == pytest.approx(want[baseline], rel=1e-4)
        for method, figures in want["skates"].items():
            assert set(figures) <= set(values[method]), (row["clip"], method)
            for metric, value in figures.items():
                assert values[method][metric] == pytest.approx(value, rel=1e-4, abs=1e-6), (
                    row["clip"],
                    method,
                    metric,
                )
    assert [want["chunks"] for want in expected.values()] == [2, 3]
    # the means (mean_rows, what evaluation.json reports): plain averages over the clips
    mean = mean_rows(out.rows)
    for key, (method, metric) in {
        "model": ("model", "mpjpe_cm"),
        "model_over_height": ("model", "mpjpe_over_height"),
        "mean_pose": ("mean_pose", "mpjpe_cm"),
        "template": ("template", "mpjpe_cm"),
    }.items():
        average = (expected["a"][key] + expected["b"][key]) / 2
        assert mean[method][metric] == pytest.approx(average, rel=1e-4)
    assert out.extra["by_topology"]["unknown"] == mean
    # sanity of the reference: following the true root path beats a static mean pose; the
    # clips have planted feet, and a pose that does not move does not skate
    for want in expected.values():
        assert want["mean_pose_on_trajectory"] < want["mean_pose"]
        assert want["skates"]["mean_pose"]["foot_skate_cm_s"] == 0.0
        assert want["skates"]["ground_truth"]["foot_skate_cm_s"] >= 0.0
