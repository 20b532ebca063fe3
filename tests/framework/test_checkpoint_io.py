"""AtomicCheckpointIO: checkpoint files written next to their path and renamed, in every fit."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import ModelCheckpoint
from torch.utils.data import DataLoader, TensorDataset

from skelagnostic.callbacks import AtomicCheckpointIO
from skelagnostic.callbacks.checkpoint_io import TEMP_SUFFIX
from skelagnostic.cli import app

FAST = [
    "experiment=smoke",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=8",
    "model.hidden=16",
    "model.latent=4",
]


@pytest.fixture
def umask_022() -> Iterator[None]:
    old = os.umask(0o022)
    yield
    os.umask(old)


@pytest.fixture
def private_tmpdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``$TMPDIR`` pointed at an empty test directory (also for :mod:`tempfile`)."""
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr(tempfile, "tempdir", None)
    return tmpdir


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_save_replaces_the_file_and_leaves_no_temporary(
    tmp_path: Path, private_tmpdir: Path, umask_022: None
) -> None:
    io = AtomicCheckpointIO()
    path = tmp_path / "ckpts" / "last.ckpt"
    stale = path.with_name("last.ckpt" + TEMP_SUFFIX)
    io.save_checkpoint({"generation": 1}, path)  # creates the directory
    stale.write_bytes(b"half a checkpoint from a killed save")
    io.save_checkpoint({"generation": 2, "w": torch.arange(5)}, path)
    assert sorted(p.name for p in path.parent.iterdir()) == ["last.ckpt"]  # stale one gone
    assert io.load_checkpoint(path)["generation"] == 2
    assert mode(path) == 0o644  # the umask applies
    assert not any(private_tmpdir.iterdir())
    io.remove_checkpoint(path)
    assert not path.exists()


def test_failed_save_keeps_the_previous_checkpoint(tmp_path: Path) -> None:
    io = AtomicCheckpointIO()
    path = tmp_path / "last.ckpt"
    io.save_checkpoint({"generation": 1}, path)
    with pytest.raises(Exception, match="pickle"):
        io.save_checkpoint({"generation": 2, "unpicklable": lambda: None}, path)
    assert io.load_checkpoint(path)["generation"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["last.ckpt"]
    with pytest.raises(TypeError, match="storage_options"):
        io.save_checkpoint({}, path, storage_options={"x": 1})


def test_save_replaces_a_symlink_not_its_target(tmp_path: Path) -> None:
    io = AtomicCheckpointIO()
    best, last = tmp_path / "best.ckpt", tmp_path / "last.ckpt"
    io.save_checkpoint({"generation": 1}, best)
    last.symlink_to(best.name)
    io.save_checkpoint({"generation": 2}, last)
    assert not last.is_symlink()
    assert io.load_checkpoint(best)["generation"] == 1
    assert io.load_checkpoint(last)["generation"] == 2


class Tiny(L.LightningModule):
    """A linear layer trained on 8 random batches."""

    def __init__(self) -> None:
        super().__init__()
        self.layer = torch.nn.Linear(4, 1)

    def training_step(self, batch: list[torch.Tensor], batch_idx: int) -> torch.Tensor:
        loss = self.layer(batch[0]).pow(2).mean()
        self.log("loss", loss)
        return loss

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.SGD(self.parameters(), lr=0.1)

    def train_dataloader(self) -> DataLoader:
        data = torch.randn(16, 4, generator=torch.Generator().manual_seed(0))
        return DataLoader(TensorDataset(data), batch_size=2)


@pytest.mark.parametrize("save_last", [True, "link"])
def test_model_checkpoint_top_k_and_last(
    tmp_path: Path, private_tmpdir: Path, umask_022: None, save_last: bool | str
) -> None:
    callback = ModelCheckpoint(
        dirpath=tmp_path / "ckpts",
        filename="{step}",
        monitor="step",
        mode="max",
        save_top_k=2,
        every_n_train_steps=1,
        save_last=save_last,
    )
    trainer = L.Trainer(
        accelerator="cpu",
        max_epochs=1,
        logger=False,
        callbacks=[callback],
        enable_progress_bar=False,
        enable_model_summary=False,
        plugins=[AtomicCheckpointIO()],
        default_root_dir=tmp_path,
    )
    assert isinstance(trainer.strategy.checkpoint_io, AtomicCheckpointIO)
    trainer.fit(Tiny())
    files = {p.name: p for p in (tmp_path / "ckpts").iterdir()}
    assert set(files) == {"step=7.ckpt", "step=8.ckpt", "last.ckpt"}  # older ones removed
    assert files["last.ckpt"].is_symlink() == (save_last == "link")
    for name, path in files.items():
        assert torch.load(path, weights_only=False)["global_step"] == (
            8 if name == "last.ckpt" else int(name[5])
        )
        assert mode(path) == 0o644
    assert not any(private_tmpdir.iterdir())


def test_ddp_trainer_saves_through_it_on_rank_zero_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # set_global_rank(1) below also sets the process-wide rank of Lightning's
    # rank_zero_only helpers: restore them after the test, or later tests in this
    # worker would log, save configs and write metrics as a non-zero rank (nothing).
    from lightning.fabric.utilities import rank_zero as fabric_rank_zero
    from lightning.pytorch.utilities import rank_zero_only
    from lightning_utilities.core import rank_zero as utilities_rank_zero

    for helper in {
        id(f): f
        for f in (
            rank_zero_only,
            fabric_rank_zero.rank_zero_only,
            utilities_rank_zero.rank_zero_only,
        )
    }.values():
        monkeypatch.setattr(helper, "rank", getattr(helper, "rank", 0), raising=False)
    trainer = L.Trainer(
        accelerator="cpu",
        strategy="ddp",
        devices=2,
        logger=False,
        plugins=[AtomicCheckpointIO()],
        default_root_dir=tmp_path,
    )
    strategy = trainer.strategy
    assert isinstance(strategy.checkpoint_io, AtomicCheckpointIO)
    assert strategy.global_rank == 0  # not launched: this process would be rank 0
    strategy.save_checkpoint({"generation": 1}, tmp_path / "rank0.ckpt")
    strategy.cluster_environment.set_global_rank(1)  # as in the second process
    assert not strategy.is_global_zero
    strategy.save_checkpoint({"generation": 1}, tmp_path / "rank1.ckpt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rank0.ckpt"]


def test_fit_writes_checkpoints_atomically(
    example_plugin: Path,
    tmp_path: Path,
    private_tmpdir: Path,
    umask_022: None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    staged: list[str] = []
    mkstemp = tempfile.mkstemp

    def spy(*args: object, **kwargs: object) -> tuple[int, str]:
        fd, name = mkstemp(*args, **kwargs)  # type: ignore[call-overload]
        if Path(name).parent == private_tmpdir:  # not the window cache's own temporaries
            staged.append(name)
        return fd, name

    monkeypatch.setattr(tempfile, "mkstemp", spy)  # fsspec stages Lightning's saves with it
    run_dir = tmp_path / "run"
    app.run(
        app.compose(
            [
                "model=example",
                f"data.cache_dir={tmp_path / 'cache'}",
                *FAST,
                f"run_dir={run_dir}",
                "trainer.max_epochs=1",
            ]
        )
    )
    ckpts = sorted((run_dir / "checkpoints").iterdir())
    assert [p.name for p in ckpts] == ["best.ckpt", "last.ckpt"]
    assert all(mode(p) == 0o644 for p in ckpts)
    assert staged == []  # written next to their path by AtomicCheckpointIO, not via $TMPDIR
    assert not any(private_tmpdir.iterdir())


@pytest.mark.slow
def test_ddp_fit_writes_checkpoints_atomically(
    subprocess_env: dict[str, str], tmp_path: Path, umask_022: None
) -> None:
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir()
    run_dir = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        "model=example",
        *FAST,
        "trainer.strategy=ddp",
        "trainer.devices=2",
        f"hydra.run.dir={run_dir}",
    ]
    proc = subprocess.run(
        cmd,
        env={**subprocess_env, "TMPDIR": str(tmpdir)},
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    ckpts = sorted((run_dir / "checkpoints").iterdir())
    assert [p.name for p in ckpts] == ["best.ckpt", "last.ckpt"]
    assert all(mode(p) == 0o644 for p in ckpts)
    assert not any(tmpdir.iterdir())
