"""One character (one skeleton topology): VQ-PAE trains; manifold overlap is not applicable."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest


@pytest.mark.data
def test_fit_on_one_bvh_character_reports_overlap_not_applicable(
    vqpae_pm, tmp_path: Path, cache_dir: Path, shared_data: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from skelagnostic.cli.app import compose, run

    clips = shared_data / "human" / "lafan1"
    paths = [str(clips / "walk4_subject1.bvh"), str(clips / "obstacles1_subject5.bvh")]
    run_dir = tmp_path / "run"
    cfg = compose(
        [
            "model=vqpae",
            "data=bvh",
            f"data.paths=[{','.join(paths)}]",
            "data.units=cm",
            "data.fps=20",
            "data.stride=8",
            f"run_dir={run_dir}",
            "experiment=smoke",
            "callbacks=default",
            "logger=none",
            "model.num_codes=8",
            "model.kernel_size=7",
            f"data.cache_dir={cache_dir}",
            "trainer.max_epochs=1",
            "trainer.limit_train_batches=3",
        ],
        plugin_manager=vqpae_pm,
    )
    with caplog.at_level(logging.INFO, logger="skelagnostic_vqpae"):
        metrics = run(cfg, vqpae_pm)
    assert "train/loss" in metrics and "val/loss" in metrics
    # a shared-code share needs two characters: no number is logged for it
    assert not any(k.startswith("val/overlap") for k in metrics)
    assert metrics["val/codes/bvh"] >= 1
    assert "val/overlap: not applicable (one dataset)" in caplog.text
    written = json.loads((run_dir / "vqpae_metrics.json").read_text())
    assert written["overlap"] is None and written["per_dataset"] == {"bvh": None}
    assert written["usage"] > 0
