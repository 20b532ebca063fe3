"""After training: npz embeddings, average-pose fitting, retrieval, plots and transfer."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch
from skelagnostic_vqpae.embed import (
    ClipEmbedding,
    ellipse_points,
    embed_clip,
    fit_average_pose,
    plot_clip_timing,
    plot_manifold,
    retrieve,
)
from skelagnostic_vqpae.model import phase_manifold
from skelagnostic_vqpae.transfer import build_database, transfer

from skelagnostic import procedural, read_bvh, write_bvh
from skelagnostic.errors import SkelagnosticError

FPS = 20


def test_embedding_round_trips_through_npz(trained: dict, tmp_path: Path) -> None:
    motion, _ = procedural.generate("biped22", "run", seconds=2.0, fps=FPS, seed=4)
    emb = embed_clip(trained["model"], motion)
    assert emb.dataset == "procedural/biped22" and len(emb) == motion.num_frames
    # the manifold point is Psi(A, phi) of the frame's own phase and amplitude
    assert torch.allclose(
        emb.manifold, phase_manifold(emb.amplitude, emb.phase[:, None])[..., 0], atol=1e-5
    )
    back = ClipEmbedding.load(emb.save(tmp_path / "clip.npz"))
    assert back.dataset == emb.dataset and back.fps == emb.fps
    for key in ("phase", "frequency", "code", "amplitude", "manifold"):
        assert torch.equal(getattr(back, key), getattr(emb, key)), key


def test_load_rejects_other_npz(tmp_path: Path) -> None:
    import numpy as np

    np.savez(tmp_path / "x.npz", phase=np.zeros(3))
    with pytest.raises(SkelagnosticError, match="not a VQ-PAE embedding"):
        ClipEmbedding.load(tmp_path / "x.npz")


def test_fit_average_pose_lowers_the_pose_loss(trained: dict) -> None:
    from skelagnostic_vqpae.aligner import VqpaeAligner

    model = VqpaeAligner.load_from_checkpoint(trained["ckpt"])
    for char in model.characters:  # start the pose MLPs over, then fit them post hoc
        for p in char.pose.parameters():
            torch.nn.init.normal_(p, std=0.1)
        char.pose_fitted.fill_(False)
    first = fit_average_pose(model, trained["dm"], epochs=1)
    last = fit_average_pose(model, trained["dm"], epochs=10)
    assert all(last[n] < first[n] for n in first)
    assert all(bool(c.pose_fitted) for c in model.characters)
    with pytest.raises(SkelagnosticError, match="epochs"):
        fit_average_pose(model, trained["dm"], epochs=0)


def test_retrieval_finds_a_planted_cycle() -> None:
    amp = torch.tensor([1.0, 0.0, 0.5, 0.0, 1.0, 0.2])
    f, fps = 2.0, 30.0
    frames = torch.arange(90)
    planted = phase_manifold(amp, frames * f / fps).t()  # phase 0 at frame 0, 30, 60
    other = phase_manifold(amp * 0.3, frames * 1.0 / fps).t()

    def emb(manifold: torch.Tensor) -> ClipEmbedding:
        n = len(manifold)
        return ClipEmbedding(
            torch.zeros(n),
            torch.ones(n),
            torch.zeros(n, dtype=torch.long),
            amp.expand(n, 6),
            manifold,
            fps,
            "x",
        )

    hits = retrieve([emb(other), emb(planted)], amp, f, top=3)
    assert hits[0].clip == 1 and hits[0].length == 15 and hits[0].frame % 15 == 0
    assert hits[0].distance < 1e-8
    with pytest.raises(SkelagnosticError, match="frequency"):
        retrieve([emb(planted)], amp, 0.0)


def test_ellipses_and_plots(trained: dict, tmp_path: Path) -> None:
    model = trained["model"]
    pts = ellipse_points(model.codebook.weight, samples=16)
    assert pts.shape == (8, 16, 10)
    embs = {
        "biped": [
            embed_clip(
                model, procedural.generate("biped22", "walk", seconds=2.0, fps=FPS, seed=1)[0]
            )
        ],
        "quadruped": [
            embed_clip(
                model, procedural.generate("quadruped", "trot", seconds=2.0, fps=FPS, seed=1)[0]
            )
        ],
    }
    plot_manifold(model, embs, out=tmp_path / "manifold.png")
    plot_clip_timing({k: v[0] for k, v in embs.items()}, out=tmp_path / "timing.png")
    assert (tmp_path / "manifold.png").stat().st_size > 0
    assert (tmp_path / "timing.png").stat().st_size > 0


def test_transfer_biped_to_quadruped_writes_a_bvh(trained: dict, tmp_path: Path) -> None:
    model = trained["model"]
    dogs = [
        procedural.generate("quadruped", g, seconds=3.0, fps=FPS, seed=s)[0]
        for g in ("walk", "trot", "gallop")
        for s in (1, 2)
    ]
    db = build_database(model, dogs)
    source, _ = procedural.generate("biped22", "run", seconds=2.5, fps=FPS, seed=7)
    result = transfer(model, source, db)
    out = result.motion
    assert out.skeleton is dogs[0].skeleton
    assert out.num_frames == source.num_frames and out.fps == FPS
    assert bool(torch.isfinite(out.global_positions()).all())
    assert sum(s.out_length for s in result.match.segments) == source.num_frames
    path = tmp_path / "dog.bvh"
    write_bvh(out, path)
    assert read_bvh(path).num_frames == source.num_frames
    with pytest.raises(SkelagnosticError, match="different characters"):
        build_database(model, [dogs[0], source])


def test_aligner_transfer_matches_the_module_function(trained: dict) -> None:
    model = trained["model"]
    assert model.supports("transfer")
    dogs = [
        procedural.generate("quadruped", g, seconds=3.0, fps=FPS, seed=3)[0]
        for g in ("walk", "trot")
    ]
    source, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=FPS, seed=8)
    assert model.last_transitions is None
    out = model.transfer(source, dogs)
    result = transfer(model, source, build_database(model, dogs))
    expected = result.motion
    assert out.skeleton is dogs[0].skeleton and out.num_frames == source.num_frames
    assert torch.equal(out.rotations, expected.rotations)
    # the viewer's timeline marks: output frames where a new matched window starts
    assert model.last_transitions == [s.start for s in result.match.segments[1:]]
    assert all(0 < f < out.num_frames for f in model.last_transitions)
    with pytest.raises(SkelagnosticError, match="empty"):
        model.transfer(source, [])


def test_a_script_loading_the_aligner_by_hand_transfers(trained: dict) -> None:
    """In a fresh interpreter, the aligner's own module is all a script needs.

    No plugin manager, no other import: ``transfer`` and ``fit_summary`` are methods of
    the class, not work a higher floor must first register.
    """
    script = (
        "from skelagnostic import procedural\n"
        "from skelagnostic_vqpae.aligner import VqpaeAligner\n"
        "from skelagnostic_vqpae.training import VqpaeModel\n"
        f"model = VqpaeAligner.load_from_checkpoint({str(trained['ckpt'])!r}).eval()\n"
        "dog = procedural.generate('quadruped', 'trot', seconds=2.0, fps=20, seed=3)[0]\n"
        "human = procedural.generate('biped22', 'walk', seconds=1.0, fps=20, seed=8)[0]\n"
        "out = model.transfer(human, [dog])\n"
        "assert out.skeleton is dog.skeleton and out.num_frames == human.num_frames\n"
        "assert 'fit_summary' in vars(VqpaeAligner) and 'transfer' in vars(VqpaeAligner)\n"
        "assert not VqpaeModel(num_codes=4).supports('transfer')\n"
        "print('ok')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and done.stdout.strip().endswith("ok"), done.stderr[-2000:]


def test_predict_writes_per_clip_embeddings(trained: dict, tmp_path: Path) -> None:
    import lightning as L
    import numpy as np

    model, dm = trained["model"], trained["dm"]
    trainer = L.Trainer(
        accelerator="cpu",
        devices=1,
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        default_root_dir=str(tmp_path),
    )
    batches = trainer.predict(model, datamodule=dm)
    path = tmp_path / "embeddings.npz"
    assert model.predictions_path == path and path.is_file()
    data = np.load(path)
    assert float(data["fps"]) == FPS
    name = dm.dataset_names[0]
    windows = dm.datasets["val"][name]
    clip = dm.clip_ids["val"][name][int(windows.clips[0])]
    frames = data[f"{name}/{clip}/frame"]
    assert (np.diff(frames) > 0).all() and frames[0] == int(windows.pivots[0])
    with torch.no_grad():
        _, params = model.forward_dataset(0, windows[0]["features"][None])
    for key, value in (
        ("phase", params.phase),
        ("frequency", params.frequency),
        ("code", params.code),
    ):
        assert np.allclose(data[f"{name}/{clip}/{key}"][0], value[0].numpy(), atol=1e-5), key
    assert data[f"{name}/{clip}/manifold"].shape[1] == 10
    assert data[f"{name}/{clip}/amplitude"].shape[1] == 20
    flat = [b for group in batches for b in (group if isinstance(group, list) else [group])]
    total = sum(len(b[n]["phase"]) for b in flat for n in b)
    keys = [k for k in data.files if k.endswith("/frame")]
    assert sum(len(data[k]) for k in keys) == total
