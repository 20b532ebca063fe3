"""VQ-PAE fixtures: a window cache, small data/trainer helpers and a trained model.

The plugin manager (``vqpae_pm``) is shared with the other methods in tests/conftest.py.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import lightning as L
import pytest

#: Frame rate of the small test datasets (windows of FPS + 1 frames).
FPS = 20


@pytest.fixture
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A per-test window cache."""
    return tmp_path_factory.mktemp("vqpae-cache")


def make_datamodule(cache_dir: Path) -> Any:
    """Procedural biped + quadruped, every gait, 3 s clips at 20 fps, pivots every 2 frames.

    With partner windows 0.1 s on, for the phase-rate loss of ``PREVIOUS_DEFAULTS``.
    """
    from skelagnostic_vqpae.data import VqpaeDataModule

    from skelagnostic.data import ProceduralSource

    src = ProceduralSource(kinds=["biped22", "quadruped"], clips_per_gait=2, seconds=3.0)
    return VqpaeDataModule(
        src, fps=FPS, stride=2, batch_size=16, cache_dir=cache_dir, pair_seconds=0.1
    )


def make_trainer(root: Path, steps: int, validate: bool = True) -> L.Trainer:
    """A quiet CPU trainer for ``steps`` steps."""
    return L.Trainer(
        max_steps=steps,
        accelerator="cpu",
        devices=1,
        logger=False,
        limit_val_batches=None if validate else 0,
        enable_checkpointing=True,
        enable_progress_bar=False,
        enable_model_summary=False,
        default_root_dir=str(root),
        num_sanity_val_steps=0,
        deterministic=True,
    )


def make_tiny(root: Path, test_fraction: float) -> tuple[Any, Any]:
    """A VQ-PAE trained 3 steps on :func:`make_datamodule` (no quality expected), in eval mode.

    Args:
        root: Directory of the run and its window cache.
        test_fraction: Share of the clips held out.

    Returns:
        ``(model, held_out(datamodule))``.
    """
    from skelagnostic_vqpae.aligner import (
        AUTHORS_OPTIMIZER,
        COSINE_SCHEDULER,
        PREVIOUS_DEFAULTS,
        VqpaeAligner,
    )

    from skelagnostic.evaluation import held_out

    L.seed_everything(0, verbose=False)
    dm = make_datamodule(root / "cache")
    dm.test_fraction = test_fraction
    model = VqpaeAligner(
        num_codes=8,
        kernel_size=7,
        **{
            **PREVIOUS_DEFAULTS,
            "optimizer": {**AUTHORS_OPTIMIZER, "lr": 1e-3},
            "scheduler": {**COSINE_SCHEDULER, "period": 1000},
        },
    )
    make_trainer(root, 3, validate=False).fit(model, datamodule=dm)
    return model.eval(), held_out(dm)


@pytest.fixture
def helpers() -> dict[str, Callable[..., Any]]:
    """``make_datamodule``, ``make_trainer`` and ``make_tiny`` for tests that train a model."""
    return {"datamodule": make_datamodule, "trainer": make_trainer, "tiny": make_tiny}


@pytest.fixture(scope="session")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A small aligner trained for 200 steps, its data, validation before/after, checkpoint."""
    from skelagnostic_vqpae.aligner import (
        AUTHORS_OPTIMIZER,
        COSINE_SCHEDULER,
        PREVIOUS_DEFAULTS,
        VqpaeAligner,
    )

    root = tmp_path_factory.mktemp("vqpae-train")
    L.seed_everything(0, verbose=False)
    dm = make_datamodule(root / "cache")
    model = VqpaeAligner(
        num_codes=8,
        kernel_size=7,
        **{
            **PREVIOUS_DEFAULTS,
            "optimizer": {**AUTHORS_OPTIMIZER, "lr": 1e-3},
            "scheduler": {**COSINE_SCHEDULER, "period": 1000},
        },
    )
    before = make_trainer(root, 1).validate(model, datamodule=dm, verbose=False)[0]
    from skelagnostic.callbacks import FitSummary

    trainer = make_trainer(root, 200, validate=False)
    trainer.callbacks.append(FitSummary(name="vqpae"))  # what `skelagnostic fit` adds
    trainer.fit(model, datamodule=dm)
    after = make_trainer(root, 1).validate(model, datamodule=dm, verbose=False)[0]
    ckpt = root / "final.ckpt"
    trainer.save_checkpoint(ckpt)
    return {"model": model, "dm": dm, "before": before, "after": after, "ckpt": ckpt, "root": root}


@pytest.fixture
def vqpae_cli(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """``skelagnostic.cli.main``, run in ``tmp_path`` with only the VQ-PAE plugin loaded."""
    from skelagnostic import cli
    from skelagnostic.plugins import LOAD_PLUGINS_ENV, get_plugin_manager

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv(LOAD_PLUGINS_ENV, "vqpae")
    get_plugin_manager.cache_clear()
    yield cli.main
    get_plugin_manager.cache_clear()


@pytest.fixture(scope="module")
def tiny_fit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A VQ-PAE fitted 3 steps with the default end-of-fit summary (auto) in ``<root>/auto``.

    Returns ``model``, ``trainer``, ``root`` and the data module ``dm``.
    """
    from skelagnostic_vqpae.aligner import (
        AUTHORS_OPTIMIZER,
        COSINE_SCHEDULER,
        PREVIOUS_DEFAULTS,
        VqpaeAligner,
    )

    from skelagnostic.callbacks import FitSummary

    root = tmp_path_factory.mktemp("vqpae-summary")
    L.seed_everything(0, verbose=False)
    dm = make_datamodule(root / "cache")
    model = VqpaeAligner(
        num_codes=8,
        kernel_size=7,
        **{
            **PREVIOUS_DEFAULTS,
            "optimizer": {**AUTHORS_OPTIMIZER, "lr": 1e-3},
            "scheduler": {**COSINE_SCHEDULER, "period": 1000},
        },
    )
    trainer = make_trainer(root, 3, validate=False)
    trainer.callbacks.append(FitSummary(name="vqpae", dirpath=root / "auto"))  # as `fit` does
    trainer.fit(model, datamodule=dm)
    return {"model": model, "trainer": trainer, "root": root, "dm": dm}
