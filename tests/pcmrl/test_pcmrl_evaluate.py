"""Table 2 protocol: metrics, the joint-name-copy baseline, the command line."""

from __future__ import annotations

import json

import pytest
import torch
from skelagnostic_pcmrl.evaluate import (
    evaluate_pair,
    format_table,
    main,
    name_copy,
    name_copy_mapping,
)

import skelagnostic as sa


@pytest.fixture
def lafan(lafan_clip) -> sa.Motion:
    m = sa.read_bvh(lafan_clip)[:30]
    m.units = "cm"
    return m


def test_name_copy_onto_the_same_skeleton_is_the_identity(lafan) -> None:
    copy = name_copy(lafan, lafan.skeleton)
    assert torch.allclose(copy.global_positions().double(), lafan.global_positions().double(),
                          atol=1e-4)
    scores = evaluate_pair(copy, lafan, sigmas=(0.0,), num_points=256, seed=0)
    assert scores["end"] == pytest.approx(0.0, abs=1e-6)
    # two independent 256-point clouds on the same motion: only the sampling differs
    assert 0.0 < scores["knn@0"] < 5.0


def test_end_effector_error_is_summed_over_effectors_in_cm(lafan) -> None:
    moved = sa.Motion(lafan.skeleton, lafan.rotations,
                      lafan.root_positions + torch.tensor([10.0, 0.0, 0.0]).double(), lafan.fps,
                      units="cm")
    scores = evaluate_pair(moved, lafan, sigmas=(0.0, 0.1), num_points=256)
    assert scores["end"] == pytest.approx(5 * 10.0, rel=1e-6)  # 5 effectors, 0.1 m, x100
    assert set(scores) == {"knn@0", "knn@0.1", "end"}


def test_name_copy_mapping_lafan_to_cmu(lafan, shared_data) -> None:
    cmu = sa.read_bvh(shared_data / "human" / "cmu" / "131_01.bvh").skeleton
    src = lafan.skeleton
    mapping = {cmu.joint_names[t]: src.joint_names[s]
               for t, s in name_copy_mapping(src, cmu).items()}
    assert mapping["Hips"] == "Hips" and mapping["Head"] == "Head"
    assert mapping["LeftToe"] == "LeftToe"
    # by body group and rank when names differ
    assert mapping["LeftHip"] == "LeftUpLeg" and mapping["LeftKnee"] == "LeftLeg"
    assert mapping["RightAnkle"] == "RightFoot"
    result = name_copy(lafan, cmu)
    assert result.skeleton is cmu and result.units == "cmu"
    assert result.num_frames == lafan.num_frames


def test_command_line_writes_table_and_json(lafan_clip, shared_data, tmp_path, capsys) -> None:
    out = tmp_path / "eval.json"
    result = main([str(lafan_clip), "--target", str(shared_data / "human" / "cmu" / "131_01.bvh"),
                   "--target-units", "cmu", "--max-frames", "20", "--points", "256",
                   "--sigmas", "0", "0.05", "--json", str(out)])
    printed = capsys.readouterr().out
    assert "| name_copy |" in printed and "KNN sigma=0.05" in printed
    saved = json.loads(out.read_text())
    assert set(saved["rows"]) == {"original", "name_copy"}
    assert saved["rows"]["original"]["knn@0"] < saved["rows"]["name_copy"]["knn@0"]
    assert format_table(result).count("\n") == 3
