"""The pieces of a run, built from a composed config: data module, model, trainer, callbacks.

Each builder names the config key at fault when it cannot build its piece: a
:class:`ConfigError` such as ``data.bogus is not an option of ...`` or
``trainer.accelerator='tpu': ...``. The task functions of
:mod:`skelagnostic.cli.tasks` put them together.
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import re
import traceback
import types
import typing
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Literal, Union

import lightning as L
from hydra.utils import instantiate
from lightning.fabric.utilities.exceptions import MisconfigurationException
from omegaconf import DictConfig, OmegaConf

from skelagnostic.data.datamodule import datamodule_options
from skelagnostic.errors import ConfigError
from skelagnostic.plugins import AlignerSpec, PluginManager

__all__ = [
    "ConfigError",
    "build_datamodule",
    "build_model",
    "build_trainer",
    "check_options",
    "config_error_of",
    "config_errors",
    "instantiate_all",
    "model_error",
    "source_keys",
]

#: Trainer options Lightning takes without checking, then divides by.
_POSITIVE_TRAINER_KEYS = ("accumulate_grad_batches", "check_val_every_n_epoch")
#: Classes a config group may name that need an optional extra of the distribution.
OPTIONAL_EXTRAS = {
    "lightning.pytorch.loggers.WandbLogger": "wandb",
    "lightning.pytorch.loggers.MLFlowLogger": "mlflow",
    "skelagnostic.callbacks.LocalMLFlowLogger": "mlflow",
}
#: Data-config keys that say where the others go: to neither the source nor the data module.
ROUTING_KEYS = ("source", "source_keys", "representation", "representation_options")


def source_keys(data: dict[str, Any], spec: AlignerSpec) -> list[str]:
    """The keys of a data config that are options of its ``source``, as the config says.

    ``data.source_keys`` lists them (each preset of ``conf/data/`` declares its
    own). Without it (``null``: an aligner's registered default data, a config
    saved before the key existed), they are the keys of the aligner's default
    data (``register_aligners(data=...)``). The aligner's ``data_options`` are
    data-module keys in any case.

    Args:
        data: The resolved ``cfg.data``.
        spec: The aligner of ``cfg.model.name``.

    Returns:
        The source's keys that ``data`` holds, in the config's order.
    """
    declared = data.get("source_keys")
    if declared is None:
        declared = [k for k in (spec.data or {}) if k != "source"]
    elif not isinstance(declared, list) or not all(isinstance(k, str) for k in declared):
        raise ConfigError(f"data.source_keys must be a list of key names, got {declared!r}")
    module_keys = set(spec.data_options or {})
    return [k for k in data if k in declared and k not in module_keys and k not in ROUTING_KEYS]


def build_datamodule(cfg: DictConfig, pm: PluginManager) -> L.LightningDataModule:
    """The data module of ``cfg.model.name`` configured by ``cfg.data``.

    The data config routes its keys explicitly: ``data.source`` names the dataset
    and the keys listed in ``data.source_keys`` (:func:`source_keys`) are its
    options; ``data.representation`` (+ ``representation_options``) names the
    features; every other key is an option of the aligner's data module.

    Raises:
        ConfigError: A data key is accepted by neither its source nor the data
            module, or has the wrong type.
        PluginError: Unknown aligner, dataset or representation.
    """
    spec = pm.aligner(cfg.model.name)
    data: dict[str, Any] = OmegaConf.to_container(cfg.data, resolve=True)  # type: ignore[assignment]
    dataset = pm.dataset(data["source"])
    options = {k: data[k] for k in source_keys(data, spec)}
    dm_kwargs = {k: v for k, v in data.items() if k not in options and k not in ROUTING_KEYS}
    _check_routed(options, dm_kwargs, dataset.factory, spec.datamodule, data["source"])
    representation = None
    if data.get("representation"):
        rep_cls = pm.representation(data["representation"]).cls
        representation = rep_cls(**(data.get("representation_options") or {}))
    made = dataset.factory(**options)  # one source, or several (data.paths entries)
    sources = list(made) if isinstance(made, (list, tuple)) else [made]
    return spec.datamodule(sources=sources, representation=representation, **dm_kwargs)


def _check_routed(
    options: dict[str, Any], dm_kwargs: dict[str, Any], factory: Any, datamodule: type, source: str
) -> None:
    """Raise :class:`ConfigError` for a routed key its receiver does not take (or cannot type).

    The signatures only check the keys here; where a key goes is the config's choice.
    """
    dm_params = datamodule_options(datamodule)  # through the subclass's **kwargs
    factory_params = inspect.signature(factory).parameters
    takes_any = any(p.kind is p.VAR_KEYWORD for p in factory_params.values())
    unknown = sorted(set(dm_kwargs) - set(dm_params))
    unknown += sorted(k for k in options if not takes_any and k not in factory_params)
    if unknown:
        accepted = sorted(set(factory_params) | set(dm_params) - {"sources", "representation"})
        raise ConfigError(
            f"data.{unknown[0]} is not an option of data.source={source!r} nor of "
            f"{datamodule.__name__}; accepted: {', '.join(accepted)}"
        )
    for owner in dict.fromkeys(dm_params[k] for k in dm_kwargs):  # typed where declared
        check_options(
            {k: v for k, v in dm_kwargs.items() if dm_params[k] is owner},
            owner,
            "data",
            datamodule.__name__,
        )


def build_model(cfg: DictConfig, spec: AlignerSpec) -> tuple[L.LightningModule, dict[str, Any]]:
    """The aligner ``spec`` built from ``cfg.model`` (its keys but ``name`` and ``_target_``).

    Returns:
        The aligner and the keyword arguments it was built with.

    Raises:
        ConfigError: An option the aligner does not take, of the wrong type, or refused.
    """
    container: dict[str, Any] = OmegaConf.to_container(cfg.model, resolve=True)  # type: ignore[assignment]
    kwargs = {k: v for k, v in container.items() if k not in ("name", "_target_")}
    check_options(kwargs, spec.module, "model", f"model={spec.name}")
    try:
        return spec.module(**kwargs), kwargs
    except (ValueError, TypeError, RuntimeError) as exc:  # e.g. model.hidden=0 in torch.nn
        raise model_error(exc, spec.name, kwargs, dict(spec.config)) from exc


@contextlib.contextmanager
def config_errors(
    cfg: DictConfig, spec: AlignerSpec, model_kwargs: dict[str, Any]
) -> Iterator[None]:
    """Within the block (the trainer's run): errors caused by a config value name its key.

    A ``ValueError``/``TypeError`` raised by ``torch.optim`` (``model.optimizer.lr=nan``) names
    the ``model.*`` values; a Lightning misconfiguration that quotes a callback or
    logger option names that option (:func:`config_error_of`).
    """
    try:
        yield
    except (ValueError, TypeError) as exc:
        if not _raised_in(exc, f"torch{os.sep}optim{os.sep}"):
            raise
        raise model_error(exc, spec.name, model_kwargs, dict(spec.config)) from exc
    except MisconfigurationException as exc:
        named = config_error_of(exc, cfg)
        if named is None:
            raise
        raise named from exc


def instantiate_all(group: DictConfig | None, what: str) -> list[Any]:
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
                extra = OPTIONAL_EXTRAS.get(str(node.get("_target_")))
                hint = f"; install it with pip install 'skelagnostic[{extra}]'" if extra else ""
                raise ConfigError(f"{what}.{name}: {cause}{hint}") from exc
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


def model_error(
    exc: BaseException, name: str, options: dict[str, Any], defaults: dict[str, Any]
) -> ConfigError:
    """``exc`` of building or optimising aligner ``name``, naming the ``model.*`` values given.

    The ``model.*`` keys the command line sets are named (only those whose value
    the message quotes, if any); without any, those that differ from the aligner's
    defaults (an experiment's), else ``model=<name>``. Nested options are named by
    their dotted key (``model.optimizer.lr``).
    """
    from hydra.core.hydra_config import HydraConfig

    options, defaults = _dotted(options), _dotted(defaults)
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


def _dotted(options: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"optimizer": {"lr": 1}}`` -> ``{"optimizer.lr": 1}`` (mappings only; lists stay)."""
    out: dict[str, Any] = {}
    for key, value in options.items():
        if isinstance(value, Mapping) and value:
            out.update(_dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _mentioned(text: str, options: dict[str, Any]) -> str | None:
    """The first option of ``options`` an error message names (`` `key` ``, ``key=``, ``'key'``)."""
    for key in options:
        if re.search(rf"(`{re.escape(key)}[`=(]|\b{re.escape(key)}=|'{re.escape(key)}')", text):
            return key
    return None


def build_trainer(
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


def config_error_of(exc: MisconfigurationException, cfg: DictConfig) -> ConfigError | None:
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


def check_options(options: dict[str, Any], cls: type, prefix: str, owner: str) -> None:
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
