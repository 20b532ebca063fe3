"""Table 2 protocol: metrics, the retargeting baselines, the pcmrl.reconstruction protocol."""

from __future__ import annotations

import pytest
import torch
from skelagnostic_pcmrl.evaluation import (
    TABLE2_METRICS,
    evaluate_clips,
    evaluate_pair,
    format_table,
    reconstruction_protocol,
)
from skelagnostic_pcmrl.recon import PcmrlReconAligner

import skelagnostic as sa
from skelagnostic.baselines import name_copy, name_match, primal_match
from skelagnostic.evaluation import HeldOut


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
    assert set(scores) == {"knn@0", "knn@0.1", "end"}


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
    assert set(result["rows"]) == {"original", "name_copy", "primal_copy"}
    assert result["rows"]["original"]["knn@0"] < result["rows"]["name_copy"]["knn@0"]
    assert format_table(result).count("\n") == 4


def test_reconstruction_protocol_rows(lafan, tmp_path) -> None:
    torch.manual_seed(0)
    model = PcmrlReconAligner(dim=16, stages=1, target="biped31").eval()
    lafan.name = "clip"
    with torch.no_grad():
        out = reconstruction_protocol(model, HeldOut("test", [lafan[:12]]), tmp_path)
    (row,) = out.rows
    assert row["clip"] == "clip" and row["frames"] == 12
    assert out.methods == ["model", "original", "name_copy", "primal_copy"]
    assert set(row["values"]["model"]) == set(TABLE2_METRICS)
    assert row["values"]["original"]["end"] == 0.0
