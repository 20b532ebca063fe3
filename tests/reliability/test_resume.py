"""Exact resume: a fit killed mid-epoch, resumed, ends with the weights of an uninterrupted fit."""

from __future__ import annotations

import copy
import signal
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import ModelCheckpoint
from torch.utils.data import TensorDataset

from skelagnostic.callbacks import FinalStepValidation, ResumeFromEpochEnd
from skelagnostic.data.loaders import ResumableDataLoader, ResumableSampler
from skelagnostic.data.sources import ProceduralSource

if TYPE_CHECKING:
    from skelagnostic_example import ExampleAligner, ExampleDataModule


def _example() -> Any:
    """The example plugin's package, from its sources (it need not be installed)."""
    import importlib

    from reliability_env import EXAMPLE_SRC

    if str(EXAMPLE_SRC) not in sys.path:
        sys.path.append(str(EXAMPLE_SRC))
    return importlib.import_module("skelagnostic_example")


#: Small procedural data: two datasets of different lengths (the shorter one cycles).
ARGS = [
    "model=example",
    "model.hidden=16",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=1",
    "data.window=16",
    "data.stride=4",
    "data.batch_size=4",
    "trainer.max_epochs=2",
    "trainer.limit_val_batches=1",
    "trainer.log_every_n_steps=1",
    "trainer.enable_model_summary=false",
    "callbacks=default",
    "seed=7",
    # last.ckpt after every step (the default checkpoint waits for val/loss)
    "callbacks.model_checkpoint.save_last=false",
    "+callbacks.resume._target_=lightning.pytorch.callbacks.ModelCheckpoint",
    "+callbacks.resume.dirpath=${run_dir}/checkpoints",
    "+callbacks.resume.save_top_k=0",
    "+callbacks.resume.save_last=true",
    "+callbacks.resume.every_n_train_steps=1",
]


def fit(env: dict[str, str], cwd: Path, run_dir: Path, *extra: str) -> subprocess.CompletedProcess:
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        *ARGS,
        f"hydra.run.dir={run_dir}",
        *extra,
    ]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=240)


def final_state(run_dir: Path) -> dict:
    return torch.load(run_dir / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=False)


def assert_same_training_state(a: dict, b: dict) -> None:
    assert a["global_step"] == b["global_step"] and a["epoch"] == b["epoch"]
    assert a["state_dict"].keys() == b["state_dict"].keys()
    for name, tensor in a["state_dict"].items():
        assert torch.equal(tensor, b["state_dict"][name]), name  # bitwise
    for x, y in zip(
        a["optimizer_states"][0]["state"].values(),
        b["optimizer_states"][0]["state"].values(),
        strict=True,
    ):
        for key in x:
            assert torch.equal(x[key], y[key]), key


def test_loader_resumes_mid_pass_with_the_same_batches() -> None:
    ds = TensorDataset(torch.arange(10))

    def loader() -> ResumableDataLoader:
        return ResumableDataLoader(ds, 3, ResumableSampler(ds, 1, 0, True, seed=5))

    ref = loader()
    ref.sampler.set_epoch(1)
    batches = [b[0].tolist() for b in ref]
    it, partial = iter(ref), loader()
    consumed = [next(it)[0].tolist() for _ in range(2)]
    partial.load_state_dict(ref.state_dict())
    assert ref.state_dict() == {"epoch": 1, "served": 2}
    assert consumed + [b[0].tolist() for b in partial] == batches
    assert partial.state_dict() == {"epoch": 1, "served": 4}
    assert sorted(i for b in batches for i in b) == list(range(10))


def test_loader_state_of_a_finished_pass_starts_the_next_epoch_whole() -> None:
    ds = TensorDataset(torch.arange(10))

    def loader() -> ResumableDataLoader:
        return ResumableDataLoader(ds, 3, ResumableSampler(ds, 1, 0, True, seed=5))

    done = loader()
    done.sampler.set_epoch(1)
    assert len(list(done)) == 4
    assert done.state_dict() == {"epoch": 1, "served": 4}
    ref = loader()
    ref.sampler.set_epoch(2)
    resumed = loader()
    resumed.load_state_dict(done.state_dict())
    resumed.sampler.set_epoch(2)  # Lightning does this before the next epoch's pass
    assert [b[0].tolist() for b in resumed] == [b[0].tolist() for b in ref]
    assert resumed.state_dict() == {"epoch": 2, "served": 4}


def test_ranks_get_disjoint_shards() -> None:
    ds = TensorDataset(torch.arange(10))
    shards = [list(ResumableSampler(ds, 2, r, True, seed=0)) for r in (0, 1)]
    assert sorted(shards[0] + shards[1]) == list(range(10))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("signum", "where"),
    [
        pytest.param(signal.SIGKILL, "mid-epoch", id="SIGKILL-mid-epoch"),
        pytest.param(signal.SIGTERM, "mid-epoch", id="SIGTERM-mid-epoch"),
        pytest.param(signal.SIGKILL, "epoch-boundary", id="SIGKILL-epoch-boundary"),
    ],
)
def test_killed_fit_resumes_bitwise(
    cli_env: dict[str, str], tmp_path: Path, signum: signal.Signals, where: str
) -> None:
    ref = fit(cli_env, tmp_path, tmp_path / "ref")
    assert ref.returncode == 0, ref.stderr[-3000:]
    reference = final_state(tmp_path / "ref")
    steps_per_epoch = reference["global_step"] // 2
    assert steps_per_epoch >= 4
    # SIGKILL in the middle of epoch 0, SIGTERM in the middle of epoch 1; at the epoch
    # boundary, SIGKILL on the first step of epoch 1 (the newest checkpoint is epoch 0's last)
    if where == "epoch-boundary":
        kill_step = steps_per_epoch + 1
    else:
        kill_step = 2 if signum == signal.SIGKILL else steps_per_epoch + 2
    killed = fit(
        cli_env,
        tmp_path,
        tmp_path / "killed",
        "+callbacks.kill._target_=killer.KillAt",
        f"+callbacks.kill.step={kill_step}",
        f"+callbacks.kill.signum={int(signum)}",
    )
    assert killed.returncode == (143 if signum == signal.SIGTERM else -signal.SIGKILL)
    if signum == signal.SIGTERM:
        assert killed.stderr.strip().splitlines()[-1] == (
            f"skelagnostic fit: terminated by SIGTERM [run directory kept: {tmp_path / 'killed'}; "
            f"resume with ckpt_path={tmp_path / 'killed' / 'checkpoints' / 'last.ckpt'}]"
        )
    last = tmp_path / "killed" / "checkpoints" / "last.ckpt"
    interrupted = torch.load(last, map_location="cpu", weights_only=False)
    # SIGKILL: the checkpoint of the step before; SIGTERM: Lightning finishes the step
    # (its handler only sets a flag), the checkpoint callback saves it, then the run stops.
    saved = kill_step - 1 if signum == signal.SIGKILL else kill_step
    assert interrupted["global_step"] == saved
    assert (interrupted["global_step"] % steps_per_epoch == 0) == (where == "epoch-boundary")
    resumed = fit(cli_env, tmp_path, tmp_path / "resumed", f"ckpt_path={last}")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "not resumable" not in resumed.stderr + resumed.stdout
    assert_same_training_state(final_state(tmp_path / "resumed"), reference)


# ------------------------------------------------ resume from every checkpoint of a run
def _trainer(
    root: Path, callbacks: tuple[L.Callback, ...] = (), **options: object
) -> tuple[L.Trainer, ExampleAligner, ExampleDataModule]:
    """A 3-epoch example-aligner fit that checkpoints at every point Lightning can.

    After every training batch (``steps/``), after every validation run
    (``val/``) and at every training-epoch end (``epochs/``): together the
    checkpoints a run interrupted anywhere would resume from.
    """
    L.seed_everything(7, workers=True)
    example = _example()
    dm = example.ExampleDataModule(
        sources=[ProceduralSource(clips_per_gait=1, seconds=2.0)],
        window=16,
        stride=4,
        batch_size=4,
        cache_dir=root.parent / "cache",
    )
    model = example.ExampleAligner(hidden=16, latent=4)
    checkpoints = [
        ModelCheckpoint(
            dirpath=root / "steps", filename="{step}", save_top_k=-1, every_n_train_steps=1
        ),
        ModelCheckpoint(
            dirpath=root / "val", filename="{step}", save_top_k=-1, save_on_train_epoch_end=False
        ),
        ModelCheckpoint(
            dirpath=root / "epochs",
            filename="{step}",
            save_top_k=-1,
            save_on_train_epoch_end=True,
            mode="max",
        ),  # mode: a distinct state key
    ]
    trainer = L.Trainer(
        accelerator="cpu",
        max_epochs=3,
        logger=False,
        callbacks=[*checkpoints, ResumeFromEpochEnd(), *callbacks],  # as skelagnostic fit
        enable_progress_bar=False,
        enable_model_summary=False,
        default_root_dir=root,
        **options,
    )
    return trainer, model, dm


def _state(trainer: L.Trainer, model: ExampleAligner) -> dict:
    return {
        "global_step": trainer.global_step,
        "epoch": trainer.current_epoch,
        "state_dict": {k: v.clone() for k, v in model.state_dict().items()},
        "optimizer_states": [copy.deepcopy(trainer.optimizers[0].state_dict())],
    }


@pytest.mark.parametrize(
    "options",
    [
        pytest.param({"limit_val_batches": 1}, id="validation"),
        pytest.param({"limit_train_batches": 4, "limit_val_batches": 0}, id="limit_train_batches"),
        # max_steps: Lightning restarts epoch-end checkpoints as unfinished (ResumeFromEpochEnd)
        pytest.param({"max_steps": 16, "limit_val_batches": 0}, id="max_steps"),
    ],
)
def test_resume_from_every_checkpoint_of_a_run_is_bitwise(tmp_path: Path, options: dict) -> None:
    trainer, model, dm = _trainer(tmp_path / "ref", **options)
    trainer.fit(model, datamodule=dm)
    reference = _state(trainer, model)
    per_epoch = trainer.num_training_batches
    total = options.get("max_steps", 3 * per_epoch)
    assert reference["global_step"] == total and per_epoch >= 4 and total > 2 * per_epoch
    saved = sorted((tmp_path / "ref").glob("*/*.ckpt"))
    steps = {int(p.stem.split("=")[1]) for p in saved if p.parent.name == "steps"}
    assert steps == set(range(1, total + 1))  # every step: first, middle, last batch
    assert {p.parent.name for p in saved} == (
        {"steps", "epochs"} if options.get("limit_val_batches") == 0 else {"steps", "val", "epochs"}
    )
    for ckpt in saved:
        if int(ckpt.stem.split("=")[1]) == options.get("max_steps"):
            continue  # written when max_steps had ended the run: no interruption to resume
        trainer, model, dm = _trainer(
            tmp_path / "resumed" / ckpt.parent.name / ckpt.stem, **options
        )
        trainer.fit(model, datamodule=dm, ckpt_path=ckpt)
        resumed = _state(trainer, model)
        assert resumed["global_step"] == reference["global_step"], ckpt
        assert_same_training_state(resumed, reference)


class _CountValidations(L.Callback):
    def __init__(self) -> None:
        self.steps: list[int] = []

    def on_validation_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if not trainer.sanity_checking:
            self.steps.append(trainer.global_step)


@pytest.mark.parametrize("final_validation", [False, True])
def test_a_run_that_max_steps_stops_inside_an_epoch_validates_its_final_weights(
    tmp_path: Path, final_validation: bool
) -> None:
    count = _CountValidations()
    extra = (count, FinalStepValidation()) if final_validation else (count,)
    trainer, model, dm = _trainer(tmp_path / "run", extra, max_steps=16, limit_val_batches=1)
    trainer.fit(model, datamodule=dm)
    per_epoch = trainer.num_training_batches
    assert trainer.global_step == 16 and 16 % per_epoch and 16 > 2 * per_epoch
    epoch_ends = [per_epoch, 2 * per_epoch]
    assert count.steps == ([*epoch_ends, 16] if final_validation else epoch_ends)
    # the validation's checkpoint callbacks saw the final weights
    newest = torch.load(
        tmp_path / "run" / "val" / f"step={count.steps[-1]}.ckpt", weights_only=False
    )
    final = model.state_dict()
    same = all(torch.equal(newest["state_dict"][k], v) for k, v in final.items())
    assert same == final_validation
    assert "val/loss" in trainer.callback_metrics


def test_a_run_that_ends_with_its_epoch_validates_once(tmp_path: Path) -> None:
    count = _CountValidations()
    trainer, model, dm = _trainer(tmp_path / "probe", limit_val_batches=0, max_steps=1)
    trainer.fit(model, datamodule=dm)
    per_epoch = trainer.num_training_batches
    trainer, model, dm = _trainer(
        tmp_path / "run",
        (count, FinalStepValidation()),
        max_steps=2 * per_epoch,
        limit_val_batches=1,
    )
    trainer.fit(model, datamodule=dm)
    assert count.steps == [per_epoch, 2 * per_epoch]
