"""``skelagnostic fit model=pcmrl``: a tiny end-to-end run, checkpoint reload, DDP (slow)."""

from __future__ import annotations

import warnings
from pathlib import Path

import torch
from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner

from skelagnostic import procedural
from skelagnostic.cli import app

REPO = Path(__file__).resolve().parents[2]
FAST = [
    "threads=1",
    "data.kinds=[biped22]",
    "data.gaits=[walk]",
    "data.clips_per_gait=2",
    "data.seconds=1.5",
    "data.window=12",
    "data.stride=12",
    "data.batch_size=2",
    "data.val_fraction=0.5",
    "trainer.max_epochs=1",
    "trainer.limit_train_batches=2",
    "trainer.limit_val_batches=1",
    "trainer.enable_model_summary=false",
    "logger=csv",
]


def test_default_config_is_registered(pcmrl_pm, tmp_path) -> None:
    cfg = app.compose(["model=pcmrl", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm)
    assert cfg.model.name == "pcmrl" and cfg.model.stage == "reconstruction"
    assert cfg.model.num_source_points == 256 and cfg.model.num_target_points == 1024
    assert cfg.model.sigma == 0.05 and cfg.model.knn_k == 8 and cfg.model.lambda_q == 0.01
    assert cfg.model.stages == 4 and cfg.model.temporal_layers == 6
    assert cfg.model.temporal_heads == 4
    assert cfg.data.source == "procedural" and list(cfg.data.kinds) == ["biped22"]
    assert cfg.data.target == "biped31"
    # the defaults are the paper's sizes; experiment=pcmrl_cpu is the CPU-sized network
    assert cfg.model.dim == 64 and cfg.model.temporal_dim is None and cfg.model.optimizer.lr == 1e-4
    paper = app.compose(
        ["model=pcmrl", "experiment=pcmrl_paper", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm
    )
    assert paper.model.dim == 64 and paper.model.temporal_dim is None
    cpu = app.compose(["experiment=pcmrl_cpu", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm)
    assert cpu.model.name == "pcmrl" and cpu.model.dim == 16 and cpu.model.temporal_dim == 128
    # data=... keeps the target skeleton option of the aligner
    bvh = app.compose(
        ["model=pcmrl", "data=bvh", "data.paths=[x]", f"run_dir={tmp_path}"],
        plugin_manager=pcmrl_pm,
    )
    assert bvh.data.target == "biped31" and bvh.data.source == "bvh"


def test_tiny_fit_writes_a_checkpoint_that_reloads(pcmrl_pm, pcmrl_tiny, tmp_path) -> None:
    tiny = [f"model.{k}={v}" for k, v in pcmrl_tiny.items()]
    cfg = app.compose(
        [
            "model=pcmrl",
            f"run_dir={tmp_path}",
            f"data.cache_dir={tmp_path / 'cache'}",
            *FAST,
            *tiny,
        ],
        plugin_manager=pcmrl_pm,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics = app.run(cfg, plugin_manager=pcmrl_pm)
    assert {"train/loss", "val/loss", "val/knn"} <= set(metrics)
    assert all(torch.isfinite(torch.tensor(v)) for v in metrics.values())
    ckpt = tmp_path / "checkpoints" / "last.ckpt"
    assert ckpt.is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = PcmrlReconAligner.load_from_checkpoint(ckpt, map_location="cpu").eval()
    assert model.target_skeleton.joint_names == procedural.skeleton("biped31").joint_names
    assert model.target_units == "cm" and model.window == 12
    source = procedural.generate("biped22", "walk", seconds=1.0, seed=5)[0]
    result = model.retarget(source, procedural.skeleton("biped31"))
    assert result.num_frames == source.num_frames and torch.isfinite(result.rotations).all()
    # the reloaded weights are the trained ones
    state = torch.load(ckpt, map_location="cpu", weights_only=False)["state_dict"]
    assert torch.equal(state["temporal.proj.weight"], model.temporal.proj.weight)


def test_tiny_fit_with_the_authors_knn_loss(pcmrl_pm, pcmrl_tiny, tmp_path) -> None:
    """knn_variant=authors trains (alpha ramp on) and logs a finite KNN loss."""
    tiny = [f"model.{k}={v}" for k, v in pcmrl_tiny.items()]
    cfg = app.compose(
        [
            "model=pcmrl",
            f"run_dir={tmp_path}",
            "model.knn_variant=authors",
            "model.knn_alpha_warmup=4",
            f"data.cache_dir={tmp_path / 'cache'}",
            *FAST,
            *tiny,
        ],
        plugin_manager=pcmrl_pm,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics = app.run(cfg, plugin_manager=pcmrl_pm)
    assert {"train/loss", "val/knn"} <= set(metrics)
    assert all(torch.isfinite(torch.tensor(v)) for v in metrics.values())
    assert metrics["val/knn"] > 0


# The 2-process DDP fit (rank-zero writes, identical weights on both ranks) is
# tests/reliability/test_ddp_methods.py::test_fit_ddp_two_cpu_processes[pcmrl].


def test_stage1_output_preset_trains_with_averaged_weights(pcmrl_pm, tmp_path) -> None:
    """experiment=pcmrl_interp_stage1 on BVH files: its options arrive, checkpoints hold the EMA."""
    import pytest
    from omegaconf.errors import MissingMandatoryValue

    from skelagnostic import write_bvh

    clips = tmp_path / "stage1_out"
    clips.mkdir()
    for seed in (1, 2):
        motion, _ = procedural.generate("biped31", "walk", seconds=5.0, fps=30.0, seed=seed)
        write_bvh(motion, clips / f"walk{seed}.bvh")
    preset = ["model=pcmrl_interp", "experiment=pcmrl_interp_stage1", f"run_dir={tmp_path / 'run'}"]
    cfg = app.compose(preset, plugin_manager=pcmrl_pm)
    with pytest.raises(MissingMandatoryValue):
        _ = cfg.data.paths  # the user names the stage-1 output
    cfg = app.compose(
        [
            *preset,
            f"data.paths=[{clips}]",
            "data.units=cm",
            "threads=1",
            "model.dim=16",
            "model.heads=2",
            "model.layers=1",
            "data.samples_per_epoch=16",
            "trainer.max_steps=4",
        ],
        plugin_manager=pcmrl_pm,
    )
    assert cfg.model.interm_tokens == "lerp" and cfg.model.canonical_heading
    assert cfg.data.key_mode == "regular" and cfg.data.rpa_prob == 0 and not cfg.data.mirror
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        app.run(cfg, plugin_manager=pcmrl_pm)
    ckpt = torch.load(tmp_path / "run" / "checkpoints" / "last.ckpt", weights_only=False)
    assert ckpt["global_step"] == 4
    raw, averaged = ckpt["current_model_state"], ckpt["state_dict"]
    assert "net.head.weight" in averaged
    assert not torch.equal(raw["net.head.weight"], averaged["net.head.weight"])
