"""``skelagnostic fit|validate|test|predict``: a pure :func:`run` under a thin Hydra wrapper.

The config tree (the repository's ``conf/``) is installed as the package
``skelagnostic.conf``, so an installed ``skelagnostic`` works from any directory.
Plugin config paths, which hold each aligner's ``model/<name>.yaml``, are added to
Hydra's search path; :func:`register_model_configs` stores the rest of each aligner's
configuration in Hydra's ConfigStore. The command is re-entrant from
``sys.argv`` alone, which Lightning's DDP launcher relies on: it re-executes
the same command line (plus ``hydra.run.dir=...``) for every extra rank.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import logging
import os
import re
import shutil
import sys
import traceback
import types
import typing
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, Literal, Union

import hydra
import lightning as L
import torch
from hydra.core.config_store import ConfigStore
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from hydra.utils import instantiate
from lightning.fabric.utilities.exceptions import MisconfigurationException
from lightning.pytorch.utilities import rank_zero_only
from lightning.pytorch.utilities.exceptions import SIGTERMException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from skelagnostic.aligners.checkpoints import (
    architecture_mismatch,
    check_architecture,
    read_checkpoint,
)
from skelagnostic.aligners.weights import is_weights
from skelagnostic.allocator import kernel_time_hint
from skelagnostic.cli.runs import (
    LOCK_FILE,
    SPLIT_FILE,
    RunDirectoryRefused,
    checkpoint_of,
    chosen_keys,
    find_run_dir,
    max_steps_overrides,
    quiet_lightning,
    read_split,
    release_run_directories,
    reuse_run_config,
    run_of_overrides,
    summary_table,
    value_of,
)
from skelagnostic.cli.signals import SIGTERM_EXIT_CODE, Terminated
from skelagnostic.core.paths import expand_home_in_override
from skelagnostic.data.datamodule import datamodule_options
from skelagnostic.errors import SkelagnosticError, error_line, printable
from skelagnostic.plugins import PluginManager, get_plugin_manager, target_of
from skelagnostic.plugins.manager import config_names

#: The verbs :func:`run` accepts as ``cfg.task``.
TASKS = ("fit", "validate", "test", "predict", "evaluate")
#: Package holding the primary config ``config.yaml``.
CONFIG_MODULE = "skelagnostic.conf"
#: Set to ``1`` (or pass ``--debug``) for full tracebacks on configuration errors.
DEBUG_ENV = "SKELAGNOSTIC_DEBUG"
#: ``ckpt_path`` values Lightning resolves itself.
_CKPT_ALIASES = ("last", "best", "hpc", "registry")
#: Provider name of the configs this module puts into Hydra's ConfigStore.
_PROVIDER = "skelagnostic"
#: Config group of the per-aligner ``model.name``, data and trainer options (internal).
ALIGNER_GROUP = "_aligner"
#: Trainer options Lightning takes without checking, then divides by.
_POSITIVE_TRAINER_KEYS = ("accumulate_grad_batches", "check_val_every_n_epoch")
#: Data-config keys that are not options of the data module or the dataset source.
_DATA_KEYS = ("source", "representation", "representation_options")


#: Largest ``seed=`` (NumPy's generators take 32-bit seeds).
MAX_SEED = 2**32 - 1


class ConfigError(SkelagnosticError):
    """A run configuration that cannot work (bad task, unknown options, missing packages)."""


class RunMetrics(dict[str, float]):
    """What :func:`run` returns: the trainer's final metrics, and why a fit ended.

    Attributes:
        stopped: For ``fit``, the limit or event that ended training (e.g.
            ``"max_steps 20 reached"``, see :func:`skelagnostic.callbacks.stop_reason`);
            ``None`` otherwise.
    """

    stopped: str | None = None


# ----------------------------------------------------------------------------- run


def _preferred_checkpoint(cfg: DictConfig) -> str | None:
    """Which checkpoint a run directory given as ``ckpt_path`` stands for.

    ``run_checkpoint=`` on the command line; else ``last`` for a resumed ``fit`` (it
    continues where the run stopped); else ``None``: the run's own choice.
    """
    chosen = cfg.get("run_checkpoint")
    if chosen is None and cfg.get("task") == "fit":
        return "last"
    return chosen


def build_datamodule(cfg: DictConfig, pm: PluginManager) -> L.LightningDataModule:
    """The data module of ``cfg.model.name`` configured by ``cfg.data``.

    Keys of ``cfg.data`` that the aligner's data module accepts go to it; the
    others (besides ``source`` and ``representation*``) are the options of the
    dataset factory registered as ``cfg.data.source``.

    Raises:
        ConfigError: A data key is accepted by neither.
        PluginError: Unknown aligner, dataset or representation.
    """
    spec = pm.aligner(cfg.model.name)
    data: dict[str, Any] = OmegaConf.to_container(cfg.data, resolve=True)  # type: ignore[assignment]
    dataset = pm.dataset(data["source"])
    dm_params = datamodule_options(spec.datamodule)  # through the subclass's **kwargs
    dm_kwargs = {k: data.pop(k) for k in list(data) if k in dm_params and k not in _DATA_KEYS}
    for owner in dict.fromkeys(dm_params[k] for k in dm_kwargs):  # typed where declared
        _check_options(
            {k: v for k, v in dm_kwargs.items() if dm_params[k] is owner},
            owner,
            "data",
            spec.datamodule.__name__,
        )
    options = {k: v for k, v in data.items() if k not in _DATA_KEYS}
    factory_params = inspect.signature(dataset.factory).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in factory_params.values()):
        unknown = sorted(set(options) - set(factory_params))
        if unknown:
            accepted = sorted(set(factory_params) | set(dm_params) - {"sources", "representation"})
            raise ConfigError(
                f"data.{unknown[0]} is not an option of data.source={data['source']!r} nor of "
                f"{spec.datamodule.__name__}; accepted: {', '.join(accepted)}"
            )
    representation = None
    if data.get("representation"):
        rep_cls = pm.representation(data["representation"]).cls
        representation = rep_cls(**(data.get("representation_options") or {}))
    made = dataset.factory(**options)  # one source, or several (data.paths entries)
    sources = list(made) if isinstance(made, (list, tuple)) else [made]
    return spec.datamodule(sources=sources, representation=representation, **dm_kwargs)


def _instantiate_all(group: DictConfig | None, what: str) -> list[Any]:
    """Instantiate each ``_target_`` node of a config group (``callbacks``, ``logger``).

    Raises:
        ConfigError: A node fails to build; the message names the node and,
            when the error mentions one of its options, that option.
    """
    out = []
    for name, node in (group or {}).items():
        if node is None:
            continue
        try:
            obj = instantiate(node)
        except Exception as exc:
            cause = exc.__cause__ or exc
            if isinstance(cause, (ImportError, ModuleNotFoundError)):
                raise ConfigError(f"{what}.{name}: {cause}") from exc
            options = {k: v for k, v in node.items() if k != "_target_"}
            key = _mentioned(str(cause), options)
            where = f"{what}.{name}" if key is None else f"{what}.{name}.{key}={options[key]!r}"
            raise ConfigError(f"{where}: {_describe(cause)}") from exc
        _check_output_dirs(obj, node, f"{what}.{name}")
        out.append(obj)
    return out


def _check_output_dirs(obj: Any, node: DictConfig, where: str) -> None:
    """Raise :class:`ConfigError` for a ``save_dir`` (logger) or ``dirpath`` (callback) not usable.

    Nothing is created: the nearest existing ancestor must be a writable directory.
    """
    for attr in ("save_dir", "dirpath"):
        value = getattr(obj, attr, None)
        if not isinstance(value, (str, Path)) or "://" in str(value):
            continue
        key = next((k for k, v in node.items() if v == value), attr)
        path = Path(value).absolute()
        existing = next(p for p in (path, *path.parents) if p.exists())
        if not existing.is_dir():
            problem = f"{str(existing)!r} is not a directory"
        elif not os.access(existing, os.W_OK | os.X_OK):
            problem = f"{str(existing)!r} is not writable"
        else:
            continue
        raise ConfigError(f"{where}.{key}={str(value)!r}: cannot write there ({problem})")


def _describe(exc: BaseException) -> str:
    """``exc`` as one line; with its type when the message alone would not say much."""
    text = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
    if isinstance(exc, (TypeError, ValueError, KeyError, ZeroDivisionError)) or not text:
        return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text


def _raised_in(exc: BaseException, where: str) -> bool:
    """Whether the innermost frame of ``exc``'s traceback is in a file under ``where``."""
    frames = traceback.extract_tb(exc.__traceback__)
    return bool(frames) and where in frames[-1].filename


def _model_error(
    exc: BaseException, name: str, options: dict[str, Any], defaults: dict[str, Any]
) -> ConfigError:
    """``exc`` of building or optimising aligner ``name``, naming the ``model.*`` values given.

    The ``model.*`` keys the command line sets are named (only those whose value
    the message quotes, if any); without any, those that differ from the aligner's
    defaults (an experiment's), else ``model=<name>``.
    """
    from hydra.core.hydra_config import HydraConfig

    given = {k: v for k, v in options.items() if k not in defaults or defaults[k] != v}
    if HydraConfig.initialized():
        keys = {o.partition("=")[0].lstrip("+~") for o in HydraConfig.get().overrides.task}
        given = {k: v for k, v in options.items() if f"model.{k}" in keys} or given
    text = str(exc)  # "Invalid learning rate: nan": the value the message quotes
    quoted = {
        k: v for k, v in given.items() if re.search(rf"(?<![\w.]){re.escape(str(v))}\b", text)
    }
    given = quoted or given
    where = ", ".join(f"model.{k}={v!r}" for k, v in given.items()) or f"model={name}"
    return ConfigError(f"{where}: the aligner {name!r} refuses it ({_describe(exc)})")


def _mentioned(text: str, options: dict[str, Any]) -> str | None:
    """The first option of ``options`` an error message names (`` `key` ``, ``key=``, ``'key'``)."""
    for key in options:
        if re.search(rf"(`{re.escape(key)}[`=(]|\b{re.escape(key)}=|'{re.escape(key)}')", text):
            return key
    return None


def _build_trainer(
    trainer_kwargs: dict[str, Any], callbacks: list[Any], loggers: list[Any], run_dir: Path
) -> L.Trainer:
    """``lightning.Trainer`` of the config; its errors name the ``trainer.<key>`` at fault.

    Lightning's messages rarely name the option (``trainer.accelerator=tpu`` fails
    with a missing package), so on failure the Trainer is built again with the
    first 1, 2, ... keys of ``cfg.trainer``: the key whose addition fails is the
    culprit. Without one, the callbacks and loggers are.

    Raises:
        ConfigError: The Trainer cannot be built.
    """
    for key in _POSITIVE_TRAINER_KEYS:
        value = trainer_kwargs.get(key)
        if isinstance(value, int) and value < 1:
            raise ConfigError(f"trainer.{key}={value!r} must be a positive integer")

    def build(kwargs: dict[str, Any]) -> L.Trainer:
        return L.Trainer(
            **kwargs,
            callbacks=list(callbacks),
            logger=loggers or False,
            default_root_dir=str(run_dir),
        )

    try:
        return build(trainer_kwargs)
    except Exception as exc:  # Lightning raises TypeError, ValueError, ImportError, ...
        where = "callbacks/logger"
        lightning_log = logging.getLogger("lightning")
        level = lightning_log.level
        lightning_log.setLevel(logging.ERROR)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                keys = list(trainer_kwargs)
                for i, key in enumerate(keys):
                    try:
                        build({k: trainer_kwargs[k] for k in keys[: i + 1]})
                    except Exception:
                        where = f"trainer.{key}={trainer_kwargs[key]!r}"
                        break
        finally:
            lightning_log.setLevel(level)
        raise ConfigError(f"{where}: {_describe(exc)}") from exc


def _name_config_key(exc: MisconfigurationException, cfg: DictConfig) -> ConfigError | None:
    """A Lightning error during the run that quotes a callback or logger option, as a ConfigError.

    For example ``ModelCheckpoint(monitor='nope')`` not finding its metric
    becomes ``callbacks.model_checkpoint.monitor='nope': ...``.
    """
    text = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
    for group in ("callbacks", "logger"):
        for name, node in (cfg.get(group) or {}).items():
            if node is None:
                continue
            for key, value in node.items():
                if (
                    key != "_target_"
                    and isinstance(value, str)
                    and value
                    and (f"{key}={value!r}" in text or f"{key}='{value}'" in text)
                ):
                    return ConfigError(f"{group}.{name}.{key}={value!r}: {text}")
    return None


def _accepts(hint: Any, value: Any) -> bool:
    """Whether ``value`` (from YAML) fits a simple type hint; other hints accept anything."""
    origin = typing.get_origin(hint)
    if origin in (Union, types.UnionType):
        return any(_accepts(h, value) for h in typing.get_args(hint))
    if origin is Literal:
        return value in typing.get_args(hint)
    if hint is type(None):
        return value is None
    if hint is bool or hint is str:
        return isinstance(value, hint)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return True  # classes, containers, ...: left to the callee


def _check_options(options: dict[str, Any], cls: type, prefix: str, owner: str) -> None:
    """Raise :class:`ConfigError` for the first option ``cls()`` does not take or cannot type.

    Args:
        options: Keyword arguments from the config.
        cls: The class they go to.
        prefix: Config path of the options (``"model"``, ``"trainer"``).
        owner: Who takes them, for the message.
    """
    params = inspect.signature(cls.__init__).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        unknown = sorted(set(options) - set(params))
        if unknown:
            accepted = sorted(
                k
                for k, p in params.items()
                if k != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
            )
            raise ConfigError(
                f"{prefix}.{unknown[0]} is not an option of {owner}; "
                f"accepted: {', '.join(accepted)}"
            )
    try:
        hints = typing.get_type_hints(cls.__init__)
    except Exception:  # unresolvable annotations: no type check
        return
    for key, value in options.items():
        if key in hints and not _accepts(hints[key], value):
            hint = hints[key]
            hint = hint.__name__ if isinstance(hint, type) else str(hint).replace("typing.", "")
            raise ConfigError(
                f"{prefix}.{key}={value!r} has the wrong type for {owner} (expected {hint})"
            )


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


def run(cfg: DictConfig, plugin_manager: PluginManager | None = None) -> RunMetrics:
    """Train or evaluate an aligner from a composed config (no Hydra needed).

    Steps: set torch's intra-op threads (``cfg.threads``, when not null), seed
    everything, build the aligner ``cfg.model.name`` (its keyword
    arguments are the other ``cfg.model`` keys) and its data module
    (:func:`build_datamodule`), the callbacks and loggers (``_target_`` nodes),
    a Lightning Trainer from ``cfg.trainer`` (``fit`` adds the plugin
    :class:`~skelagnostic.callbacks.AtomicCheckpointIO`); save the resolved config as
    ``<run_dir>/config.yaml``; then call ``trainer.<task>`` with ``cfg.ckpt_path``.
    ``predict`` also saves ``<run_dir>/predictions.pt``.

    Args:
        cfg: A config composed from ``pkg://skelagnostic.conf`` (see :func:`compose`).
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
    pm = plugin_manager or get_plugin_manager()
    task = cfg.task
    if task not in TASKS:
        raise ConfigError(f"task must be one of {', '.join(TASKS)}, got {task!r}")
    run_dir = Path(cfg.run_dir)
    ckpt = cfg.ckpt_path
    spec = pm.aligner(cfg.model.name)
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
    # an external checkpoint (a plugin's reader) is read below, once the data are built
    if external is None and ckpt and ckpt not in _CKPT_ALIASES and "://" not in str(ckpt):
        source_run = find_run_dir(ckpt)  # a run directory stands for its best/last checkpoint
        ckpt = str(checkpoint_of(ckpt, _preferred_checkpoint(cfg)))
        checkpoint = read_checkpoint(
            ckpt, spec.name, option="ckpt_path", aligners=pm.aligner_classes()
        )
    if task == "evaluate" and checkpoint is None and external is None:
        raise ConfigError(
            "evaluate: give ckpt_path=<checkpoint or run directory> of the trained model"
        )
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
    L.seed_everything(cfg.seed, workers=True)
    datamodule = build_datamodule(cfg, pm)
    if external is not None:  # evaluate a model a plugin's reader builds, on cfg.data
        from skelagnostic.cli.evaluate import evaluate_checkpoint

        aligner = pm.read_external_checkpoint(ckpt, spec.name)
        _save_config(cfg, run_dir)
        return evaluate_checkpoint(cfg, pm, spec.module, datamodule, ckpt, aligner=aligner)
    recorded = read_split(source_run) if source_run is not None else None
    if recorded is not None and hasattr(datamodule, "recorded_splits"):
        datamodule.recorded_splits = recorded  # never evaluate on the run's training clips
    model_kwargs = {
        k: v
        for k, v in OmegaConf.to_container(cfg.model, resolve=True).items()
        if k not in ("name", "_target_")
    }
    _check_options(model_kwargs, spec.module, "model", f"model={spec.name}")
    try:
        model = spec.module(**model_kwargs)
    except (ValueError, TypeError, RuntimeError) as exc:  # e.g. model.hidden=0 in torch.nn
        raise _model_error(exc, spec.name, model_kwargs, dict(spec.config)) from exc
    saved: dict[str, Any] = {}
    if checkpoint is not None:  # fail before the Trainer starts when the weights cannot fit
        check_architecture(ckpt, checkpoint, model, "ckpt_path")
        saved = dict(checkpoint.get("hyper_parameters") or {})
        if task == "evaluate":  # no trainer: a protocol on the held-out clips
            from skelagnostic.cli.evaluate import evaluate_checkpoint

            _save_config(cfg, run_dir)
            return evaluate_checkpoint(cfg, pm, spec.module, datamodule, ckpt)
        del checkpoint
    if task == "test":
        untested = recorded is not None and "test" not in recorded.values()
        _require_test_split(datamodule, source_run if untested else None)
    callbacks = _instantiate_all(cfg.get("callbacks"), "callbacks")
    stop = None
    if task == "fit":
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
        callbacks += [
            StopOnNonFinite(),
            ResumeHint(),
            LatestWithoutValidation(),
            FinalStepCheckpoint(),
            FinalStepValidation(),
            ResumeFromEpochEnd(),
            RecordSplit(run_dir),
            AdaptiveLogInterval(),
            stop,
        ]
    loggers = _instantiate_all(cfg.get("logger"), "logger")
    trainer_kwargs: dict[str, Any] = OmegaConf.to_container(cfg.trainer, resolve=True)  # type: ignore[assignment]
    _check_options(trainer_kwargs, L.Trainer, "trainer", "lightning.Trainer")
    if task == "fit":  # checkpoint files are never half-written
        from skelagnostic.callbacks import AtomicCheckpointIO

        plugins = trainer_kwargs.get("plugins") or []
        trainer_kwargs["plugins"] = [
            *(plugins if isinstance(plugins, list) else [plugins]),
            AtomicCheckpointIO(),
        ]
    trainer = _build_trainer(trainer_kwargs, callbacks, loggers, run_dir)
    _save_config(cfg, run_dir)
    # weights_only=True: a checkpoint is never unpickled into code (what skelagnostic's
    # aligners, callbacks and data loaders save is tensors and plain data).
    try:
        with architecture_mismatch(ckpt or "", saved, dict(model.hparams), "ckpt_path"):
            if task == "fit":
                trainer.fit(model, datamodule=datamodule, ckpt_path=ckpt, weights_only=True)
            elif task == "validate":
                trainer.validate(model, datamodule=datamodule, ckpt_path=ckpt, weights_only=True)
            elif task == "test":
                trainer.test(model, datamodule=datamodule, ckpt_path=ckpt, weights_only=True)
            else:
                _save_predictions(
                    trainer.predict(
                        model, datamodule=datamodule, ckpt_path=ckpt, weights_only=True
                    ),
                    run_dir,
                )
    except (ValueError, TypeError) as exc:  # e.g. model.lr=nan, refused by torch.optim
        if not _raised_in(exc, f"torch{os.sep}optim{os.sep}"):
            raise
        raise _model_error(exc, spec.name, model_kwargs, dict(spec.config)) from exc
    except MisconfigurationException as exc:
        named = _name_config_key(exc, cfg)
        if named is None:
            raise
        raise named from exc
    metrics = RunMetrics({k: float(v) for k, v in trainer.callback_metrics.items()})
    metrics.stopped = stop.reason if stop is not None else None
    return metrics


# ----------------------------------------------------------------- composition
def register_model_configs(pm: PluginManager) -> None:
    """Store each registered aligner's configs in Hydra's ConfigStore.

    For every aligner ``<name>``:

    * ``model/<name>``: ``_target_`` and the registered defaults, unless a
      registered config path ships ``model/<name>.yaml`` (Hydra reads that file,
      from which the plugin read its defaults);
    * ``_aligner/<name>`` (global package, selected by ``_aligner: ${model}`` in
      ``config.yaml``): ``model.name`` and the aligner's ``data_options`` and
      ``trainer_options``;
    * ``data/<name>`` (selected by ``data: ${model}`` unless the command line or an
      experiment names ``data=``): the aligner's default data, else ``procedural``.

    Hydra's ConfigStore is one per process: the entries stored for an earlier
    plugin manager (tagged with the provider ``skelagnostic``) are removed
    first, so it lists exactly the aligners of ``pm``.
    """
    store = ConfigStore.instance()
    for group in ("model", "data", ALIGNER_GROUP):
        nodes = store.repo.get(group, {})
        for key in [k for k, v in nodes.items() if getattr(v, "provider", None) == _PROVIDER]:
            del nodes[key]
    shipped = {name for url in pm.config_paths for name in config_names(url, "model")}
    for name, spec in pm.aligners.items():
        if name not in shipped:
            store.store(
                group="model",
                name=name,
                node={"_target_": target_of(spec.module), **dict(spec.config)},
                provider=_PROVIDER,
            )
        data: dict[str, Any] = dict(spec.data) if spec.data else {}
        base = "/data_defaults@_here_" if data else "/data/procedural@_here_"
        store.store(
            group="data", name=name, node={"defaults": [base, "_self_"], **data}, provider=_PROVIDER
        )
        node: dict[str, Any] = {"model": {"name": name}}
        if spec.data_options:
            node["data"] = dict(spec.data_options)
        if spec.trainer_options:
            node["trainer"] = dict(spec.trainer_options)
        store.store(
            group=ALIGNER_GROUP, name=name, node=node, package="_global_", provider=_PROVIDER
        )


def compose(
    overrides: Sequence[str] = (), task: str = "fit", plugin_manager: PluginManager | None = None
) -> DictConfig:
    """Compose the run config like the CLI does, for tests and notebooks.

    ``run_dir`` is not resolvable outside a Hydra run: set it, e.g.
    ``compose(["model=example", "run_dir=/tmp/run"])``.

    Args:
        overrides: Hydra overrides (``key=value``, ``group=option``, ``+key=value``).
        task: One of :data:`TASKS`.
        plugin_manager: Where aligners and config paths come from.

    Returns:
        The composed config.
    """
    pm = plugin_manager or get_plugin_manager()
    register_model_configs(pm)
    overrides = [expand_home_in_override(o) for o in overrides]
    with hydra.initialize_config_module(CONFIG_MODULE, version_base="1.3"):
        return hydra.compose(
            "config", overrides=[*_searchpath_overrides(pm, overrides), *overrides, f"task={task}"]
        )


def _searchpath_overrides(pm: PluginManager, args: Sequence[str]) -> list[str]:
    """``hydra.searchpath=[...]`` with the plugins' config paths (merged with the user's)."""
    paths = list(pm.config_paths)
    if not paths:
        return []
    for arg in args:
        if arg.split("=", 1)[0].lstrip("+~") == "hydra.searchpath":
            parsed = OverridesParser.create().parse_override(arg)
            paths = [*parsed.value(), *paths]
    quoted = ",".join(f"'{p}'" for p in dict.fromkeys(paths))
    return [f"hydra.searchpath=[{quoted}]"]


# ------------------------------------------------------------------ the CLI verbs
@contextlib.contextmanager
def _patched(argv: list[str], env: dict[str, str]) -> Iterator[None]:
    old_argv, old_env = sys.argv, {k: os.environ.get(k) for k in env}
    sys.argv = argv
    os.environ.update(env)
    try:
        yield
    finally:
        sys.argv = old_argv
        for k, v in old_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


#: Loggers that print by themselves instead of propagating to the root logger (Lightning
#: sets them up so when it is imported before logging is configured).
_OWN_HANDLER_LOGGERS = ("lightning.pytorch", "lightning.fabric")


@contextlib.contextmanager
def _job_log() -> Iterator[logging.Logger]:
    """Copy the run's log lines into Hydra's job log (``<run_dir>/app.log``) within the block.

    Hydra gives the root logger a file handler, but Lightning's loggers (``Seed set to
    42``, the data sets, the trainer's messages) print through their own handler and do
    not propagate, so the file stayed empty. Within the block the root's file handlers
    are also theirs (the console output is unchanged), and the logger yielded writes to
    the file only (the end of the run, which the console shows as a table).
    """
    files = [h for h in logging.getLogger().handlers if isinstance(h, logging.FileHandler)]
    loggers = [logging.getLogger(name) for name in _OWN_HANDLER_LOGGERS]
    quiet = logging.getLogger("skelagnostic.run")
    quiet.propagate = False
    quiet.setLevel(logging.INFO)
    added = [
        (logger, handler)
        for logger in [*[lg for lg in loggers if not lg.propagate], quiet]
        for handler in files
        if handler not in logger.handlers
    ]
    for logger, handler in added:
        logger.addHandler(handler)
    try:
        yield quiet
    finally:
        for logger, handler in added:
            logger.removeHandler(handler)


#: Files a run directory holds before it produced anything (Hydra's and ours).
_BOOKKEEPING = frozenset(
    {
        ".hydra/config.yaml",
        ".hydra/hydra.yaml",
        ".hydra/overrides.yaml",
        "app.log",
        "config.yaml",
        "csv/hparams.yaml",
        LOCK_FILE,
        SPLIT_FILE,
    }
)


def _discard_failed_run(run_dir: Path) -> str:
    """After a failure: delete ``run_dir`` if it holds only bookkeeping files.

    A run directory with anything else (checkpoints, logged metrics, renders,
    files of an earlier run) is kept so the run can be inspected or resumed.

    Returns:
        Text appended to the error line.
    """
    cwd = Path.cwd()
    if rank_zero_only.rank != 0 or not run_dir.is_dir() or run_dir.resolve() in (cwd, *cwd.parents):
        return ""
    files = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if not p.is_dir()}
    kept = sorted(f for f in files if f not in _BOOKKEEPING and not f.endswith(".log"))
    if kept:
        last = run_dir / "checkpoints" / "last.ckpt"
        hint = f"; resume with ckpt_path={last}" if last.is_file() else ""
        return f" [run directory kept: {run_dir}{hint}]"
    shutil.rmtree(run_dir, ignore_errors=True)
    return ""


def check_config_package(module: str = CONFIG_MODULE) -> None:
    """Fail with a clear message when the config package has no ``config.yaml``.

    The config tree is installed as ``skelagnostic.conf`` from the top-level
    ``conf/``. An editable checkout updated from a version that kept it in
    ``src/skelagnostic/conf/`` can keep that directory (git leaves its
    ``__pycache__``), and Python then imports it as an empty namespace package
    that hides the real one; Hydra's own message ("Cannot find primary config")
    does not say why.

    Raises:
        ConfigError: The package cannot be imported or holds no ``config.yaml``.
    """
    import importlib.util

    spec = importlib.util.find_spec(module)
    places = list(spec.submodule_search_locations or []) if spec else []
    if any((Path(place) / "config.yaml").is_file() for place in places):
        return
    where = ", ".join(places) or "nowhere"
    raise ConfigError(
        f"the config package {module} (found at {where}) has no config.yaml; if that is a "
        "leftover src/skelagnostic/conf/ directory of an older checkout, delete it (the "
        "configs now live in the top-level conf/), then reinstall with pip install -e ."
    )


@contextlib.contextmanager
def _hidden_groups_in_help(flags: Sequence[str]) -> Iterator[None]:
    """Leave the internal ``_aligner`` group out of ``--help``'s list of config groups.

    Hydra lists every group of the search path; ``_aligner/<name>`` only carries an
    aligner's data and trainer options (selected from ``model=``), so it is not a
    choice for users. Other output passes through unchanged.
    """
    if not {"--help", "-h"} & set(flags):
        yield
        return
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stdout(buffer):
            yield
    finally:
        hidden = f"{ALIGNER_GROUP}: "
        sys.stdout.write(
            "".join(
                line
                for line in buffer.getvalue().splitlines(keepends=True)
                if not line.startswith(hidden)
            )
        )


def split_hydra_flags(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split a command line into Hydra's flags (with their values) and its overrides.

    Hydra parses ``sys.argv`` with argparse, which takes the overrides as one
    contiguous run of positional arguments; the CLI adds overrides of its own
    (``task=<verb>``, the plugins' search path), so it re-orders the user's
    arguments as flags first, overrides after. Flags and their arity come from
    Hydra's own argument parser: ``--cfg job``, ``--cfg=job``, ``-m``,
    ``--info`` with or without a value, ...

    Args:
        args: The arguments after the verb, in the user's order.

    Returns:
        ``(flags, overrides)``, each in the user's order.

    Example:
        >>> split_hydra_flags(["model=example", "--cfg", "job", "-m", "seed=1,2"])
        (['--cfg', 'job', '-m'], ['model=example', 'seed=1,2'])
    """
    from hydra._internal.utils import get_args_parser

    actions = get_args_parser()._option_string_actions
    flags: list[str] = []
    overrides: list[str] = []
    tokens = list(args)
    i = 0
    while i < len(tokens):
        token = tokens[i]
        i += 1
        name = token.split("=", 1)[0]
        if not token.startswith("-") or name not in actions:
            overrides.append(token)
            continue
        flags.append(token)
        action = actions[name]
        if "=" in token or action.nargs == 0:
            continue
        takes_value = action.nargs is None or (
            action.nargs == "?"
            and i < len(tokens)
            and (action.choices is None or tokens[i] in action.choices)
        )
        if takes_value and i < len(tokens):
            flags.append(tokens[i])
            i += 1
    return flags, overrides


#: Hydra flags that show something instead of running a job.
_INFO_FLAGS = frozenset(
    {"--help", "-h", "--cfg", "-c", "--info", "-i", "--shell-completion", "-sc"}
)


def _informational(flags: Sequence[str]) -> bool:
    return any(f.split("=", 1)[0] in _INFO_FLAGS for f in flags)


def _failed_plugins(pm: PluginManager | None) -> str:
    if pm is None:
        return ""
    failed = [f"{p.name} ({p.error})" for p in pm.plugins() if p.status == "failed"]
    return f" [plugins that failed to load: {'; '.join(failed)}]" if failed else ""


def _one_line(exc: BaseException) -> str:
    r"""The error as one message: Hydra's lines joined, without its config search path.

    A :class:`SkelagnosticError` is kept whole: a line end in it comes from a
    name (a file, a joint, a value), and :func:`~skelagnostic.errors.error_line`
    shows it as ``\n``. A system error (errno set) names its file and cause.
    """
    # a system error (errno set); Hydra's MissingConfigException is an OSError without one
    if isinstance(exc, OSError) and exc.errno is not None:
        where = f" ({exc.filename})" if exc.filename else ""
        return f"cannot read or write a file{where}: {exc.strerror or exc}"
    if isinstance(exc, SkelagnosticError):
        text = str(exc)
    else:
        text = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        text = text.split(" Config search path:")[0]
    cause = exc.__cause__
    if isinstance(cause, OmegaConfBaseException) and str(cause).splitlines()[0] not in text:
        text += f" ({str(cause).splitlines()[0]})"
    return text


def main(task: str, argv: Sequence[str]) -> int:
    """Run one verb with Hydra command-line overrides.

    ``--debug`` (or ``SKELAGNOSTIC_DEBUG=1``) shows full tracebacks; otherwise
    configuration errors and :class:`~skelagnostic.errors.SkelagnosticError`
    print one line to stderr and return exit code 1. The line also names the
    plugins that failed to load, if any. A failed run's directory is deleted
    when it holds nothing but the resolved configs and logs; otherwise it is
    kept (and the line says where, with the checkpoint to resume from). A
    run stopped by SIGTERM returns :data:`SIGTERM_EXIT_CODE`.

    Args:
        task: One of :data:`TASKS`.
        argv: The arguments after the verb.

    Returns:
        The exit code.
    """
    cpu_start = _cpu_times()
    args = [a for a in argv if a != "--debug"]
    debug = len(args) != len(argv) or os.environ.get(DEBUG_ENV, "") not in {"", "0"}
    outer_argv = list(sys.argv)
    pm: PluginManager | None = None
    run_dirs: list[Path] = []
    try:
        pm = get_plugin_manager()
        register_model_configs(pm)
        flags, overrides = split_hydra_flags(args)
        overrides = [expand_home_in_override(o) for o in overrides]  # data.paths=[~/mocap]
        if not _informational(flags):  # Hydra would create an unusable run directory first
            from skelagnostic.cli.locations import check_run_locations

            check_run_locations(overrides)
        # Hydra's argparse takes its overrides as one run of positional arguments:
        # flags first, then ours and the user's overrides (user's last, so they win).
        # The plugins' config trees come from the search-path plugin in
        # hydra_plugins/skelagnostic_searchpath (so --help lists their options).
        ours = [f"task={task}"]
        if _informational(flags) and not any(
            o.split("=", 1)[0].lstrip("+") in ("model", "experiment") for o in overrides
        ):
            ours.append("~model")  # --help / --cfg / --info work before a model is chosen
        saved = run_of_overrides(overrides)
        external = pm.checkpoint_reader_of(value_of(overrides, "ckpt_path") or "")
        if saved is not None and not chosen_keys(overrides) & {"model", "experiment"}:
            ours.append(f"model={saved.model.name}")  # the run's aligner, e.g. for test
        elif external is not None and not chosen_keys(overrides) & {"model", "experiment"}:
            ours.append(f"model={external[0].model}")  # the model the reader builds
        ours += max_steps_overrides(overrides)
        hydra_args = [*flags, *ours, *overrides]
        if "--hydra-help" in flags:  # Hydra's own help: no app config, no overrides
            hydra_args = flags

        failures: list[Exception] = []
        terminated: list[bool] = []

        results: list[tuple[Path, dict[str, float], Path | None]] = []

        def task_function(cfg: DictConfig) -> None:
            run_dirs.append(Path(cfg.run_dir))
            if saved is not None:
                reuse_run_config(cfg, saved, overrides)
            # Lightning's DDP launcher re-executes sys.argv
            with _patched(outer_argv, {}), _job_log() as job_log:
                try:
                    metrics = run(cfg, pm)
                    if getattr(metrics, "stopped", None):
                        job_log.info("stopped: %s", metrics.stopped)  # type: ignore[attr-defined]
                    job_log.info(
                        "final metrics: %s",
                        ", ".join(f"{k}={v:.5g}" for k, v in sorted(metrics.items())) or "none",
                    )
                    ckpt = (
                        checkpoint_of(cfg.ckpt_path, _preferred_checkpoint(cfg))
                        if cfg.ckpt_path
                        and task != "fit"
                        and cfg.ckpt_path not in _CKPT_ALIASES
                        and pm.checkpoint_reader_of(cfg.ckpt_path) is None
                        else None
                    )
                    results.append((Path(cfg.run_dir), metrics, ckpt))
                except (SkelagnosticError, MisconfigurationException, HydraException) as exc:
                    failures.append(exc)  # re-raised below, after Hydra cleaned up
                except SIGTERMException:  # a SystemExit with status 0: report it as a failure
                    terminated.append(True)

        check_config_package()
        entry = hydra.main(
            config_path=f"pkg://{CONFIG_MODULE}", config_name="config", version_base="1.3"
        )(task_function)
        with _patched([outer_argv[0], *hydra_args], {"HYDRA_FULL_ERROR": "1"}), quiet_lightning():
            try:
                with _hidden_groups_in_help(flags):
                    entry()
            except SystemExit as exc:  # Hydra exits by itself after --help and --hydra-help
                if exc.code not in (0, None) or failures or terminated or run_dirs:
                    raise
                return 0
        if failures:
            raise failures[0]
        if terminated:
            kept = "".join(_discard_failed_run(d) for d in run_dirs)
            print(printable(f"skelagnostic {task}: terminated by SIGTERM{kept}"), file=sys.stderr)
            return SIGTERM_EXIT_CODE
        for run_dir, metrics, ckpt in results:  # evaluate printed its own table
            summary_table(
                task,
                run_dir,
                {} if task == "evaluate" else metrics,
                checkpoint=ckpt,
                stopped=getattr(metrics, "stopped", None),
            )
        if task == "fit":  # this command's CPU time, not the process's (tests, notebooks)
            (user, system), (user0, system0) = _cpu_times(), cpu_start
            if (hint := kernel_time_hint(user - user0, system - system0)) is not None:
                print(f"skelagnostic fit: hint: {hint}", file=sys.stderr)
    except (
        SkelagnosticError,
        HydraException,
        OmegaConfBaseException,
        MisconfigurationException,
        OSError,  # e.g. a full disk while Hydra writes the run folder's .hydra/ files
    ) as exc:
        kept = "".join(_discard_failed_run(d) for d in run_dirs)
        if debug:
            raise
        message = f"{_one_line(exc)}{_failed_plugins(pm)}{kept}"
        print(error_line(f"skelagnostic {task}", message), file=sys.stderr)
        return 1
    except Terminated:  # SIGTERM outside training (e.g. building the window cache)
        kept = "".join(_discard_failed_run(d) for d in run_dirs)
        print(printable(f"skelagnostic {task}: terminated by SIGTERM{kept}"), file=sys.stderr)
        return SIGTERM_EXIT_CODE
    except RunDirectoryRefused as exc:  # before Hydra wrote anything: nothing to discard
        if debug:
            raise
        print(error_line(f"skelagnostic {task}", exc), file=sys.stderr)
        return 1
    finally:
        release_run_directories()
    return 0


def _cpu_times() -> tuple[float, float]:
    """This process's user and system CPU time so far (seconds; zeros without ``resource``)."""
    try:
        import resource
    except ImportError:  # not POSIX
        return 0.0, 0.0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime, usage.ru_stime


def fit(argv: Sequence[str]) -> int:
    """``skelagnostic fit model=<name> [overrides]``: train."""
    return main("fit", argv)


def validate(argv: Sequence[str]) -> int:
    """``skelagnostic validate model=<name> ckpt_path=<ckpt> [overrides]``."""
    return main("validate", argv)


def test(argv: Sequence[str]) -> int:
    """``skelagnostic test model=<name> ckpt_path=<ckpt> [overrides]``."""
    return main("test", argv)


def predict(argv: Sequence[str]) -> int:
    """``skelagnostic predict model=<name> ckpt_path=<ckpt>``: latents to ``predictions.pt``."""
    return main("predict", argv)
