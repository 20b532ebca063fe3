"""What plugins contribute: the records of the registry, and the errors of plugin loading.

:class:`~skelagnostic.plugins.PluginManager` keeps one record per contribution
(an :class:`AlignerSpec` per ``register(...)`` call of ``register_aligners``, and
so on) and a :class:`PluginInfo` per plugin for ``skelagnostic plugins``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from skelagnostic.errors import SkelagnosticError, printable


class PluginError(SkelagnosticError):
    """A plugin problem: a name registered twice, or an unknown aligner/representation/dataset.

    Raised by :meth:`PluginManager.register` and the lookups; while plugins load, a
    name clash is the skipped plugin's ``error`` instead (and a :class:`PluginLoadWarning`).
    """


class PluginLoadWarning(UserWarning):
    """A plugin was skipped because it failed to import or to register."""


@dataclass(frozen=True)
class PluginInfo:
    """What ``skelagnostic plugins`` shows about one plugin.

    Attributes:
        name: Entry-point name (``"skelagnostic"`` for the built-in plugin).
        version: Version of the distribution providing it.
        source: ``"built-in"`` or the providing distribution's name.
        status: ``"loaded"``, ``"failed"`` or ``"disabled"`` (filtered out by
            ``SKELAGNOSTIC_LOAD_PLUGINS``).
        error: ``"ExceptionType: message"`` when the plugin failed.
        hooks: Names of the hooks the plugin implements.
        provides: What it registered, as ``"kind:name"`` strings: ``aligner``,
            ``representation``, ``dataset`` (``data.source=``), ``config_path``, and
            the configs it ships: ``experiment`` (``experiment=``) and ``data_preset``
            (``data=``).
        description: First line of the plugin module's docstring, else the
            distribution's summary.
    """

    name: str
    version: str
    source: str
    status: str
    error: str | None = None
    hooks: tuple[str, ...] = ()
    provides: tuple[str, ...] = ()
    description: str = ""


@dataclass(frozen=True)
class AlignerSpec:
    """An aligner contributed through ``register_aligners``.

    Attributes:
        name: The ``model=<name>`` of the aligner.
        module: The :class:`~skelagnostic.aligners.Aligner` subclass.
        datamodule: The :class:`~skelagnostic.data.MotionDataModule` subclass feeding it.
        config: Default keyword arguments of ``module`` (the ``model/<name>`` config).
        description: One line for ``skelagnostic plugins``.
        plugin: Name of the plugin that registered it.
        data: The aligner's default data config (stored as ``data/<name>`` and selected
            when the command line names no ``data=``), or empty for ``data: procedural``.
        data_options: Data-module keys (e.g. ``window``, ``fps``) the aligner needs
            whatever the data source; merged over the selected data config, under the
            command line's overrides.
        trainer_options: Trainer keys the aligner needs by default (e.g.
            ``gradient_clip_val``; never a limit such as ``max_time``: those belong in
            experiments); merged over the selected trainer config, under the command
            line's overrides.
    """

    name: str
    module: type
    datamodule: type
    config: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    plugin: str = ""
    data: Mapping[str, Any] = field(default_factory=dict)
    data_options: Mapping[str, Any] = field(default_factory=dict)
    trainer_options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RepresentationSpec:
    """A motion representation contributed through ``register_representations``."""

    name: str
    cls: type
    plugin: str = ""


@dataclass(frozen=True)
class DatasetSpec:
    """A dataset reader or preset contributed through ``register_datasets``.

    Attributes:
        name: The ``data.source=<name>`` of the dataset.
        factory: ``factory(**options)`` returns a :class:`~skelagnostic.data.ClipSource`.
        description: One line for ``skelagnostic plugins``.
        plugin: Name of the plugin that registered it.
    """

    name: str
    factory: Callable[..., Any]
    description: str = ""
    plugin: str = ""


@dataclass(frozen=True)
class EvaluationSpec:
    """An evaluation protocol contributed through ``register_evaluations``.

    Attributes:
        name: The ``protocol=<name>`` of ``skelagnostic evaluate`` (``<method>.<what>``).
        function: ``function(aligner, held_out, out_dir)`` returning an
            :class:`~skelagnostic.evaluation.Evaluation`.
        model: The aligner (``model=<name>``) it evaluates.
        description: One line for ``skelagnostic plugins`` and the outputs.
        default: The protocol ``evaluate`` runs for ``model`` when none is named.
        plugin: Name of the plugin that registered it.
    """

    name: str
    function: Callable[..., Any]
    model: str
    description: str = ""
    default: bool = False
    plugin: str = ""


@dataclass(frozen=True)
class CheckpointReaderSpec:
    """A reader of ``ckpt=<scheme>:<path>`` contributed through ``register_checkpoint_readers``.

    Attributes:
        name: The scheme.
        reader: ``reader(path: str) -> Aligner`` (weights loaded).
        model: The aligner (``model=<name>``) it builds.
        description: One line for ``skelagnostic plugins`` and the messages.
        plugin: Name of the plugin that registered it.
    """

    name: str
    reader: Callable[[str], Any]
    model: str
    description: str = ""
    plugin: str = ""


@dataclass
class Contributions:
    """What one plugin (or all of them) registered, in registration order."""

    aligners: list[AlignerSpec] = field(default_factory=list)
    representations: list[RepresentationSpec] = field(default_factory=list)
    datasets: list[DatasetSpec] = field(default_factory=list)
    config_paths: list[tuple[str, str]] = field(default_factory=list)
    evaluations: list[EvaluationSpec] = field(default_factory=list)
    checkpoint_readers: list[CheckpointReaderSpec] = field(default_factory=list)


def error_text(exc: BaseException) -> str:
    """``"Type: message"`` on one line (control characters escaped, see ``printable``)."""
    return printable(f"{type(exc).__name__}: {exc}")


def first_line(doc: str | None) -> str:
    """The first line of a docstring, without reStructuredText double backticks."""
    lines = (doc or "").strip().splitlines()
    return lines[0].strip().replace("``", "") if lines else ""
