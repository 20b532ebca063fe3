"""``model=humot`` without ``data=``: the registered default data and data-module keys."""

import pytest

from skelagnostic.cli.app import compose, run


def test_default_data_is_procedural_humans_of_three_topologies(humot_pm, tmp_path):
    cfg = compose(["model=humot", f"run_dir={tmp_path}"], plugin_manager=humot_pm)
    assert cfg.data.source == "procedural"
    assert list(cfg.data.kinds) == ["biped22", "biped31", "biped17"]
    # the paper's preprocessing (Sec. 3.4.1) and batch size (App. A.5)
    assert (cfg.data.fps, cfg.data.window, cfg.data.stride) == (30, 30, 6)
    assert cfg.data.batch_size == 32
    # the paper's network
    assert (cfg.model.dim, cfg.model.blocks, cfg.model.scheduler.max_lr) == (128, 4, 1e-4)
    # no trainer limit from the model (issue 48, item 4): trainer=default's, experiments' own
    assert cfg.trainer.max_time is None and cfg.trainer.max_epochs == 10


def test_other_data_keeps_the_paper_chunking(humot_pm, tmp_path):
    cfg = compose(
        ["model=humot", "data=bvh", "data.paths=[x]", f"run_dir={tmp_path}"],
        plugin_manager=humot_pm,
    )
    assert cfg.data.source == "bvh" and "kinds" not in cfg.data
    assert (cfg.data.window, cfg.data.stride, cfg.data.fps) == (30, 6, 30)
    cfg = compose(["model=humot", "data.window=60", f"run_dir={tmp_path}"], plugin_manager=humot_pm)
    assert cfg.data.window == 60  # the command line still wins


@pytest.mark.slow
def test_fit_on_the_default_data_writes_checkpoint_metrics_and_render(humot_pm, tmp_path):
    cfg = compose(
        [
            "model=humot",
            f"run_dir={tmp_path}",
            f"data.cache_dir={tmp_path / 'c'}",
            "model.dim=32",
            "model.latent=16",
            "model.blocks=1",
            "model.heads=4",
            "trainer.max_epochs=1",
            "data.seconds=1.5",
            "callbacks=render",
            "threads=1",
        ],
        plugin_manager=humot_pm,
    )
    metrics = run(cfg, humot_pm)
    assert {"val/loss", "val/mpjpe_cm", "train/loss"} <= set(metrics)
    assert (tmp_path / "checkpoints" / "last.ckpt").exists()
    assert (tmp_path / "humot_metrics.json").exists()
    assert (tmp_path / "humot_retarget.gif").exists()
    assert (tmp_path / "humot_retarget.png").exists()
    assert list((tmp_path / "renders").glob("*.gif"))
