"""What plugins contribute: the records of the registry, and the errors of plugin loading.

:class:`~skelagnostic.plugins.PluginManager` keeps one record per contribution
(an :class:`AlignerSpec` per ``register(...)`` call of ``register_aligners``, and
so on) and a :class:`PluginInfo` per plugin for ``skelagnostic plugins``.

A plugin may register the object itself or a reference ``"package.module:name"``
(the entry-point syntax): a reference is imported when the object is first used
(:func:`resolve_ref`), so listing the plugins or composing a config imports no
aligner, data module or protocol, and none of the Lightning they need.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from skelagnostic.errors import SkelagnosticError, printable

#: An object, or ``"package.module:name"`` naming it (imported on first use).
Ref = Any


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


def is_ref(obj: Any) -> bool:
    """Whether ``obj`` is a ``"package.module:name"`` reference."""
    return isinstance(obj, str) and ":" in obj


def ref_target(ref: Ref) -> str:
    """The dotted ``_target_`` of a reference or an object, importing nothing.

    Examples:
        >>> ref_target("skelagnostic_vqpae.aligner:VqpaeAligner")
        'skelagnostic_vqpae.aligner.VqpaeAligner'
    """
    if isinstance(ref, str):
        return ref.replace(":", ".")
    return f"{ref.__module__}.{ref.__qualname__}"


def resolve_ref(ref: Ref, what: str, plugin: str) -> Any:
    """The object ``ref`` names (an object is returned as it is).

    Args:
        ref: ``"package.module:name"`` (``name`` may be dotted) or the object.
        what: What it is, for the message (``"aligner 'vqpae'"``).
        plugin: The plugin that registered it, for the message.

    Raises:
        PluginError: The module cannot be imported or has no such name; the
            message names the plugin, the reference and the cause.
    """
    if not isinstance(ref, str):
        return ref
    module_name, sep, attr = ref.partition(":")
    if not sep or not module_name or not attr:
        raise PluginError(
            f"{what} of plugin {plugin!r}: {ref!r} is not a reference 'package.module:name'"
        )
    try:
        obj: Any = importlib.import_module(module_name)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except Exception as exc:  # an ImportError, or any error of the plugin's module
        raise PluginError(
            f"{what} of plugin {plugin!r}: cannot load {ref!r} ({error_text(exc)})"
        ) from exc
    return obj


def _subclass(obj: Any, base: type, what: str, field_name: str) -> type:
    if not (isinstance(obj, type) and issubclass(obj, base)):
        article = "an" if base.__name__[0] in "AEIOU" else "a"
        raise PluginError(
            f"{what}: {field_name} must be {article} {base.__name__} subclass, got {obj!r}"
        )
    return obj


@dataclass(frozen=True)
class AlignerSpec:
    """An aligner contributed through ``register_aligners``.

    Attributes:
        name: The ``model=<name>`` of the aligner.
        module_ref: The :class:`~skelagnostic.aligners.Aligner` subclass or a
            reference to it (:attr:`module` resolves it).
        datamodule_ref: The :class:`~skelagnostic.data.MotionDataModule` subclass
            feeding it, a reference to it, or ``None`` (the framework's).
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
    module_ref: Ref
    datamodule_ref: Ref = None
    config: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    plugin: str = ""
    data: Mapping[str, Any] = field(default_factory=dict)
    data_options: Mapping[str, Any] = field(default_factory=dict)
    trainer_options: Mapping[str, Any] = field(default_factory=dict)

    @functools.cached_property
    def module(self) -> type:
        """The aligner class (imported on first use)."""
        from skelagnostic.aligners import Aligner

        what = f"aligner {self.name!r}"
        cls = resolve_ref(self.module_ref, what, self.plugin)
        return _subclass(cls, Aligner, what, "module")

    @functools.cached_property
    def datamodule(self) -> type:
        """The data-module class (imported on first use)."""
        from skelagnostic.data.datamodule import MotionDataModule

        if self.datamodule_ref is None:
            return MotionDataModule
        what = f"aligner {self.name!r}"
        cls = resolve_ref(self.datamodule_ref, what, self.plugin)
        return _subclass(cls, MotionDataModule, what, "datamodule")

    @property
    def target(self) -> str:
        """The class's dotted path (the config's ``_target_``), importing nothing."""
        return ref_target(self.module_ref)


@dataclass(frozen=True)
class RepresentationSpec:
    """A motion representation contributed through ``register_representations``."""

    name: str
    cls_ref: Ref
    plugin: str = ""

    @functools.cached_property
    def cls(self) -> type:
        """The representation class (imported on first use)."""
        from skelagnostic.representations import MotionRepresentation

        what = f"representation {self.name!r}"
        found = resolve_ref(self.cls_ref, what, self.plugin)
        return _subclass(found, MotionRepresentation, what, "cls")


@dataclass(frozen=True)
class DatasetSpec:
    """A dataset reader or preset contributed through ``register_datasets``.

    Attributes:
        name: The ``data.source=<name>`` of the dataset.
        factory_ref: ``factory(**options)`` returning a
            :class:`~skelagnostic.data.ClipSource`, or a reference to it
            (:attr:`factory` resolves it).
        description: One line for ``skelagnostic plugins``.
        plugin: Name of the plugin that registered it.
    """

    name: str
    factory_ref: Ref
    description: str = ""
    plugin: str = ""

    @functools.cached_property
    def factory(self) -> Callable[..., Any]:
        """The factory (imported on first use)."""
        return _callable(self.factory_ref, f"dataset {self.name!r}", self.plugin, "factory")


@dataclass(frozen=True)
class EvaluationSpec:
    """An evaluation protocol contributed through ``register_evaluations``.

    Attributes:
        name: The ``protocol=<name>`` of ``skelagnostic evaluate`` (``<method>.<what>``).
        function_ref: ``function(aligner, held_out, out_dir)`` returning an
            :class:`~skelagnostic.evaluation.Evaluation`, or a reference to it
            (:attr:`function` resolves it).
        model: The aligner (``model=<name>``) it evaluates.
        description: One line for ``skelagnostic plugins`` and the outputs.
        default: The protocol ``evaluate`` runs for ``model`` when none is named.
        plugin: Name of the plugin that registered it.
    """

    name: str
    function_ref: Ref
    model: str
    description: str = ""
    default: bool = False
    plugin: str = ""

    @functools.cached_property
    def function(self) -> Callable[..., Any]:
        """The protocol function (imported on first use)."""
        return _callable(self.function_ref, f"evaluation {self.name!r}", self.plugin, "function")


@dataclass(frozen=True)
class CheckpointReaderSpec:
    """A reader of ``ckpt=<scheme>:<path>`` contributed through ``register_checkpoint_readers``.

    Attributes:
        name: The scheme.
        reader_ref: ``reader(path: str) -> Aligner`` (weights loaded), or a reference
            to it (:attr:`reader` resolves it).
        model: The aligner (``model=<name>``) it builds.
        description: One line for ``skelagnostic plugins`` and the messages.
        plugin: Name of the plugin that registered it.
    """

    name: str
    reader_ref: Ref
    model: str
    description: str = ""
    plugin: str = ""

    @functools.cached_property
    def reader(self) -> Callable[[str], Any]:
        """The reader (imported on first use)."""
        return _callable(self.reader_ref, f"checkpoint reader {self.name!r}", self.plugin, "reader")


@dataclass
class Contributions:
    """What one plugin (or all of them) registered, in registration order."""

    aligners: list[AlignerSpec] = field(default_factory=list)
    representations: list[RepresentationSpec] = field(default_factory=list)
    datasets: list[DatasetSpec] = field(default_factory=list)
    config_paths: list[tuple[str, str]] = field(default_factory=list)
    evaluations: list[EvaluationSpec] = field(default_factory=list)
    checkpoint_readers: list[CheckpointReaderSpec] = field(default_factory=list)


def _callable(ref: Ref, what: str, plugin: str, field_name: str) -> Callable[..., Any]:
    obj = resolve_ref(ref, what, plugin)
    if not callable(obj):
        raise PluginError(f"{what}: {field_name} must be callable, got {obj!r}")
    return obj


def error_text(exc: BaseException) -> str:
    """``"Type: message"`` on one line (control characters escaped, see ``printable``)."""
    return printable(f"{type(exc).__name__}: {exc}")


def first_line(doc: str | None) -> str:
    """The first line of a docstring, without reStructuredText double backticks."""
    lines = (doc or "").strip().splitlines()
    return lines[0].strip().replace("``", "") if lines else ""
