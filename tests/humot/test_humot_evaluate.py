import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluate import chunks_of, reconstruction

import skelagnostic as sa
from conftest import SMALL


def test_reconstruction_baselines_on_a_rigidly_translated_pose():
    """A frozen pose sliding at constant speed: only the trajectory baseline is exact."""
    motion = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30)[0]
    pose = motion.global_positions().float()[:1] / 100  # [1, J, 3] metres
    shift = torch.zeros(30, 1, 3)
    shift[:, 0, 2] = torch.linspace(0, 0.9, 30)  # 0.9 m forward along Z (the skeleton's facing)
    chunks = (pose + shift)[None]
    model = HumotAligner(**SMALL).eval()
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
