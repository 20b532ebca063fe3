"""A run that ends on a limit says which one (issue 48, item 4).

``fit model=humot trainer.max_steps=20`` used to stop after 4 steps on the model's
hidden ``max_time`` without a word. :func:`stop_reason` names the limit; ``skelagnostic
fit`` prints it in the summary table (``stopped``) and in ``summary.md``.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import EarlyStopping
from lightning.pytorch.demos.boring_classes import BoringModel
from lightning.pytorch.trainer.states import TrainerStatus

from skelagnostic import cli
from skelagnostic.aligners import quiet_trainer
from skelagnostic.callbacks import StopReason, stop_reason


class _Flat(BoringModel):
    """A model whose validation loss never improves (early stopping's case)."""

    def validation_step(self, batch: torch.Tensor, batch_idx: int) -> dict[str, torch.Tensor]:
        loss = torch.tensor(1.0)
        self.log("val_loss", loss, batch_size=1)
        return {"x": loss}


def _fit(model: BoringModel | None = None, **options: object) -> tuple[L.Trainer, StopReason]:
    recorder = StopReason()
    callbacks = [recorder, *options.pop("callbacks", [])]  # type: ignore[misc]
    trainer = quiet_trainer(
        accelerator="cpu",
        limit_train_batches=4,
        limit_val_batches=1,
        callbacks=callbacks,
        **options,
    )
    trainer.fit(model or BoringModel())
    return trainer, recorder


def test_max_steps_reached() -> None:
    trainer, recorder = _fit(max_steps=6, max_epochs=-1)
    assert stop_reason(trainer) == recorder.reason == "max_steps 6 reached"


def test_max_epochs_reached_says_at_which_step() -> None:
    _, recorder = _fit(max_epochs=2)
    assert recorder.reason == "max_epochs 2 reached at step 8"


def test_max_time_reached_says_the_budget_and_the_step_of_max_steps() -> None:
    # a zero budget is spent before the first step, whatever the machine's speed
    _, recorder = _fit(max_steps=20, max_epochs=-1, max_time=datetime.timedelta(0))
    assert recorder.reason == "max_time 0:00:00 reached at step 0 of 20"
    _, recorder = _fit(max_epochs=10, max_time={"seconds": 0})
    assert recorder.reason == "max_time 0:00:00 reached at step 0 (epoch 1 of 10)"


def test_early_stopping_says_why() -> None:
    stopper = EarlyStopping(monitor="val_loss", patience=1)
    trainer, recorder = _fit(_Flat(), max_epochs=10, callbacks=[stopper])
    assert trainer.current_epoch < 10
    assert recorder.reason is not None and recorder.reason.startswith("early stopping (")
    assert "val_loss did not improve" in recorder.reason and "of 10" in recorder.reason


def test_an_interruption_is_recorded(capfd: pytest.CaptureFixture[str]) -> None:
    # Lightning's Ctrl-C path (it then exits the process): the status, then on_exception
    trainer = quiet_trainer(max_steps=20, max_epochs=-1)
    trainer.state.status = TrainerStatus.INTERRUPTED
    assert stop_reason(trainer) == "interrupted at step 0 of 20"
    recorder = StopReason()
    recorder.on_exception(trainer, BoringModel(), KeyboardInterrupt())
    assert recorder.reason == "interrupted (Ctrl-C) at step 0 of 20"
    recorder.on_exception(trainer, BoringModel(), ValueError("not an interruption"))
    assert recorder.reason == "interrupted (Ctrl-C) at step 0 of 20"


FIT = [
    "model=example",
    "experiment=smoke",
    "model.hidden=8",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "threads=1",
    "~callbacks.rich_progress_bar",
]


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["trainer.max_steps=3"], "max_steps 3 reached"),
        (["trainer.max_steps=20", "trainer.max_time=00:00:00:00"], "max_time 0:00:00 reached"),
    ],
)
def test_fit_names_the_limit_in_the_table_and_in_summary_md(
    extra: list[str],
    expected: str,
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    assert cli.main(["fit", *FIT, *extra]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    (row,) = [line for line in out.splitlines() if line.startswith("│ stopped ")]
    assert expected in row
    (run,) = (tmp_path / "runs" / "example" / "fit").iterdir()
    assert f"stopped: {expected}" in (run / "summary.md").read_text()
    # Hydra's job log gets the run's log lines too (it stayed empty: issue 48, item 7)
    log = (run / "app.log").read_text()
    for line in ("Seed set to 42", "data: dataset 'procedural/", f"stopped: {expected}"):
        assert line in log, log
    assert "final metrics: " in log
