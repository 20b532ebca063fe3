"""A diverged fit stops at its first non-finite loss (issue 47, item 2).

The run exits non-zero with one line naming the step, the loss term and the last
checkpoint; every checkpoint it leaves holds finite weights, and ``best.ckpt`` is
never chosen on a non-finite ``val/loss``.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import ModelCheckpoint
from reliability_env import EVERY_STEP, SMALL
from torch.utils.data import DataLoader

from skelagnostic.callbacks import NonFiniteTrainingError, StopOnNonFinite
from skelagnostic.core.finite import first_non_finite


def fit(env: dict[str, str], cwd: Path, run_dir: Path, *extra: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "skelagnostic.cli", "fit", *SMALL, f"hydra.run.dir={run_dir}"]
    return subprocess.run(
        [*cmd, *extra], env=env, cwd=cwd, capture_output=True, text=True, timeout=300
    )


def error_lines(stderr: str) -> list[str]:
    assert "Traceback" not in stderr, stderr[-3000:]
    return [line for line in stderr.splitlines() if line.startswith("skelagnostic fit: ")]


def assert_finite_checkpoints(run_dir: Path) -> list[Path]:
    """Every checkpoint of the run loads and holds finite weights; returns them."""
    found = sorted((run_dir / "checkpoints").glob("*.ckpt")) if run_dir.exists() else []
    for path in found:
        state = torch.load(path, map_location="cpu", weights_only=True)["state_dict"]
        assert first_non_finite(state.items()) is None, path
    return found


@pytest.mark.slow
def test_a_learning_rate_that_diverges_stops_the_fit(
    cli_env: dict[str, str], tmp_path: Path
) -> None:
    """The issue's case: model.optimizer.lr=1e9 used to log NaN every epoch and exit 0."""
    run_dir = tmp_path / "run"
    proc = fit(cli_env, tmp_path, run_dir, "model.optimizer.lr=1e9", "trainer.max_epochs=3")
    assert proc.returncode == 1, proc.stderr[-3000:]
    lines = error_lines(proc.stderr)
    assert len(lines) == 1, proc.stderr[-3000:]
    assert re.fullmatch(
        r"skelagnostic fit: error: training diverged: (train|val)/loss=(nan|inf|-inf) at step "
        r"\d+ \(epoch \d+\); the run is stopped and .*",
        lines[0],
    ), lines[0]
    assert_finite_checkpoints(run_dir)  # no best.ckpt chosen on a NaN/inf val/loss
    assert "Trainer.fit` stopped: `max_epochs=3` reached" not in proc.stderr + proc.stdout


@pytest.mark.slow
def test_the_first_nan_loss_stops_the_run_and_names_the_last_finite_checkpoint(
    cli_env: dict[str, str], tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    proc = fit(
        cli_env,
        tmp_path,
        run_dir,
        "trainer.max_steps=6",
        *EVERY_STEP,
        "+callbacks.poison._target_=killer.PoisonAt",
        "+callbacks.poison.step=3",
    )
    assert proc.returncode == 1, proc.stderr[-3000:]
    last = run_dir / "checkpoints" / "last.ckpt"
    assert error_lines(proc.stderr) == [
        "skelagnostic fit: error: training diverged: train/loss=nan at step 3 (epoch 0); the "
        f"run is stopped and the last checkpoint, with finite weights, is {last} (lower the "
        "learning rate, or look for NaN/inf in the data) "
        f"[run directory kept: {run_dir}; resume with ckpt_path={last}]"
    ]
    assert assert_finite_checkpoints(run_dir) == [last]
    assert torch.load(last, map_location="cpu", weights_only=True)["global_step"] == 3
    metrics = (run_dir / "csv" / "metrics.csv").read_text()
    assert "nan" not in metrics.lower()  # the NaN step was stopped before it was logged


class Terms(L.LightningModule):
    """A toy module that logs two loss terms; ``bad`` picks what goes non-finite at step 2."""

    def __init__(self, bad: str) -> None:
        super().__init__()
        self.w = torch.nn.Parameter(torch.ones(3))
        self.bad = bad
        if bad == "gradient":  # a finite loss whose gradient is infinite
            self.w.register_hook(lambda g: g * float("inf") if self.global_step == 2 else g)

    def training_step(self, batch: torch.Tensor, batch_idx: int) -> torch.Tensor:
        rec = ((batch - self.w) ** 2).mean()
        kl = self.w.abs().mean()
        if self.bad == "term" and self.global_step == 2:
            kl = kl * float("nan")
        self.log_dict({"train/rec": rec, "train/kl": kl}, batch_size=len(batch))
        loss = rec + kl
        self.log("train/loss", loss, batch_size=len(batch))
        return loss

    def validation_step(self, batch: torch.Tensor, batch_idx: int) -> None:
        value = ((batch - self.w) ** 2).mean()
        if self.bad == "val":
            value = value * float("inf")
        self.log("val/loss", value, batch_size=len(batch))

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.SGD(self.parameters(), lr=0.01)


def train(tmp_path: Path, bad: str) -> NonFiniteTrainingError:
    data = DataLoader(torch.randn(16, 3), batch_size=4)
    trainer = L.Trainer(
        max_steps=5,
        callbacks=[
            StopOnNonFinite(),
            ModelCheckpoint(dirpath=tmp_path, filename="best", monitor="val/loss", save_last=True),
        ],
        default_root_dir=tmp_path,
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
        limit_val_batches=1,
    )
    with pytest.raises(NonFiniteTrainingError) as caught:
        trainer.fit(Terms(bad), train_dataloaders=data, val_dataloaders=data)
    return caught.value


def test_the_message_names_the_non_finite_loss_terms(tmp_path: Path) -> None:
    error = train(tmp_path, "term")
    assert error.step == 2
    assert error.what == "train/kl=nan, train/loss=nan"
    assert str(error).startswith("training diverged: train/kl=nan, train/loss=nan at step 2 (")


def test_an_infinite_gradient_stops_before_the_optimizer_step(tmp_path: Path) -> None:
    error = train(tmp_path, "gradient")
    assert error.step == 2
    assert error.what == "the gradient norm is inf (first non-finite gradient: w)"


def test_no_best_checkpoint_is_chosen_on_a_non_finite_val_loss(tmp_path: Path) -> None:
    error = train(tmp_path, "val")
    assert error.what == "val/loss=inf"
    assert error.checkpoint is None
    assert not list(tmp_path.glob("*.ckpt"))
