"""One function per verb: ``fit``, ``validate``, ``test``, ``predict``, ``evaluate``.

Each task function takes a composed config and returns the run's metrics; it
needs no Hydra run, so tests and notebooks call it directly::

    from skelagnostic.cli.app import compose
    from skelagnostic.cli.tasks import fit

    metrics = fit(compose(["model=example", "experiment=smoke", "run_dir=/tmp/run"]))

The CLI verbs (:func:`skelagnostic.cli.app.main`) are a thin Hydra wrapper
around :func:`run`, which calls the function of ``cfg.task``. The functions
share the steps of a run: check the run options, resolve ``ckpt_path``, build
the data module, the aligner and the trainer (:mod:`skelagnostic.cli.build`),
then call ``trainer.<verb>`` (or, for ``evaluate``, the protocol).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.utilities import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from skelagnostic.aligners.checkpoints import (
    architecture_mismatch,
    check_architecture,
    read_checkpoint,
)
from skelagnostic.aligners.weights import is_weights
from skelagnostic.cli.build import (
    ConfigError,
    build_datamodule,
    build_model,
    build_trainer,
    check_options,
    config_errors,
    instantiate_all,
)
from skelagnostic.cli.evaluate import evaluate_checkpoint
from skelagnostic.cli.runs import checkpoint_of, find_run_dir, read_split
from skelagnostic.plugins import AlignerSpec, PluginManager, get_plugin_manager

__all__ = [
    "MAX_SEED",
    "TASKS",
    "RunMetrics",
    "evaluate",
    "fit",
    "predict",
    "run",
    "test",
    "validate",
]

#: The verbs :func:`run` accepts as ``cfg.task``.
TASKS = ("fit", "validate", "test", "predict", "evaluate")
#: ``ckpt_path`` values Lightning resolves itself.
CKPT_ALIASES = ("last", "best", "hpc", "registry")
#: Largest ``seed=`` (NumPy's generators take 32-bit seeds).
MAX_SEED = 2**32 - 1


class RunMetrics(dict[str, float]):
    """What a task function returns: the trainer's final metrics, and why a fit ended.

    Attributes:
        stopped: For ``fit``, the limit or event that ended training (e.g.
            ``"max_steps 20 reached"``, see :func:`skelagnostic.callbacks.stop_reason`);
            ``None`` otherwise.
    """

    stopped: str | None = None


@dataclass
class _Run:
    """What every task builds before it runs: the aligner's spec, the checkpoint, the data.

    Attributes:
        spec: The aligner of ``cfg.model.name``.
        ckpt: The checkpoint to resume or evaluate (a file, an alias, a URL, or the
            ``<scheme>:<path>`` of a plugin's reader), or ``None``.
        checkpoint: The checkpoint file's contents, read to check it before training.
        source_run: The run directory ``ckpt`` belongs to, if any.
        recorded: The clip split that run recorded (``clip id -> split``), if any.
        external: Whether a plugin's checkpoint reader reads ``ckpt``.
        datamodule: The data module of ``cfg.data``.
    """

    spec: AlignerSpec
    ckpt: str | None
    checkpoint: dict[str, Any] | None
    source_run: Path | None
    recorded: dict[str, str] | None
    external: bool
    datamodule: L.LightningDataModule


# ----------------------------------------------------------------------- the tasks


def fit(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Train the aligner ``cfg.model.name`` on ``cfg.data`` (resume from ``cfg.ckpt_path``).

    Besides the config's callbacks, a fit gets those that make a run safe to stop
    and resume (:mod:`skelagnostic.callbacks`): non-finite losses stop it, the
    last step is checkpointed and validated, the clip split is recorded
    (``split.json``), and checkpoints are written atomically.

    Returns:
        The final metrics; ``stopped`` says which limit or event ended training.
    """
    from skelagnostic.callbacks import (
        AdaptiveLogInterval,
        FinalStepCheckpoint,
        FinalStepValidation,
        LatestWithoutValidation,
        RecordSplit,
        ResumeFromEpochEnd,
        ResumeHint,
        StopOnNonFinite,
        StopReason,
    )

    stop = StopReason()
    safety = [
        StopOnNonFinite(),
        ResumeHint(),
        LatestWithoutValidation(),
        FinalStepCheckpoint(),
        FinalStepValidation(),
        ResumeFromEpochEnd(),
        RecordSplit(cfg.run_dir),
        AdaptiveLogInterval(),
        stop,
    ]
    metrics = _run_trainer(cfg, "fit", plugin_manager, safety)
    metrics.stopped = stop.reason
    return metrics


def validate(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Evaluate ``cfg.ckpt_path`` (or untrained weights) on the validation split."""
    return _run_trainer(cfg, "validate", plugin_manager)


def test(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Evaluate ``cfg.ckpt_path`` on the test split.

    Raises:
        ConfigError: The data have no test clip (the run's recorded split has none).
    """
    return _run_trainer(cfg, "test", plugin_manager)


def predict(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Run the aligner of ``cfg.ckpt_path`` on the data; saves ``<run_dir>/predictions.pt``."""
    return _run_trainer(cfg, "predict", plugin_manager)


def evaluate(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Run the protocol ``cfg.protocol`` on the held-out clips of the checkpoint's run.

    No trainer: the aligner is loaded from ``cfg.ckpt_path`` (a checkpoint, a run
    directory, or ``<scheme>:<path>`` of a plugin's checkpoint reader) and the
    protocol writes ``evaluation.json``/``.md`` into ``cfg.run_dir``
    (:func:`skelagnostic.cli.evaluate.evaluate_checkpoint`).

    Returns:
        The model's mean figures, ``model/<metric>``.

    Raises:
        ConfigError: No ``ckpt_path``.
    """
    pm = plugin_manager or get_plugin_manager()
    prepared = _prepare(cfg, "evaluate", pm)
    spec, ckpt, run_dir = prepared.spec, prepared.ckpt, Path(cfg.run_dir)
    if prepared.external:  # a model a plugin's reader builds, evaluated on cfg.data
        aligner = pm.read_external_checkpoint(ckpt, spec.name)
        _save_config(cfg, run_dir)
        figures = evaluate_checkpoint(cfg, pm, spec.module, prepared.datamodule, ckpt, aligner)
        return RunMetrics(figures)
    assert prepared.checkpoint is not None and ckpt is not None  # _prepare refuses no ckpt_path
    model, _ = build_model(cfg, spec)
    check_architecture(ckpt, prepared.checkpoint, model, "ckpt_path")
    _save_config(cfg, run_dir)
    return RunMetrics(evaluate_checkpoint(cfg, pm, spec.module, prepared.datamodule, ckpt))


#: The task function of each verb.
TASK_FUNCTIONS: dict[str, Callable[[DictConfig, PluginManager | None], RunMetrics]] = {
    "fit": fit,
    "validate": validate,
    "test": test,
    "predict": predict,
    "evaluate": evaluate,
}


def run(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Run the task ``cfg.task`` of a composed config (no Hydra needed).

    Every task sets torch's intra-op threads (``cfg.threads``, when not null),
    seeds everything, builds the aligner ``cfg.model.name`` (its keyword
    arguments are the other ``cfg.model`` keys) and its data module
    (:func:`~skelagnostic.cli.build.build_datamodule`), the callbacks and loggers
    (``_target_`` nodes), a Lightning Trainer from ``cfg.trainer`` (``fit`` adds the
    plugin :class:`~skelagnostic.callbacks.AtomicCheckpointIO`); saves the resolved
    config as ``<run_dir>/config.yaml``; then calls ``trainer.<task>`` with
    ``cfg.ckpt_path``. ``predict`` also saves ``<run_dir>/predictions.pt``;
    ``evaluate`` runs a protocol instead (:func:`evaluate`).

    Args:
        cfg: A config composed from ``pkg://skelagnostic.conf``
            (see :func:`skelagnostic.cli.app.compose`).
        plugin_manager: Where aligners and datasets are looked up (default: the
            process-wide one).

    Returns:
        The trainer's final ``callback_metrics`` as floats (a :class:`RunMetrics`,
        whose ``stopped`` says why a fit ended).

    Raises:
        ConfigError: Unknown task, a model or
            trainer option the aligner or ``lightning.Trainer`` does not take (or
            of the wrong type), or another config that cannot work.
        PluginError: Unknown aligner, dataset or representation.
        CheckpointError: ``ckpt_path`` is missing, not a readable checkpoint,
            refused by the safe loader (checkpoints are loaded with
            ``weights_only=True``), written by another model or of a different
            architecture.
    """
    task = cfg.task
    if task not in TASK_FUNCTIONS:
        raise ConfigError(f"task must be one of {', '.join(TASKS)}, got {task!r}")
    return TASK_FUNCTIONS[task](cfg, plugin_manager)


# ------------------------------------------------------------- shared steps


def _preferred_checkpoint(cfg: DictConfig, task: str | None = None) -> str | None:
    """Which checkpoint a run directory given as ``ckpt_path`` stands for.

    ``run_checkpoint=`` on the command line; else ``last`` for a resumed ``fit`` (it
    continues where the run stopped); else ``None``: the run's own choice.

    Args:
        cfg: The composed config.
        task: The verb (default: ``cfg.task``).
    """
    chosen = cfg.get("run_checkpoint")
    if chosen is None and (task or cfg.get("task")) == "fit":
        return "last"
    return chosen


def _check_run_options(cfg: DictConfig, task: str) -> None:
    """Check ``seed``, ``threads`` and (fit) ``summary``; apply ``threads``.

    Raises:
        ConfigError: A value out of range or of the wrong type.
    """
    if cfg.seed is not None and (not isinstance(cfg.seed, int) or isinstance(cfg.seed, bool)):
        raise ConfigError(f"seed must be an integer, got {cfg.seed!r}")
    if cfg.seed is not None and not 0 <= cfg.seed <= MAX_SEED:
        raise ConfigError(f"seed must be from 0 to {MAX_SEED}, got {cfg.seed}")
    threads = cfg.get("threads")
    if threads is not None:
        if not isinstance(threads, int) or threads < 1:
            raise ConfigError(f"threads must be a positive integer or null, got {threads!r}")
        from skelagnostic.cli.render import check_threads

        torch.set_num_threads(check_threads(threads))  # refuses more than 4 per core
    if task == "fit" and cfg.get("summary") is not None:  # before the data is read
        from skelagnostic.callbacks.fit_summary import SUMMARY_MODES

        if cfg.summary not in SUMMARY_MODES:
            raise ConfigError(f"summary={cfg.summary!r}: must be one of {', '.join(SUMMARY_MODES)}")


def _prepare(cfg: DictConfig, task: str, pm: PluginManager) -> _Run:
    """The steps every task takes first: resolve and read ``ckpt_path``, seed, build the data.

    A run directory given as ``ckpt_path`` stands for one of its checkpoints, and
    the data module keeps that run's recorded split (never evaluating on its
    training clips). A checkpoint is read (and refused if it is another model's)
    before anything is built.

    Raises:
        ConfigError: A plugin's checkpoint for a verb other than ``evaluate``, or a
            run option that cannot work.
    """
    spec = pm.aligner(cfg.model.name)
    ckpt = cfg.ckpt_path
    checkpoint: dict[str, Any] | None = None
    source_run: Path | None = None
    external = pm.checkpoint_reader_of(ckpt) if ckpt else None
    if external is not None and task != "evaluate":
        raise ConfigError(
            f"ckpt_path={ckpt!r} (checkpoint reader {external[0].name!r}) is "
            f"read by evaluate and the inference verbs, not by {task}"
        )
    if ckpt and task != "evaluate" and is_weights(ckpt):  # export format=safetensors
        raise ConfigError(
            f"ckpt_path={ckpt!r} is a weights file (export format=safetensors), read by "
            f"evaluate and the inference verbs; {task} needs a run's Lightning checkpoint"
        )
    # an external checkpoint (a plugin's reader) is read by evaluate, once the data are built
    if external is None and ckpt and ckpt not in CKPT_ALIASES and "://" not in str(ckpt):
        source_run = find_run_dir(ckpt)  # a run directory stands for its best/last checkpoint
        ckpt = str(checkpoint_of(ckpt, _preferred_checkpoint(cfg, task)))
        checkpoint = read_checkpoint(
            ckpt, spec.name, option="ckpt_path", aligners=pm.aligner_classes()
        )
    if task == "evaluate" and checkpoint is None and external is None:
        raise ConfigError(
            "evaluate: give ckpt_path=<checkpoint or run directory> of the trained model"
        )
    _check_run_options(cfg, task)
    L.seed_everything(cfg.seed, workers=True)
    datamodule = build_datamodule(cfg, pm)
    recorded = read_split(source_run) if source_run is not None and external is None else None
    if recorded is not None and hasattr(datamodule, "recorded_splits"):
        datamodule.recorded_splits = recorded  # never evaluate on the run's training clips
    return _Run(spec, ckpt, checkpoint, source_run, recorded, external is not None, datamodule)


def _run_trainer(
    cfg: DictConfig,
    task: str,
    plugin_manager: PluginManager | None,
    extra_callbacks: Sequence[L.Callback] = (),
) -> RunMetrics:
    """Build the run's pieces and call ``trainer.<task>`` (fit, validate, test, predict).

    Args:
        cfg: The composed config.
        task: The verb, the name of the trainer's method.
        plugin_manager: Where aligners and datasets are looked up.
        extra_callbacks: Added after the config's callbacks (``fit``'s safety net).

    Returns:
        The trainer's final ``callback_metrics`` as floats.
    """
    from skelagnostic.callbacks.loggers import finished_runs

    pm = plugin_manager or get_plugin_manager()
    prepared = _prepare(cfg, task, pm)
    spec, ckpt, run_dir = prepared.spec, prepared.ckpt, Path(cfg.run_dir)
    model, model_kwargs = build_model(cfg, spec)
    saved: dict[str, Any] = {}
    if prepared.checkpoint is not None:  # fail before the Trainer starts when weights cannot fit
        check_architecture(ckpt, prepared.checkpoint, model, "ckpt_path")
        saved = dict(prepared.checkpoint.get("hyper_parameters") or {})
        prepared.checkpoint = None  # the trainer reads the file again
    if task == "test":
        recorded = prepared.recorded
        untested = recorded is not None and "test" not in recorded.values()
        _require_test_split(prepared.datamodule, prepared.source_run if untested else None)
    trainer = _trainer(cfg, task, extra_callbacks)
    _save_config(cfg, run_dir)
    # weights_only=True: a checkpoint is never unpickled into code (what skelagnostic's
    # aligners, callbacks and data loaders save is tensors and plain data).
    with (
        finished_runs(trainer.loggers),
        config_errors(cfg, spec, model_kwargs),
        architecture_mismatch(ckpt or "", saved, dict(model.hparams), "ckpt_path"),
    ):
        output = getattr(trainer, task)(
            model, datamodule=prepared.datamodule, ckpt_path=ckpt, weights_only=True
        )
    if task == "predict":
        _save_predictions(output, run_dir)
    return RunMetrics({k: float(v) for k, v in trainer.callback_metrics.items()})


def _trainer(cfg: DictConfig, task: str, extra_callbacks: Sequence[L.Callback]) -> L.Trainer:
    """The Lightning Trainer of ``cfg.trainer``, with the config's callbacks and loggers.

    ``fit`` adds the plugin :class:`~skelagnostic.callbacks.AtomicCheckpointIO`
    (checkpoint files are never half-written).

    Raises:
        ConfigError: A trainer, callback or logger option that cannot work.
    """
    callbacks = [*instantiate_all(cfg.get("callbacks"), "callbacks"), *extra_callbacks]
    loggers = instantiate_all(cfg.get("logger"), "logger")
    trainer_kwargs: dict[str, Any] = OmegaConf.to_container(cfg.trainer, resolve=True)  # type: ignore[assignment]
    check_options(trainer_kwargs, L.Trainer, "trainer", "lightning.Trainer")
    if task == "fit":
        from skelagnostic.callbacks import AtomicCheckpointIO

        plugins = trainer_kwargs.get("plugins") or []
        trainer_kwargs["plugins"] = [
            *(plugins if isinstance(plugins, list) else [plugins]),
            AtomicCheckpointIO(),
        ]
    return build_trainer(trainer_kwargs, callbacks, loggers, Path(cfg.run_dir))


def _require_test_split(datamodule: L.LightningDataModule, run_dir: Path | None = None) -> None:
    """Raise :class:`ConfigError` when the data module has no test clip (``test`` would do nothing).

    Only for data modules that expose their splits (``datasets["test"]``).

    Args:
        datamodule: The data module (set up here).
        run_dir: The run whose recorded split the data module keeps, if any: its
            training and validation clips are never test clips.
    """
    if not hasattr(datamodule, "datasets"):
        return
    datamodule.setup("test")
    if any(len(ds) for ds in datamodule.datasets.get("test", {}).values()):
        return
    if run_dir is not None:
        raise ConfigError(
            f"test: the run {run_dir} has no test split (it was fitted with "
            "data.test_fraction=0 and no test clip; its validation clips chose its "
            "checkpoint, so they are not held out): use validate, or fit again with "
            "data.test_fraction=0.2 (or data.test_pattern=REGEX) and test that run"
        )
    raise ConfigError(
        "test: the test split is empty (data.test_fraction=0 and no clip matches a test "
        "pattern); set data.test_fraction>0 or data.test_pattern=REGEX, or use validate"
    )


@rank_zero_only
def _save_config(cfg: DictConfig, run_dir: Path) -> None:
    from skelagnostic.io.outputs import write_output

    write_output(run_dir / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True))


@rank_zero_only
def _save_predictions(predictions: Any, run_dir: Path) -> None:
    from skelagnostic.io.outputs import write_output

    write_output(run_dir / "predictions.pt", lambda fh: torch.save(predictions, fh))
