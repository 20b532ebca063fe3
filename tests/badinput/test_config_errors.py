"""Configuration errors found while building the Trainer, the loggers and the callbacks.

Each is one line naming the config key at fault (``trainer.devices``,
``logger.csv.save_dir``, ``callbacks.model_checkpoint.monitor`` ...), quoted
in docs/troubleshooting.md, and leaves no run directory behind.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from test_badinput import assert_no_partial_output, documented, error_line, fit


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["trainer.devices=abc"],
            "trainer.devices='abc': TypeError: `devices` selected with "
            "`CPUAccelerator` should be an int > 0.",
        ),
        (
            ["trainer.strategy=nope"],
            "trainer.strategy='nope': ValueError: You selected an invalid "
            "strategy name: `strategy='nope'`.",
        ),
        (
            ["trainer.accelerator=nope"],
            "trainer.accelerator='nope': ValueError: You selected an "
            "invalid accelerator name: `accelerator='nope'`.",
        ),
        (
            ["trainer.accumulate_grad_batches=0"],
            "trainer.accumulate_grad_batches=0 must be a positive integer",
        ),
        (
            ["trainer.check_val_every_n_epoch=0"],
            "trainer.check_val_every_n_epoch=0 must be a positive integer",
        ),
        (
            ["callbacks.model_checkpoint.mode=sideways"],
            "callbacks.model_checkpoint.mode='sideways': `mode` can be min, max but got sideways",
        ),
        (
            ["logger.csv.save_dir={tmp}/file"],
            "logger.csv.save_dir='{tmp}/file': cannot write "
            "there ('{tmp}/file' is not a directory)",
        ),
        (
            ["callbacks.model_checkpoint.dirpath={tmp}/file/checkpoints"],
            "callbacks.model_checkpoint.dirpath='{tmp}/file/checkpoints': cannot write there "
            "('{tmp}/file' is not a directory)",
        ),
        (
            ["data.batch_size=abc"],
            "data.batch_size='abc' has the wrong type for ExampleDataModule (expected int)",
        ),
        (["seed=abc"], "seed must be an integer, got 'abc'"),
        (["seed=-1"], "seed must be from 0 to 4294967295, got -1"),
        (
            ["hydra.run.dir={tmp}/`a`"],
            "hydra.run.dir={tmp}/`a`: Hydra cannot parse this override "
            "(token recognition error at: '`'); quote the value: hydra.run.dir='...'",
        ),
        (
            ["model.hidden=0"],
            "model.hidden=0, model.latent=4: the aligner 'example' refuses it "
            "(ValueError: input_size must be greater than zero)",
        ),
        (
            ["+model.optimizer.lrr=1"],
            "model.optimizer.lrr is not an argument of torch.optim.Adam; accepted: amsgrad, "
            "betas, capturable, decoupled_weight_decay, differentiable, eps, foreach, fused, lr, "
            "maximize, weight_decay",
        ),
        (
            ["model.optimizer._target_=torch.optim.Nope"],
            "model.optimizer._target_='torch.optim.Nope': torch.optim has no 'Nope'",
        ),
        (
            ["model.optimizer.lr=nan"],
            "model.optimizer.lr=nan: the aligner 'example' refuses it "
            "(ValueError: Invalid learning rate: nan)",
        ),
    ],
)
def test_cli_names_the_key(
    site: Path, tmp_path: Path, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "file").write_text("")
    assert fit(tmp_path, *(a.format(tmp=tmp_path) for a in args)) == 1
    err = error_line(capsys)
    expected = f"skelagnostic fit: error: {message.format(tmp=tmp_path)}"
    assert err.startswith(expected)
    assert_no_partial_output(tmp_path)
    documented(expected, tmp_path)


def test_cli_names_the_monitor_that_never_appears(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert fit(tmp_path, "callbacks.model_checkpoint.monitor=val/nope") == 1
    err = error_line(capsys)
    expected = (
        "skelagnostic fit: error: callbacks.model_checkpoint.monitor='val/nope': "
        "`ModelCheckpoint(monitor='val/nope')` could not find the monitored key in the "
        "returned metrics: ['train/loss', 'val/loss', 'epoch', 'step']."
    )
    assert err.startswith(expected)
    documented(expected, tmp_path)
