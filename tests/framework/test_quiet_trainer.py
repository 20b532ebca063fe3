"""skelagnostic.aligners.quiet_trainer: a Lightning trainer that writes and prints nothing."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import pytest
from lightning.pytorch.callbacks import ModelCheckpoint, ModelSummary, ProgressBar
from lightning.pytorch.demos.boring_classes import BoringModel
from lightning.pytorch.loggers import CSVLogger

from skelagnostic.aligners import QUIET_TRAINER_OPTIONS, quiet_trainer


def test_options_are_the_four_quiet_ones_and_read_only() -> None:
    assert dict(QUIET_TRAINER_OPTIONS) == {
        "logger": False,
        "enable_checkpointing": False,
        "enable_progress_bar": False,
        "enable_model_summary": False,
    }
    with pytest.raises(TypeError):
        QUIET_TRAINER_OPTIONS["logger"] = True  # type: ignore[index]


def test_fit_writes_no_file_and_prints_no_bar_or_summary(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    trainer = quiet_trainer(
        max_steps=3, accelerator="cpu", limit_val_batches=1, default_root_dir=tmp_path
    )
    assert isinstance(trainer, L.Trainer)
    assert trainer.logger is None and trainer.checkpoint_callback is None
    assert trainer.progress_bar_callback is None
    assert not any(isinstance(c, ModelSummary | ProgressBar) for c in trainer.callbacks)
    capfd.readouterr()
    trainer.fit(BoringModel())
    assert trainer.global_step == 3  # the overrides apply
    assert capfd.readouterr().out == ""  # neither a progress bar nor the summary table
    assert list(tmp_path.rglob("*")) == []  # no logs, no checkpoints
    trainer.save_checkpoint(tmp_path / "asked.ckpt")  # on request only
    assert [p.name for p in tmp_path.iterdir()] == ["asked.ckpt"]


def test_overrides_win_over_the_quiet_options(tmp_path: Path) -> None:
    logger = CSVLogger(tmp_path)
    trainer = quiet_trainer(logger=logger, enable_checkpointing=True, default_root_dir=tmp_path)
    assert trainer.logger is logger
    assert isinstance(trainer.checkpoint_callback, ModelCheckpoint)
    assert trainer.progress_bar_callback is None  # the others stay quiet
