"""The Rich progress bar's epoch line on step-limited and epoch-limited runs."""

from __future__ import annotations

import lightning as L
import pytest

from skelagnostic.callbacks import RichProgress


def _description(**limits: int) -> str:
    bar = RichProgress()
    trainer = L.Trainer(accelerator="cpu", logger=False, callbacks=[bar], **limits)
    bar.setup(trainer, L.LightningModule(), stage="fit")
    return bar._get_train_description(51).strip()


@pytest.mark.parametrize(
    ("limits", "expected"),
    [
        ({"max_epochs": -1, "max_steps": 5000}, "Epoch 51 · max 5000 steps"),
        ({"max_epochs": -1}, "Epoch 51"),
        ({"max_epochs": 100}, "Epoch 51/99"),  # Lightning's own line
    ],
)
def test_epoch_line_has_no_negative_total(limits: dict[str, int], expected: str) -> None:
    assert _description(**limits) == expected


def test_default_callbacks_use_it(example_plugin: object) -> None:
    from hydra.utils import instantiate

    from skelagnostic.cli import app

    cfg = app.compose(["model=example", "run_dir=/tmp/x", "callbacks=default"])
    assert isinstance(instantiate(cfg.callbacks.rich_progress_bar), RichProgress)
