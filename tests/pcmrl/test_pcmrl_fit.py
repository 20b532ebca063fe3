"""``skelagnostic fit model=pcmrl``: a tiny end-to-end run, checkpoint reload, DDP (slow)."""

from __future__ import annotations

import warnings
from pathlib import Path

import torch
from skelagnostic_pcmrl.recon import PcmrlReconstruction

from conftest import TINY
from skelagnostic import procedural
from skelagnostic.cli import app

REPO = Path(__file__).resolve().parents[2]
FAST = ["threads=1", "data.kinds=[biped22]", "data.gaits=[walk]", "data.clips_per_gait=2",
        "data.seconds=1.5", "data.window=12", "data.stride=12", "data.batch_size=2",
        "data.val_fraction=0.5", "trainer.max_epochs=1", "trainer.limit_train_batches=2",
        "trainer.limit_val_batches=1", "trainer.enable_model_summary=false", "logger=csv",
        *(f"model.{k}={v}" for k, v in TINY.items())]


def test_default_config_is_registered(pcmrl_pm, tmp_path) -> None:
    cfg = app.compose(["model=pcmrl", f"run_dir={tmp_path}"], plugin_manager=pcmrl_pm)
    assert cfg.model.name == "pcmrl" and cfg.model.stage == "reconstruction"
    assert cfg.model.num_source_points == 256 and cfg.model.num_target_points == 1024
    assert cfg.model.sigma == 0.05 and cfg.model.knn_k == 8 and cfg.model.lambda_q == 0.01
    assert cfg.model.stages == 4 and cfg.model.temporal_layers == 6
    assert cfg.model.temporal_heads == 4
    assert cfg.data.source == "procedural" and list(cfg.data.kinds) == ["biped22"]
    assert cfg.data.target == "biped31"
    paper = app.compose(["model=pcmrl", "experiment=pcmrl_paper", f"run_dir={tmp_path}"],
                        plugin_manager=pcmrl_pm)
    assert paper.model.dim == 64 and paper.model.temporal_dim is None
    # data=... keeps the target skeleton option of the aligner
    bvh = app.compose(["model=pcmrl", "data=bvh", "data.paths=[x]", f"run_dir={tmp_path}"],
                      plugin_manager=pcmrl_pm)
    assert bvh.data.target == "biped31" and bvh.data.source == "bvh"


def test_tiny_fit_writes_a_checkpoint_that_reloads(pcmrl_pm, tmp_path) -> None:
    cfg = app.compose(["model=pcmrl", f"run_dir={tmp_path}",
                       f"data.cache_dir={tmp_path / 'cache'}", *FAST], plugin_manager=pcmrl_pm)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        metrics = app.run(cfg, plugin_manager=pcmrl_pm)
    assert {"train/loss", "val/loss", "val/knn"} <= set(metrics)
    assert all(torch.isfinite(torch.tensor(v)) for v in metrics.values())
    ckpt = tmp_path / "checkpoints" / "last.ckpt"
    assert ckpt.is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = PcmrlReconstruction.load_from_checkpoint(ckpt, map_location="cpu").eval()
    assert model.target_skeleton.joint_names == procedural.skeleton("biped31").joint_names
    assert model.target_units == "cm" and model.window == 12
    source = procedural.generate("biped22", "walk", seconds=1.0, seed=5)[0]
    result = model.retarget(source, procedural.skeleton("biped31"))
    assert result.num_frames == source.num_frames and torch.isfinite(result.rotations).all()
    # the reloaded weights are the trained ones
    state = torch.load(ckpt, map_location="cpu", weights_only=False)["state_dict"]
    assert torch.equal(state["temporal.proj.weight"], model.temporal.proj.weight)


# The 2-process DDP fit (rank-zero writes, identical weights on both ranks) is
# tests/reliability/test_ddp_methods.py::test_fit_ddp_two_cpu_processes[pcmrl].
