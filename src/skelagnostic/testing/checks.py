"""The contract's checks as plain functions, for pytest and other test runners.

:func:`fit_for_contract` makes the short training run (a :class:`ContractRun`);
each ``check_*`` function asserts one promise of the contract on it (see
:mod:`skelagnostic.testing`). This module imports pytest: use it from tests.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic._shadow import check_not_shadowed

check_not_shadowed()  # a folder named skelagnostic hiding the package: say so, in one line

if TYPE_CHECKING:
    from skelagnostic.aligners import Aligner
    from skelagnostic.core.motion import Motion
    from skelagnostic.core.skeleton import Skeleton
    from skelagnostic.plugins import PluginManager


#: Lightning hooks whose ``self.log`` is per batch (``batch_size`` matters there).
_STEP_HOOKS = ("training_step", "validation_step", "test_step")


#: Step hooks where ``on_epoch`` defaults to ``True`` in ``LightningModule.log``.
_EPOCH_DEFAULT_HOOKS = ("validation_step", "test_step")


@dataclass(frozen=True)
class LogCall:
    """One ``self.log(name, value, ...)`` call seen during the contract run.

    Attributes:
        hook: The Lightning hook that logged (``training_step``, ...).
        name: The logged key.
        kwargs: The keyword arguments given to ``log``.
        is_metric: The value was a torchmetrics ``Metric`` (it synchronises itself).
    """

    hook: str
    name: str
    kwargs: dict[str, Any]
    is_metric: bool


@dataclass
class ContractRun:
    """The result of :func:`fit_for_contract`.

    Attributes:
        aligner: The registered aligner name.
        run_dir: The run directory.
        metrics: What :func:`~skelagnostic.cli.app.run` returned.
        model: The trained aligner.
        datamodule: Its data module (set up).
        initial: The weights at the first training step, before any update.
        logs: Every ``self.log`` call.
        plugin_manager: Where the aligner was looked up.
        global_manager: ``plugin_manager`` is the process-wide one (then the round
            trip goes through :func:`skelagnostic.plugins.load_aligner`).
    """

    aligner: str
    run_dir: Path
    metrics: dict[str, float]
    model: Aligner
    datamodule: Any
    initial: dict[str, torch.Tensor]
    plugin_manager: PluginManager
    logs: list[LogCall] = field(default_factory=list)
    global_manager: bool = True

    @property
    def checkpoint(self) -> Path:
        """``<run_dir>/checkpoints/last.ckpt``."""
        return self.run_dir / "checkpoints" / "last.ckpt"


@contextmanager
def _spy_on_log(cls: type, calls: list[LogCall], seen: dict[str, Any]) -> Iterator[None]:
    """Record ``cls.log`` calls; remember the module and its weights at its first call."""
    from torchmetrics import Metric

    original = cls.log

    def log(self: Any, name: str, value: Any, *args: Any, **kwargs: Any) -> None:
        hook = str(getattr(self, "_current_fx_name", None) or "")
        if "model" not in seen:
            seen["model"] = self
        if hook == "training_step" and "initial" not in seen:
            seen["initial"] = {k: v.detach().clone() for k, v in self.state_dict().items()}
        names = (
            "prog_bar",
            "logger",
            "on_step",
            "on_epoch",
            "reduce_fx",
            "enable_graph",
            "sync_dist",
            "sync_dist_group",
            "add_dataloader_idx",
            "batch_size",
            "metric_attribute",
            "rank_zero_only",
        )
        given = {**dict(zip(names, args, strict=False)), **kwargs}
        calls.append(LogCall(hook, name, given, isinstance(value, Metric)))
        return original(self, name, value, *args, **kwargs)

    cls.log = log  # type: ignore[method-assign]
    try:
        yield
    finally:
        cls.log = original  # type: ignore[method-assign]


def fit_for_contract(
    aligner: str,
    run_dir: str | Path,
    overrides: Sequence[str] = (),
    steps: int = 4,
    plugin_manager: PluginManager | None = None,
) -> ContractRun:
    """Train ``aligner`` for ``steps`` optimizer steps plus one validation pass, on CPU.

    Args:
        aligner: A registered aligner name.
        run_dir: Where the run writes (its window cache goes to ``run_dir/cache``).
        overrides: Extra Hydra overrides (after ``experiment=smoke``), e.g. tiny sizes.
        steps: Training batches (one epoch).
        plugin_manager: Where the aligner is looked up (default: the process-wide one).

    Returns:
        The run, with the trained model and every ``self.log`` call.
    """
    from skelagnostic.cli.app import compose, run
    from skelagnostic.plugins import get_plugin_manager

    pm = plugin_manager or get_plugin_manager()
    run_dir = Path(run_dir)
    cfg = compose(
        [
            f"model={aligner}",
            "experiment=smoke",
            f"run_dir={run_dir}",
            f"data.cache_dir={run_dir / 'cache'}",
            "threads=1",
            "trainer.max_epochs=1",
            "trainer.max_time=null",
            f"trainer.limit_train_batches={steps}",
            "trainer.limit_val_batches=1",
            "~callbacks.rich_progress_bar",
            "+trainer.enable_progress_bar=false",
            "+trainer.num_sanity_val_steps=0",
            *overrides,
        ],
        plugin_manager=pm,
    )
    calls: list[LogCall] = []
    seen: dict[str, Any] = {}
    with _spy_on_log(pm.aligner(aligner).module, calls, seen):
        metrics = run(cfg, pm)
    model = seen.get("model")
    assert model is not None, f"aligner {aligner!r} never called self.log during fit"
    assert "initial" in seen, f"aligner {aligner!r}: training_step logged nothing"
    return ContractRun(
        aligner,
        run_dir,
        metrics,
        model,
        model.trainer.datamodule,
        seen["initial"],
        pm,
        calls,
        plugin_manager is None,
    )


def check_fit(run: ContractRun) -> None:
    """Finite ``train/loss`` and ``val/loss``, weights that changed, a ``last.ckpt``."""
    for key in ("train/loss", "val/loss"):
        assert key in run.metrics, (
            f"aligner {run.aligner!r} did not log {key!r} "
            f"(logged: {', '.join(sorted(run.metrics)) or 'nothing'})"
        )
        assert math.isfinite(run.metrics[key]), f"aligner {run.aligner!r}: {key} is not finite"
    now = run.model.state_dict()
    changed = [
        k
        for k, v in run.initial.items()
        if v.is_floating_point() and not torch.equal(v.cpu(), now[k].detach().cpu())
    ]
    assert changed, f"aligner {run.aligner!r}: training did not change any weight"
    assert run.checkpoint.is_file(), f"aligner {run.aligner!r}: no {run.checkpoint}"


def _load(run: ContractRun) -> Aligner:
    from skelagnostic.plugins import load_aligner

    if run.global_manager:
        return load_aligner(run.aligner, checkpoint=run.checkpoint)
    spec = run.plugin_manager.aligner(run.aligner)
    return spec.module.load_from_checkpoint(run.checkpoint, map_location="cpu").eval()


def check_checkpoint_round_trip(run: ContractRun, motion: Motion | None = None) -> Aligner:
    """The checkpoint alone rebuilds the network with the saved weights (and same encodings).

    Args:
        run: The contract run.
        motion: A clip to encode with both models (default: :func:`contract_motion`).

    Returns:
        The reloaded aligner.
    """
    saved = torch.load(run.checkpoint, map_location="cpu", weights_only=False)["state_dict"]
    loaded = _load(run)
    state = loaded.state_dict()
    missing, extra = sorted(set(saved) - set(state)), sorted(set(state) - set(saved))
    assert not missing and not extra, (
        f"aligner {run.aligner!r}: the network rebuilt from the checkpoint's hyper-parameters "
        f"differs (missing: {missing[:5]}, unexpected: {extra[:5]}); save data-dependent sizes "
        "with self.save_hyperparameters()"
    )
    for key, value in saved.items():
        assert torch.equal(value, state[key].cpu()), (
            f"aligner {run.aligner!r}: weight {key!r} differs after load_aligner"
        )
    motion = motion if motion is not None else contract_motion(run)
    run.model.eval()
    a, b = run.model.encode(motion), loaded.encode(motion)
    torch.testing.assert_close(
        b.z.float().cpu(),
        a.z.float().cpu(),
        rtol=1e-4,
        atol=1e-5,
        msg=lambda m: f"aligner {run.aligner!r}: reloaded encode differs: {m}",
    )
    return loaded


def contract_motion(run: ContractRun, max_frames: int = 64) -> Motion:
    """The first clip of the run's first data source at the data module's fps (cut short)."""
    dm = run.datamodule
    source = dm.sources[0]
    motion = source.load(source.clips()[0])
    if abs(motion.fps - dm.fps) > 1e-6:
        motion = motion.resample(dm.fps)
    return motion[: min(motion.num_frames, max_frames)]


def check_encode_decode(run: ContractRun, motion: Motion, target: Skeleton) -> None:
    """``decode(encode(motion), target)`` (and ``retarget``) give finite motions on ``target``.

    Args:
        run: The contract run.
        motion: A clip of a skeleton the aligner was trained on.
        target: The skeleton to decode onto.
    """
    from skelagnostic.aligners import Latent
    from skelagnostic.core.motion import Motion

    model = run.model.eval()
    latent = model.encode(motion)
    assert isinstance(latent, Latent), f"{type(model).__name__}.encode must return a Latent"
    assert isinstance(latent.z, torch.Tensor) and bool(torch.isfinite(latent.z).all()), (
        f"{type(model).__name__}.encode: z is not a finite tensor"
    )
    results = {"decode": model.decode(latent, target)}
    if model.supports("retarget"):
        results["retarget"] = model.retarget(motion, target)
    for what, out in results.items():
        name = f"{type(model).__name__}.{what}"
        assert isinstance(out, Motion), f"{name} must return a Motion, got {type(out).__name__}"
        assert out.skeleton.num_joints == target.num_joints, f"{name}: wrong skeleton"
        assert out.num_frames == motion.num_frames, (
            f"{name}: {out.num_frames} frames for a {motion.num_frames}-frame clip"
        )
        assert abs(out.fps - motion.fps) < 1e-6, f"{name}: fps {out.fps} != {motion.fps}"
        assert tuple(out.rotations.shape) == (motion.num_frames, target.num_joints, 4)
        assert bool(torch.isfinite(out.global_positions()).all()), f"{name}: non-finite output"


def check_length_units(run: ContractRun, motion: Motion) -> None:
    """``encode`` gives the same latent for a clip in metres, centimetres, or an unstated unit.

    Args:
        run: The contract run.
        motion: A clip of a skeleton the aligner was trained on.
    """
    model = run.model.eval()
    metres = motion.to_metres()
    cm = metres.convert_units("cm")
    guessed = cm.scaled(1.0)  # a copy, whose unit is left to the height guess (as read_bvh)
    guessed.units = None
    reference = model.encode(metres).z.float().cpu()
    for label, other in (("centimetres", cm), ("no unit", guessed)):
        torch.testing.assert_close(
            model.encode(other).z.float().cpu(),
            reference,
            rtol=1e-4,
            atol=1e-5,
            msg=lambda m, label=label: (
                f"{type(model).__name__}.encode: the clip in {label} encodes differently from "
                f"the same clip in metres (convert with Motion.to_metres before the network): {m}"
            ),
        )


def _first_batch(loader: Any) -> Any:
    """The first batch of a data module's loader (a ``CombinedLoader`` too), or None."""
    from lightning.pytorch.utilities import CombinedLoader

    if isinstance(loader, CombinedLoader):
        return next(iter(loader), (None,))[0]
    return next(iter(loader), None)


def check_steps_without_trainer(run: ContractRun) -> None:
    """``training_step`` and ``validation_step`` run on the data's batches without a Trainer.

    The aligner rebuilt from the checkpoint is attached to no Trainer (its
    ``self.trainer`` raises) and gets the first training batch of the run's data
    module, then its first validation batch (the training batch when there is no
    validation data). The training loss must be finite and back-propagate to a
    finite gradient that is not zero everywhere. ``self.log`` without a Trainer
    only warns (Lightning's own rule for testing steps), so that warning is silenced.

    Args:
        run: The contract run.
    """
    import warnings

    name = type(run.model).__name__
    model = _load(run)
    assert model._trainer is None, f"{name}: the reloaded model is attached to a Trainer"
    train = _first_batch(run.datamodule.train_dataloader())
    assert train is not None, f"aligner {run.aligner!r}: the training loader gave no batch"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*self.log.*", category=UserWarning)
        model.train()
        model.zero_grad()
        loss = model.training_step(train, 0)
        loss = loss["loss"] if isinstance(loss, dict) else loss
        assert isinstance(loss, torch.Tensor) and bool(torch.isfinite(loss)), (
            f"{name}.training_step without a Trainer: the loss is not a finite tensor ({loss})"
        )
        loss.backward()
        grads = [p.grad for p in model.parameters() if p.grad is not None]
        assert grads and all(bool(torch.isfinite(g).all()) for g in grads), (
            f"{name}.training_step without a Trainer: no finite gradient"
        )
        assert any(bool(g.abs().sum() > 0) for g in grads), f"{name}: the gradient is zero"
        val = _first_batch(run.datamodule.val_dataloader())
        model.eval()
        with torch.no_grad():
            model.validation_step(train if val is None else val, 0)


def check_logging(run: ContractRun) -> None:
    """Explicit ``batch_size`` in step logs; ``sync_dist=True`` for epoch-level step values.

    Values logged in epoch-end hooks are not checked: they are usually computed
    from already synchronised state (a torchmetrics ``compute()``, an
    ``all_gather``), which the contract cannot see.
    """
    problems = []
    for call in run.logs:
        if call.is_metric or call.kwargs.get("rank_zero_only"):
            continue
        where = f"{type(run.model).__name__}.{call.hook} logs {call.name!r}"
        if call.hook in _STEP_HOOKS and call.kwargs.get("batch_size") is None:
            problems.append(f"{where} without batch_size=")
        on_epoch = call.kwargs.get("on_epoch")
        epoch_level = on_epoch if on_epoch is not None else call.hook in _EPOCH_DEFAULT_HOOKS
        if call.hook in _STEP_HOOKS and epoch_level and not call.kwargs.get("sync_dist"):
            problems.append(f"{where} per epoch without sync_dist=True")
    assert not problems, "; ".join(dict.fromkeys(problems))
    assert any(c.hook == "validation_step" and c.name == "val/loss" for c in run.logs), (
        f"{type(run.model).__name__}.validation_step must log 'val/loss' (checkpoint monitor)"
    )
