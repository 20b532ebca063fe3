import json

import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluate import chunks_of, reconstruction

import skelagnostic as sa


def test_reconstruction_baselines_on_a_rigidly_translated_pose(humot_small):
    """A frozen pose sliding at constant speed: only the trajectory baseline is exact."""
    motion = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30)[0]
    pose = motion.global_positions().float()[:1] / 100  # [1, J, 3] metres
    shift = torch.zeros(30, 1, 3)
    shift[:, 0, 2] = torch.linspace(0, 0.9, 30)  # 0.9 m forward along Z (the skeleton's facing)
    chunks = (pose + shift)[None]
    model = HumotAligner(**humot_small).eval()
    out = reconstruction(model, chunks, model.topology(motion.skeleton), "y")
    assert out["mean_pose_on_trajectory_cm"] < 1e-4
    expected = 100 * (shift[:, 0, 2] - shift[:, 0, 2].mean()).abs().mean()
    assert abs(out["mean_pose_cm"] - float(expected)) < 1e-3
    assert out["chunks"] == 1 and out["mpjpe_cm"] > 0


def test_chunks_of_resamples_and_converts_to_metres():
    motion = sa.procedural.generate("biped17", "run", seconds=2.2, fps=60)[0]
    chunks = chunks_of(motion)
    assert chunks.shape == (2, 30, 17, 3)
    ref = motion.resample(30.0).global_positions().float()[:30] / 100
    assert torch.allclose(chunks[0], ref, atol=1e-5)


# --------------------------------------------------------------- retargeting and curves
def _checkpoint(model, path):
    """A Lightning-format checkpoint of an untrained model (no trainer needed)."""
    import lightning as L

    torch.save({"state_dict": model.state_dict(), "hyper_parameters": dict(model.hparams),
                "pytorch-lightning_version": L.__version__}, path)
    return path


def test_name_match_pairs_same_side_joints_by_name():
    from skelagnostic_humot.evaluate import name_match

    a = sa.procedural.skeleton("biped22")
    b = sa.procedural.skeleton("biped31")
    match = name_match(a, b)
    names = {b.joint_names[j]: (None if i is None else a.joint_names[i])
             for j, i in enumerate(match)}
    assert names["Hips"] == "Hips"
    assert names["LeftUpLeg"] == "LeftUpLeg" and names["RightForeArm"] == "RightForeArm"
    assert names["LeftToeBase"] == "LeftToe"
    for target, source in names.items():
        if source is not None and target != "Hips":
            # never across sides
            assert target.startswith(("Left", "L")) == source.startswith(("Left", "L"))


def test_name_copy_retarget_is_identity_on_the_same_skeleton_and_scales_the_root():
    from skelagnostic_humot.evaluate import name_copy_retarget

    motion = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=4)[0]
    same = name_copy_retarget(motion, motion.skeleton, "cm", "cm")
    assert torch.allclose(same.global_positions(), motion.global_positions(), atol=1e-6)
    big = name_copy_retarget(motion, motion.skeleton.scaled(2.0), "cm", "cm")
    assert torch.allclose(big.global_positions(), 2 * motion.global_positions(), atol=1e-6)


def test_motion_error_of_a_translation():
    from skelagnostic_humot.evaluate import _motion_error

    truth = sa.procedural.generate("biped17", "run", seconds=1.0, fps=30)[0]
    shifted = sa.Motion(truth.skeleton, truth.rotations,
                        truth.root_positions + torch.tensor([3.0, 0.0, 4.0], dtype=torch.float64),
                        truth.fps)
    err = _motion_error(shifted, truth)
    assert abs(err["mpjpe"] - 5.0) < 1e-6
    assert abs(err["mpjpe_over_height"] - 5.0 / truth.skeleton.height()) < 1e-9
    assert err["root_aligned_mpjpe"] < 1e-6


def test_retargeting_procedural_uses_paired_ground_truth(humot_small):
    from skelagnostic_humot.evaluate import retargeting_procedural

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    out = retargeting_procedural(model, kinds=("biped22", "biped17"), gaits=("walk",),
                                 clips_per_gait=1, seconds=1.0)
    assert set(out) == {"biped22->biped17", "biped17->biped22", "mean"}
    pair = out["biped22->biped17"]
    assert pair["clips"] == 1
    for method in ("humot", "name_copy"):
        assert 0 < pair[f"{method}_mpjpe_over_height"] < 10
        assert pair[f"{method}_root_aligned_mpjpe"] <= pair[f"{method}_mpjpe"] + 50
    mean = out["mean"]["humot_mpjpe"]
    assert abs(mean - (out["biped22->biped17"]["humot_mpjpe"]
                       + out["biped17->biped22"]["humot_mpjpe"]) / 2) < 1e-9


def test_upsampling_curve_counts_removed_joints(humot_small):
    from skelagnostic_humot.evaluate import upsampling_curve

    model = HumotAligner(**humot_small).eval()
    motion = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30)[0]
    chunks = chunks_of(motion)
    out = upsampling_curve(model, chunks, model.topology(motion.skeleton),
                           fractions=(1.0, 0.5, 0.0))
    assert out["removed_joints"] == [0, 11, 20]  # at least two joints are kept
    assert len(out["mpjpe_cm"]) == 3 and all(e > 0 for e in out["mpjpe_cm"])


def test_evaluate_cli_writes_json_and_plots(tmp_path, humot_small):
    from skelagnostic_humot.evaluate import main

    torch.manual_seed(0)
    ckpt = _checkpoint(HumotAligner(**humot_small), tmp_path / "model.ckpt")
    a = sa.procedural.generate("biped31", "walk", seconds=2.0, fps=30, seed=7)[0]
    b = sa.procedural.generate("biped17", "run", seconds=1.5, fps=60, seed=8)[0]
    sa.write_bvh(a, tmp_path / "a.bvh")
    sa.write_bvh(b, tmp_path / "b.bvh")
    out = tmp_path / "eval"
    assert main([str(ckpt), "--group", "b31:cm", str(tmp_path / "a.bvh"),
                 "--group", "b17", str(tmp_path / "b.bvh"),
                 "--cycle-via", str(tmp_path / "b.bvh"), "--out", str(out)]) == 0
    res = json.loads((out / "humot_eval.json").read_text())
    assert set(res["groups"]) == {"b31", "b17"}
    g = res["groups"]["b31"]
    assert g["joints"] == 31 and g["reconstruction"]["chunks"] == 2
    assert g["denoising"]["sigma_cm"][0] == 0.0
    assert len(g["denoising"]["output_mpjpe_cm"]) == len(g["denoising"]["sigma_cm"])
    assert g["upsampling"]["removed_joints"][0] == 0
    assert g["cycle"]["humot_mpjpe"] > 0 and "name_copy_mpjpe_over_height" in g["cycle"]
    assert g["cycle"]["via"] == "b"  # the skeleton of b.bvh
    assert "cycle" not in res["groups"]["b17"]  # no other topology to cycle through
    assert (out / "denoising.png").stat().st_size > 0
    assert (out / "upsampling.png").stat().st_size > 0


def test_evaluate_cli_needs_something_to_evaluate(tmp_path):
    from skelagnostic_humot.evaluate import main

    with pytest.raises(SystemExit):
        main([str(tmp_path / "x.ckpt"), "--out", str(tmp_path)])
