"""The FitSummary callback (metrics JSON, renders, summary.md) and steps_per_epoch."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, TensorDataset

from skelagnostic.aligners import steps_per_epoch
from skelagnostic.callbacks import FitSummary

FAST = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=16",
    "trainer.max_epochs=1",
    "threads=1",
]


class _Tiny(L.LightningModule):
    """One linear layer; records the mode its ``fit_summary`` ran in."""

    def __init__(self, content: dict[str, Any] | None = None) -> None:
        super().__init__()
        self.layer = torch.nn.Linear(2, 1)
        self.content = content
        self.seen: dict[str, Any] = {}

    def training_step(self, batch: Any, batch_idx: int) -> torch.Tensor:
        loss = self.layer(batch[0]).square().mean()
        self.log("train/loss", loss)
        return loss

    def configure_optimizers(self) -> Any:
        self.seen["steps_per_epoch"] = steps_per_epoch(self.trainer)
        return torch.optim.SGD(self.parameters(), lr=0.1)

    def fit_summary(self, trainer: L.Trainer) -> dict[str, Any]:
        self.seen.update(training=self.training, grad=torch.is_grad_enabled())
        return self.content or {}


def _fit(module: L.LightningModule, root: Path, batches: int = 6, **trainer: Any) -> L.Trainer:
    data = DataLoader(TensorDataset(torch.randn(batches * 2, 2)), batch_size=2)
    options = {
        "max_epochs": 1,
        "accelerator": "cpu",
        "logger": False,
        "enable_checkpointing": False,
        "enable_progress_bar": False,
        "enable_model_summary": False,
        "default_root_dir": str(root),
        **trainer,
    }
    fitted = L.Trainer(**options)
    fitted.fit(module, data)
    return fitted


def test_fit_summary_writes_metrics_renders_figures_and_markdown(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    from skelagnostic.viz import StickFigure

    stick = StickFigure(np.array([[[0.0, 0, 0], [0, 1, 0]]] * 3), parents=[-1, 0])
    figure = plt.figure()
    content = {
        "metrics": {"usage": torch.tensor(0.25), "per": {"a": None}},
        "renders": {"pose": [stick]},
        "figures": {"curve": figure},
        "notes": ["A note from the aligner."],
        "headline": ["**The finding** of the run."],
    }
    module = _Tiny(content)
    callback = FitSummary(name="tiny", size=(40, 40), sheet_frames=2)
    _fit(module, tmp_path, callbacks=[callback])
    assert module.seen["training"] is False and module.seen["grad"] is False
    metrics = json.loads((tmp_path / "tiny_metrics.json").read_text())
    assert metrics["usage"] == 0.25 and metrics["per"] == {"a": None}
    assert isinstance(metrics["train/loss"], float)
    for name in ("tiny_pose.gif", "tiny_pose.png", "tiny_curve.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert not plt.fignum_exists(figure.number)  # saved and closed
    summary = (tmp_path / "summary.md").read_text()
    assert summary.startswith("# Fit summary: tiny")
    assert "| `train/loss` |" in summary and "| `usage` | 0.25 |" in summary
    assert "![pose](tiny_pose.gif)" in summary and "![curve](tiny_curve.png)" in summary
    assert "A note from the aligner." in summary
    # the headline sits under the step count, before every table
    paragraphs = summary.split("\n\n")
    assert "optimiser step(s)" in paragraphs[1] and paragraphs[2] == "**The finding** of the run."
    assert {p.name for p in callback.written} == {
        "tiny_metrics.json",
        "tiny_pose.gif",
        "tiny_pose.png",
        "tiny_curve.png",
        "summary.md",
    }


def test_render_options_set_one_render_over_the_callback_size(tmp_path: Path) -> None:
    from PIL import Image

    from skelagnostic.viz import StickFigure

    stick = StickFigure(np.array([[[0.0, 0, 0], [0, 1, 0]]] * 3), parents=[-1, 0])
    content = {
        "renders": {"big": [stick, stick], "small": [stick]},
        "render_options": {"big": {"size": (50, 60), "same_scale": True, "labels": ["a", "b"]}},
    }
    _fit(_Tiny(content), tmp_path, callbacks=[FitSummary(name="t", size=(40, 40))])
    for name, size in (("t_big.gif", (100, 60)), ("t_small.gif", (40, 40))):
        with Image.open(tmp_path / name) as image:
            assert image.size == size, name


def test_fit_summary_without_content_or_name(tmp_path: Path) -> None:
    _fit(_Tiny(), tmp_path / "run", callbacks=[FitSummary()])
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert set(metrics) == {"train/loss", "summary"}  # the summary it ran, and why
    assert metrics["summary"]["mode"] == "full"  # _Tiny.fit_summary takes no mode: one summary
    assert "## Pictures" not in (tmp_path / "run" / "summary.md").read_text()
    with pytest.raises(ValueError, match="sheet_frames"):
        FitSummary(sheet_frames=0)


@pytest.mark.parametrize(
    ("batches", "trainer", "expected"),
    [
        (6, {"max_epochs": 3}, 6),
        (6, {"max_epochs": 3, "limit_train_batches": 4}, 4),
        (6, {"max_epochs": 2, "accumulate_grad_batches": 4}, 2),  # ceil(6 / 4)
        (5, {"max_epochs": 1000, "max_steps": 3}, 5),  # not max_steps / max_epochs
        (5, {"max_epochs": -1, "max_steps": 3}, 5),  # the trainer does not count: the loader
    ],
)
def test_steps_per_epoch(
    tmp_path: Path, batches: int, trainer: dict[str, Any], expected: int
) -> None:
    module = _Tiny()
    if trainer.get("max_epochs") == -1:

        class _WithData(L.LightningDataModule):
            def train_dataloader(self) -> DataLoader:
                return DataLoader(TensorDataset(torch.randn(batches * 2, 2)), batch_size=2)

        fitted = L.Trainer(
            accelerator="cpu",
            logger=False,
            enable_checkpointing=False,
            enable_progress_bar=False,
            enable_model_summary=False,
            default_root_dir=str(tmp_path),
            **trainer,
        )
        fitted.fit(module, datamodule=_WithData())
    else:
        _fit(module, tmp_path, batches, **trainer)
    assert module.seen["steps_per_epoch"] == expected
    assert steps_per_epoch(None) == 1


def test_skelagnostic_fit_writes_the_summary_by_default(
    fit_example: Callable[[Path, Sequence[str]], Path], tmp_path: Path
) -> None:
    run_dir = fit_example(tmp_path, FAST)
    metrics = json.loads((run_dir / "example_metrics.json").read_text())
    assert "val/loss" in metrics
    assert (run_dir / "summary.md").read_text().startswith("# Fit summary: example")


def test_long_nested_figures_point_to_the_json_instead_of_a_blob(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from skelagnostic.callbacks import FitSummary

    trainer = SimpleNamespace(current_epoch=1, global_step=5)
    content = {
        "metrics": {"usage": 0.5, "codes": {"a": 1}, "transfer": {"rows": list(range(80))}},
        "notes": ["## Transfer\n\n| a |\n|---|\n| 1 |"],
    }
    text = FitSummary(name="m")._markdown(trainer, {}, content, tmp_path / "m_metrics.json", [])
    assert "| `usage` | 0.5 |" in text and '| `codes` | {"a": 1} |' in text
    assert "| `transfer` | see `transfer` in `m_metrics.json` |" in text
    assert "## Transfer" in text and "79" not in text


class _Moded(_Tiny):
    """A module whose ``fit_summary`` takes the summary mode."""

    def fit_summary(self, trainer: L.Trainer, mode: str = "full") -> dict[str, Any]:
        self.seen["mode"] = mode
        return {"metrics": {"computed": mode}, "notes": [f"computed the {mode} summary"]}


@pytest.mark.parametrize(
    ("mode", "quick_below", "expected"),
    [("auto", 1000, "quick"), ("auto", 6, "full"), ("full", 1000, "full"), ("quick", 3, "quick")],
)
def test_fit_summary_mode_reaches_the_aligner_and_is_stated(
    tmp_path: Path, mode: str, quick_below: int, expected: str
) -> None:
    module = _Moded()
    _fit(module, tmp_path, 6, callbacks=[FitSummary(mode=mode, quick_below=quick_below)])
    assert module.seen["mode"] == expected  # 6 optimiser steps
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["computed"] == expected and metrics["summary"]["mode"] == expected
    text = (tmp_path / "summary.md").read_text()
    assert f"Summary: the aligner's {expected} summary" in text
    if mode == "auto":
        assert "summary=auto: 6 optimiser steps" in text
    assert f"computed the {expected} summary" in text


def test_fit_summary_none_skips_the_aligner(tmp_path: Path) -> None:
    module = _Moded()
    _fit(module, tmp_path, callbacks=[FitSummary(name="m", mode="none")])
    assert "mode" not in module.seen
    assert {p.name for p in tmp_path.iterdir()} == {"m_metrics.json", "summary.md"}
    metrics = json.loads((tmp_path / "m_metrics.json").read_text())
    assert metrics["summary"] == {"mode": "none", "reason": "summary=none"}
    assert "no aligner summary: the logged metrics only" in (tmp_path / "summary.md").read_text()


def test_summary_mode_rule_and_bad_values() -> None:
    from skelagnostic.callbacks import QUICK_BELOW_STEPS, summary_mode

    assert summary_mode("auto", QUICK_BELOW_STEPS - 1)[0] == "quick"
    assert summary_mode("auto", QUICK_BELOW_STEPS)[0] == "full"
    assert summary_mode("none", 10**6) == ("none", "summary=none")
    with pytest.raises(ValueError, match="summary must be one of auto, full, quick, none"):
        summary_mode("sometimes", 1)
    with pytest.raises(ValueError, match=r"mode \(summary=\) must be one of"):
        FitSummary(mode="sometimes")


def test_summary_key_configures_the_callback(example_plugin: Path) -> None:
    from hydra.utils import instantiate

    from skelagnostic.cli.app import compose

    for value, expected in (("", "auto"), ("summary=none", "none"), ("summary=quick", "quick")):
        args = ["model=example", "run_dir=/tmp/unused", *([value] if value else [])]
        assert instantiate(compose(args).callbacks.fit_summary).mode == expected
