import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluation.reconstruction import chunks_of, reconstruction

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
def test_motion_error_of_a_translation():
    from skelagnostic_humot.evaluation.retarget import _motion_error

    truth = sa.procedural.generate("biped17", "run", seconds=1.0, fps=30)[0]
    shifted = sa.Motion(
        truth.skeleton,
        truth.rotations,
        truth.root_positions + torch.tensor([3.0, 0.0, 4.0], dtype=torch.float64),
        truth.fps,
    )
    err = _motion_error(shifted, truth)
    assert abs(err["mpjpe"] - 5.0) < 1e-6
    assert abs(err["mpjpe_over_height"] - 5.0 / truth.skeleton.height()) < 1e-9
    assert err["root_aligned_mpjpe"] < 1e-6


def test_retargeting_procedural_uses_paired_ground_truth(humot_small):
    from skelagnostic_humot.evaluation.retarget import retargeting_procedural

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    out = retargeting_procedural(
        model, kinds=("biped22", "biped17"), gaits=("walk",), clips_per_gait=1, seconds=1.0
    )
    assert set(out) == {"biped22->biped17", "biped17->biped22", "mean"}
    pair = out["biped22->biped17"]
    assert pair["clips"] == 1
    for method in ("humot", "name_copy", "primal_copy", "direction_copy"):
        assert 0 < pair[f"{method}_mpjpe_over_height"] < 10
        assert pair[f"{method}_root_aligned_mpjpe"] <= pair[f"{method}_mpjpe"] + 50
    mean = out["mean"]["humot_mpjpe"]
    assert (
        abs(
            mean
            - (out["biped22->biped17"]["humot_mpjpe"] + out["biped17->biped22"]["humot_mpjpe"]) / 2
        )
        < 1e-9
    )


def test_upsampling_curve_counts_removed_joints(humot_small):
    from skelagnostic_humot.evaluation.reconstruction import upsampling_curve

    model = HumotAligner(**humot_small).eval()
    motion = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30)[0]
    chunks = chunks_of(motion)
    out = upsampling_curve(
        model, chunks, model.topology(motion.skeleton), fractions=(1.0, 0.5, 0.0)
    )
    assert out["removed_joints"] == [0, 11, 20]  # at least two joints are kept
    assert len(out["mpjpe_cm"]) == 3 and all(e > 0 for e in out["mpjpe_cm"])


def _held(*clips):
    from skelagnostic.evaluation import HeldOut

    return HeldOut("test", list(clips))


def test_reconstruction_protocol_rows_curves_and_plots(tmp_path, humot_small):
    from skelagnostic_humot.evaluation.reconstruction import reconstruction_protocol

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    a = sa.procedural.generate("biped31", "walk", seconds=2.0, fps=30, seed=7)[0]
    b = sa.procedural.generate("biped17", "run", seconds=1.5, fps=60, seed=8)[0]
    dog = sa.procedural.generate("quadruped", "trot", seconds=2.0, fps=30)[0]
    a.name, b.name, dog.name = "a", "b", "dog"
    with torch.no_grad():
        out = reconstruction_protocol(model, _held(a, b, dog), tmp_path)
    assert [r["clip"] for r in out.rows] == ["a", "b"]
    assert out.rows[0]["chunks"] == 2
    assert set(out.rows[0]["values"]) == {
        "model",
        "mean_pose",
        "template",
        "mean_pose_on_trajectory",
        "ground_truth",  # its own foot skate: a reference
    }
    assert any("dog" in n for n in out.notes)
    assert set(out.extra["curves"]) == {"biped31", "biped17"}
    assert out.plots == ["denoising.png", "upsampling.png"]
    assert (tmp_path / "denoising.png").stat().st_size > 0


def test_retarget_protocol_cycles_through_another_topology(tmp_path, humot_small):
    from skelagnostic_humot.evaluation.retarget import retarget_protocol

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    clip = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=3)[0]
    clip.name = "c"
    with torch.no_grad():
        out = retarget_protocol(model, _held(clip), tmp_path)
    (row,) = out.rows
    assert row["via"] == "biped31"  # the first human kind of another topology
    methods = {"model", "name_copy", "primal_copy", "direction_copy", "ground_truth"}
    assert set(row["values"]) == methods
    assert all(v["cycle_over_height"] >= 0 for m, v in row["values"].items() if m != "ground_truth")
    mean = out.extra["procedural_paired_retargeting"]["mean"]
    by_method = out.extra["procedural_paired_mean"]
    assert set(by_method) == {"model", "name_copy", "primal_copy", "direction_copy"}
    for method, prefix in (("model", "humot"), ("name_copy", "name_copy")):
        for metric in ("mpjpe", "mpjpe_over_height", "root_aligned_mpjpe"):
            assert by_method[method][metric] == mean[f"{prefix}_{metric}"]
    assert len(by_method["primal_copy"]) == 4


# --------------------------------------------------------------- seen / unseen topology
class _RunData:
    """The parts of a set-up data module the protocols read: training skeletons, splits."""

    def __init__(self, skeletons, assigned=None):
        self.skeletons = skeletons
        self.assigned_splits = assigned or {}


def test_topology_status_compares_hierarchies_not_names():
    from skelagnostic_humot.evaluation.held_out import topology_status, trained_hierarchies

    from skelagnostic.evaluation import HeldOut

    b22, b31, b17 = (sa.procedural.skeleton(k) for k in ("biped22", "biped31", "biped17"))
    renamed = b31.subset(b31.joint_names)  # same hierarchy
    renamed = sa.Skeleton(
        [f"j{i}" for i in range(renamed.num_joints)], renamed.parents, renamed.offsets
    )
    trained = trained_hierarchies(HeldOut("test", [], _RunData({"a": b22, "b": b31})))
    assert trained == {tuple(b22.parents), tuple(b31.parents)}
    assert topology_status(renamed, trained) == "seen"
    assert topology_status(b17, trained) == "unseen"
    assert topology_status(b17, trained_hierarchies(HeldOut("test", []))) == "unknown"


def test_reconstruction_protocol_groups_extra_clips_by_topology(tmp_path, humot_small):
    from skelagnostic_humot.evaluation.reconstruction import reconstruction_protocol

    from skelagnostic.evaluation import HeldOut

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    seen = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=5)[0]
    seen.name = "seen"
    other = sa.procedural.generate("biped17", "run", seconds=1.0, fps=30, seed=6)[0]
    folder = tmp_path / "extra"
    folder.mkdir()
    sa.write_bvh(other, folder / "other.bvh")
    held = HeldOut("test", [seen], _RunData({"train": seen.skeleton}))
    with torch.no_grad():
        out = reconstruction_protocol(model, held, tmp_path, extra=[str(folder)], extra_units="cm")
        # the extra clip's row, recomputed from the file independently
        direct = reconstruction(
            model,
            chunks_of(sa.read_bvh(folder / "other.bvh"), 30, "cm"),
            model.topology(other.skeleton),
            "y",
        )
    rows = {r["clip"]: r for r in out.rows}
    extra_row = rows[str(folder / "other.bvh")]
    assert rows["seen"]["topology"] == "seen" and extra_row["topology"] == "unseen"
    assert abs(extra_row["values"]["model"]["mpjpe_cm"] - direct["mpjpe_cm"]) < 1e-4
    assert abs(extra_row["values"]["mean_pose"]["mpjpe_cm"] - direct["mean_pose_cm"]) < 1e-4
    groups = out.extra["by_topology"]
    assert groups["seen"]["model"]["mpjpe_cm"] == rows["seen"]["values"]["model"]["mpjpe_cm"]
    assert groups["unseen"]["mean_pose"]["mpjpe_cm"] == direct["mean_pose_cm"]
    assert set(out.extra["curves"]) == {"biped22 (seen)", "other (unseen)"}  # skeleton names


def test_extra_clips_refuse_training_clips_and_missing_paths(tmp_path):
    import pytest
    from skelagnostic_humot.evaluation.held_out import extra_clips

    from skelagnostic.evaluation import EvaluationError, HeldOut

    clip = sa.procedural.generate("biped17", "walk", seconds=1.0, fps=30)[0]
    path = tmp_path / "a.bvh"
    sa.write_bvh(clip, path)
    held = HeldOut("test", [], _RunData({}, {f"corpus:{path}": "train"}))
    with pytest.raises(EvaluationError, match="training clip"):
        extra_clips([str(tmp_path)], "cm", held)
    with pytest.raises(EvaluationError, match="does not exist"):
        extra_clips(str(tmp_path / "nowhere"))
    (loaded,) = extra_clips(str(path), "cm")
    assert loaded.units == "m" and loaded.name == str(path)
    assert torch.allclose(loaded.global_positions(), clip.global_positions() / 100, atol=1e-4)


def test_retarget_protocol_labels_procedural_topologies(tmp_path, humot_small):
    from skelagnostic_humot.evaluation.retarget import retarget_protocol

    from skelagnostic.evaluation import HeldOut

    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    clip = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30, seed=3)[0]
    clip.name = "c"
    held = HeldOut("test", [clip], _RunData({"p": clip.skeleton}))
    with torch.no_grad():
        out = retarget_protocol(model, held, tmp_path, paired_seconds=1.0)
    assert out.extra["procedural_topologies"] == {
        "biped22": "seen",
        "biped31": "unseen",
        "biped17": "unseen",
    }
    assert out.rows[0]["topology"] == "seen"
    paired = out.extra["procedural_paired_retargeting"]
    assert paired["biped22->biped17"]["clips"] == 2  # walk and run, one clip each
