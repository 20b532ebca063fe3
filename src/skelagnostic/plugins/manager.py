"""Plugin discovery and the registry of aligners, representations, datasets, configs, protocols.

:class:`PluginManager` wraps a :class:`pluggy.PluginManager` (project name
``skelagnostic``). It registers the built-in plugin, then every entry point of
the ``skelagnostic`` group, and calls the registration hooks of
:mod:`skelagnostic.plugins.hookspecs` one plugin at a time so that each
contribution is attributed to its plugin. A plugin that fails to import (an
exception, ``SystemExit``, a ``KeyboardInterrupt`` its own code raises, or any
other ``BaseException``), or
whose hook raises, is skipped with a :class:`PluginLoadWarning` and reported
as ``failed``. So is a plugin that registers a name another plugin (or the
built-in one) registered before it, or whose entry-point name is taken: the
first one registered (the built-in plugin, then entry points by name and
distribution name) keeps the name, and the warning names both.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import inspect
import os
import re
import signal
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from importlib import metadata, resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pluggy

from skelagnostic.errors import SkelagnosticError, printable
from skelagnostic.plugins import hookspecs

#: The pluggy project name and the entry-point group plugins register under.
ENTRY_POINT_GROUP = "skelagnostic"
#: Comma-separated entry-point names to load; unset loads all, empty loads none.
LOAD_PLUGINS_ENV = "SKELAGNOSTIC_LOAD_PLUGINS"
#: Name of the built-in plugin (the package's own representations and datasets).
BUILTIN_NAME = "skelagnostic"

#: Marker for hook implementations in plugins: ``@hookimpl def register_aligners(register): ...``.
hookimpl = pluggy.HookimplMarker(ENTRY_POINT_GROUP)

_HOOKS = (
    "register_aligners",
    "register_representations",
    "register_datasets",
    "register_config_paths",
    "register_evaluations",
    "register_checkpoint_readers",
)

#: The ``<scheme>`` of ``ckpt=<scheme>:<path>`` (two characters or more, so a Windows drive
#: letter is never one).
CHECKPOINT_SCHEME = re.compile(r"[a-z][a-z0-9_]+")


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
class _Contributions:
    aligners: list[AlignerSpec] = field(default_factory=list)
    representations: list[RepresentationSpec] = field(default_factory=list)
    datasets: list[DatasetSpec] = field(default_factory=list)
    config_paths: list[tuple[str, str]] = field(default_factory=list)
    evaluations: list[EvaluationSpec] = field(default_factory=list)
    checkpoint_readers: list[CheckpointReaderSpec] = field(default_factory=list)


def _allowed_plugins() -> frozenset[str] | None:
    value = os.environ.get(LOAD_PLUGINS_ENV)
    if value is None:
        return None
    return frozenset(name.strip() for name in value.split(",") if name.strip())


def _error_text(exc: BaseException) -> str:
    """``"Type: message"`` on one line (control characters escaped, see ``printable``)."""
    return printable(f"{type(exc).__name__}: {exc}")


@contextmanager
def _user_interrupts() -> Iterator[list[int]]:
    """Record the Ctrl-C (SIGINT) the user presses while plugin code runs.

    A :class:`KeyboardInterrupt` raised while no SIGINT arrived comes from the
    plugin's own code (``raise KeyboardInterrupt`` at import): the plugin is
    broken and is skipped like any other. One that follows a SIGINT is the
    user's and must stop the command. The handler only records the signal and
    calls the one installed before (Python's raises ``KeyboardInterrupt``).
    Outside the main thread, or when SIGINT is ignored or left to the system,
    no handler is installed: a ``KeyboardInterrupt`` can then only be the plugin's.

    Yields:
        The list the handler appends the signal numbers to.
    """
    seen: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield seen
        return
    previous = signal.getsignal(signal.SIGINT)
    if not callable(previous):
        yield seen
        return

    def record(signum: int, frame: Any) -> Any:
        seen.append(signum)
        return previous(signum, frame)

    signal.signal(signal.SIGINT, record)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, previous)


def _raise_if_user_interrupt(exc: BaseException, interrupts: list[int]) -> None:
    """Re-raise a ``KeyboardInterrupt`` that follows the user's Ctrl-C (``_user_interrupts``)."""
    if isinstance(exc, KeyboardInterrupt) and interrupts:
        raise exc


class PluginManager:
    """Loads plugins and holds what they registered.

    Args:
        load_entrypoints: Load the ``skelagnostic`` entry-point group.
        builtins: Register the built-in plugin (:mod:`skelagnostic.plugins.builtin`).
        only: Entry-point names to load; ``None`` reads ``SKELAGNOSTIC_LOAD_PLUGINS``
            (unset: all). The built-in plugin is always loaded.

    Examples:
        >>> from skelagnostic.plugins import PluginManager
        >>> pm = PluginManager(load_entrypoints=False)
        >>> "global_positions" in pm.representations
        True
    """

    def __init__(
        self,
        *,
        load_entrypoints: bool = True,
        builtins: bool = True,
        only: Iterable[str] | None = None,
    ) -> None:
        self._pm = pluggy.PluginManager(ENTRY_POINT_GROUP)
        self._pm.add_hookspecs(hookspecs)
        self._infos: dict[str, PluginInfo] = {}
        self._collected: _Contributions | None = None
        if builtins:
            from skelagnostic import __version__
            from skelagnostic.plugins import builtin

            self.register(builtin, BUILTIN_NAME, version=__version__, source="built-in")
        if load_entrypoints:
            self.load_entrypoints(_allowed_plugins() if only is None else frozenset(only))

    def register(
        self,
        plugin: object,
        name: str,
        *,
        version: str = "",
        source: str = "",
        description: str | None = None,
    ) -> None:
        """Register a plugin object (usually a module with ``@hookimpl`` functions).

        Args:
            plugin: The plugin.
            name: Its unique name.
            version: Version shown by ``skelagnostic plugins``.
            source: Where it comes from (distribution name, ``"built-in"``, ...).
            description: One line for ``skelagnostic plugins``; ``None`` takes the
                first line of the plugin's docstring.

        Raises:
            PluginError: ``name`` or the plugin object is already registered, or the
                plugin implements an unknown hook.
        """
        if name in self._infos:
            raise PluginError(
                f"plugin name {name!r} is registered twice "
                f"(by {self._infos[name].source!r} and {source!r})"
            )
        try:
            self._pm.register(plugin, name=name)
            self._pm.check_pending()  # rejects misspelt hook names
        except (ValueError, pluggy.PluginValidationError) as exc:
            if self._pm.get_plugin(name) is plugin:
                self._pm.unregister(name=name)
            raise PluginError(f"plugin {name!r}: {exc}") from exc
        hooks = tuple(h.name for h in self._pm.get_hookcallers(plugin) or ())
        if description is None:
            description = _first_line(getattr(plugin, "__doc__", None))
        self._infos[name] = PluginInfo(
            name, version, source, "loaded", hooks=hooks, description=description
        )
        self._collected = None

    def load_entrypoints(self, only: frozenset[str] | None = None) -> None:
        """Import and register every entry point of the ``skelagnostic`` group.

        Args:
            only: Names to load; the others are listed as ``disabled``. ``None`` loads all.
        """
        # by name, then distribution: of two distributions claiming one name, the same one wins
        found = metadata.entry_points(group=ENTRY_POINT_GROUP)
        unknown = sorted((only or set()) - {ep.name for ep in found} - set(self._infos))
        if unknown:  # a misspelt name would otherwise disable every plugin without a word
            warnings.warn(
                printable(
                    f"{LOAD_PLUGINS_ENV} names {', '.join(map(repr, unknown))}, which no "
                    "installed plugin is; installed: "
                    f"{', '.join(sorted({ep.name for ep in found})) or 'none'}"
                ),
                PluginLoadWarning,
                stacklevel=2,
            )
        for ep in sorted(found, key=lambda e: (e.name, e.dist.name if e.dist else e.value)):
            dist = ep.dist
            version = dist.version if dist is not None else ""
            source = dist.name if dist is not None else ep.value
            summary = (dist.metadata["Summary"] or "") if dist is not None else ""
            if only is not None and ep.name not in only:
                self._infos.setdefault(
                    ep.name, PluginInfo(ep.name, version, source, "disabled", description=summary)
                )
                continue
            taken = self._infos.get(ep.name)
            if taken is not None:  # another distribution (or the built-in) has the name
                self._skip_duplicate(ep.name, version, source, taken)
                continue
            with _user_interrupts() as interrupts:
                try:
                    plugin = ep.load()
                    described = _first_line(getattr(plugin, "__doc__", None)) or summary
                    other = self._pm.get_name(plugin)
                    if other is not None:  # the same module under a second entry-point name
                        raise PluginError(
                            f"plugin {ep.name!r} ({source}) is the module {ep.value!r} "
                            f"already loaded as plugin {other!r} ({self._infos[other].source})"
                        )
                    self.register(
                        plugin, ep.name, version=version, source=source, description=described
                    )
                    self._require_hooks(plugin, ep.name, ep.value)
                except BaseException as exc:
                    # a broken third-party plugin must not break (or end) the CLI
                    _raise_if_user_interrupt(exc, interrupts)
                    self._fail(ep.name, version, source, exc)

    def _skip_duplicate(self, name: str, version: str, source: str, taken: PluginInfo) -> None:
        """Skip an entry point whose name a plugin loaded before holds; warn naming both.

        The skipped one is listed (status ``failed``) under ``"<name> (<source>)"``.
        """
        exc = PluginError(
            f"plugin name {name!r} is registered by both {taken.source!r} and {source!r} "
            f"(the first one loaded keeps it)"
        )
        self._fail(name, version, source, exc, key=f"{name} ({source})")

    def _require_hooks(self, plugin: object, name: str, target: str) -> None:
        """Unregister ``plugin`` and raise when it implements no hook (or forgot ``@hookimpl``).

        A function named like a hook but not decorated with :data:`hookimpl` is
        ignored by pluggy, so the plugin would load silently and contribute
        nothing (``Could not find 'model/<name>'`` later); this turns that into
        a failure naming the function.

        Raises:
            PluginError: Caused by a :class:`pluggy.PluginValidationError`, so that
                :meth:`load_entrypoints` reports the plugin as failed.
        """
        problem = _hook_problem(plugin, target, self._infos[name].hooks)
        if problem is None:
            return
        self._pm.unregister(name=name)
        del self._infos[name]
        cause = pluggy.PluginValidationError(plugin, problem)
        raise PluginError(f"plugin {name!r}: {problem}") from cause

    def _fail(
        self, name: str, version: str, source: str, exc: BaseException, key: str | None = None
    ) -> None:
        """Warn that plugin ``name`` is skipped; list it as failed under ``key`` (or ``name``)."""
        warnings.warn(
            printable(f"skelagnostic plugin {name!r} ({source}) skipped: {_error_text(exc)}"),
            PluginLoadWarning,
            stacklevel=3,
        )
        key = name if key is None else key
        old = self._infos.get(key)
        hooks = old.hooks if old is not None else ()
        description = old.description if old is not None else ""
        self._infos[key] = PluginInfo(
            name, version, source, "failed", _error_text(exc), hooks, description=description
        )

    def plugins(self) -> list[PluginInfo]:
        """Every plugin seen, in registration order, with what it provides."""
        self._collect()
        return list(self._infos.values())

    @property
    def aligners(self) -> Mapping[str, AlignerSpec]:
        """Registered aligners by name."""
        return MappingProxyType({s.name: s for s in self._collect().aligners})

    def aligner_classes(self) -> dict[str, type]:
        """Registered aligner classes by name (what checkpoint checks compare against).

        Example:
            >>> from skelagnostic.plugins import get_plugin_manager
            >>> get_plugin_manager().aligner_classes()["humot"].__name__
            'HumotAligner'
        """
        return {name: spec.module for name, spec in self.aligners.items()}

    @property
    def representations(self) -> Mapping[str, RepresentationSpec]:
        """Registered motion representations by name."""
        return MappingProxyType({s.name: s for s in self._collect().representations})

    @property
    def datasets(self) -> Mapping[str, DatasetSpec]:
        """Registered dataset readers/presets by name."""
        return MappingProxyType({s.name: s for s in self._collect().datasets})

    @property
    def config_paths(self) -> list[str]:
        """Hydra search-path URLs registered by plugins, in plugin order."""
        return [path for path, _ in self._collect().config_paths]

    @property
    def evaluations(self) -> Mapping[str, EvaluationSpec]:
        """Registered evaluation protocols by name."""
        return MappingProxyType({s.name: s for s in self._collect().evaluations})

    @property
    def checkpoint_readers(self) -> Mapping[str, CheckpointReaderSpec]:
        """Registered readers of ``ckpt=<scheme>:<path>`` by scheme."""
        return MappingProxyType({s.name: s for s in self._collect().checkpoint_readers})

    def checkpoint_reader_of(self, ckpt: str | Path) -> tuple[CheckpointReaderSpec, str] | None:
        """The registered reader and the path of ``ckpt = "<scheme>:<path>"``, else ``None``.

        A value that names an existing file or directory is a path, whatever its form.

        Raises:
            PluginError: ``ckpt`` has the form ``<scheme>:<path>`` with an unregistered
                scheme and is no existing path, or its path is empty (the message lists
                the registered schemes).
        """
        text = str(ckpt)
        scheme, sep, rest = text.partition(":")
        if not sep or rest.startswith("//") or not CHECKPOINT_SCHEME.fullmatch(scheme):
            return None
        if Path(text).exists():
            return None
        known = (
            ", ".join(
                f"{s.name}: ({s.model}) {s.description}" for s in self.checkpoint_readers.values()
            )
            or "none"
        )
        spec = self.checkpoint_readers.get(scheme)
        if spec is None:
            raise PluginError(
                f"checkpoint {text!r}: no checkpoint reader {scheme!r} is "
                f"registered (readers: {known})"
            )
        if not rest:
            raise PluginError(f"checkpoint {text!r}: give the path after '{scheme}:'")
        return spec, rest

    def read_external_checkpoint(self, ckpt: str | Path, model: str | None = None) -> Any | None:
        """The aligner a registered reader builds from ``ckpt = "<scheme>:<path>"``, else ``None``.

        Args:
            ckpt: The checkpoint argument as the user gave it.
            model: The aligner name the user asked for (``None``: the reader's).

        Returns:
            The aligner in eval mode, or ``None`` when ``ckpt`` is a plain path.

        Raises:
            PluginError: See :meth:`checkpoint_reader_of`; also when ``model`` is not
                the reader's model, or the reader returned something else than it.
        """
        found = self.checkpoint_reader_of(ckpt)
        if found is None:
            return None
        spec, path = found
        if model is not None and model != spec.model:
            raise PluginError(
                f"checkpoint {str(ckpt)!r} is read as model={spec.model} (plugin "
                f"{spec.plugin!r}), not model={model}"
            )
        cls = self.aligner(spec.model).module
        aligner = spec.reader(path)
        if not isinstance(aligner, cls):
            raise PluginError(
                f"checkpoint reader {spec.name!r} (plugin {spec.plugin!r}) returned "
                f"{type(aligner).__name__}, not the {cls.__name__} of "
                f"model={spec.model}"
            )
        return aligner.eval()

    def evaluation(self, name: str | None, model: str) -> EvaluationSpec:
        """The protocol ``name`` of aligner ``model`` (None: ``model``'s default protocol).

        Raises:
            PluginError: Unknown protocol, a protocol of another model, or no
                (default) protocol for ``model``; the message lists ``model``'s protocols.
        """
        mine = sorted(s.name for s in self._collect().evaluations if s.model == model)
        listed = ", ".join(mine) or "none"
        if name is None:
            default = [s for s in self._collect().evaluations if s.model == model and s.default]
            if not default:
                raise PluginError(
                    f"model={model} has no default evaluation protocol; give "
                    f"protocol=NAME (protocols of model={model}: {listed})"
                )
            return default[0]
        spec = self.evaluations.get(name)
        if spec is None:
            raise PluginError(
                f"unknown evaluation protocol {name!r}; protocols of model={model}: {listed}"
            )
        if spec.model != model:
            raise PluginError(
                f"protocol {name!r} evaluates model={spec.model}, not "
                f"model={model}; protocols of model={model}: {listed}"
            )
        return spec

    def aligner(self, name: str) -> AlignerSpec:
        """The aligner registered as ``name``; :class:`PluginError` lists the known ones."""
        return _lookup(self.aligners, name, "aligner")

    def representation(self, name: str) -> RepresentationSpec:
        """The representation registered as ``name``; :class:`PluginError` lists the known ones."""
        return _lookup(self.representations, name, "representation")

    def dataset(self, name: str) -> DatasetSpec:
        """The dataset registered as ``name``; :class:`PluginError` lists the known ones."""
        return _lookup(self.datasets, name, "dataset")

    def _collect(self) -> _Contributions:
        if self._collected is not None:
            return self._collected
        total = _Contributions()
        owners: dict[tuple[str, str], str] = {}
        for name, info in list(self._infos.items()):
            if info.status != "loaded":
                continue
            plugin = self._pm.get_plugin(name)
            with _user_interrupts() as interrupts:
                try:
                    mine = _call_hooks(self._pm, plugin, name)
                    names = _registered_names(mine, owners, name)
                except BaseException as exc:
                    # a plugin whose registration raises, or that registers a name
                    # another plugin holds, is skipped (the first one keeps the name)
                    _raise_if_user_interrupt(exc, interrupts)
                    self._pm.unregister(plugin)
                    self._fail(name, info.version, info.source, exc)
                    continue
            owners.update(dict.fromkeys(names, name))
            provides = [f"{kind}:{item}" for kind, item in names]
            provides += [f"config_path:{path}" for path, _ in mine.config_paths]
            total.aligners += mine.aligners
            total.representations += mine.representations
            total.datasets += mine.datasets
            total.config_paths += mine.config_paths
            total.evaluations += mine.evaluations
            total.checkpoint_readers += mine.checkpoint_readers
            config_urls = [path for path, _ in mine.config_paths]
            if name == BUILTIN_NAME:
                config_urls.insert(0, "pkg://skelagnostic.conf")
            presets = [*(f"data/{spec.name}" for spec in mine.aligners if spec.data)]
            for url in config_urls:
                provides += [f"experiment:{n}" for n in config_names(url, "experiment")]
                presets += [f"data/{n}" for n in config_names(url, "data")]
            provides += [f"data_preset:{p.split('/', 1)[1]}" for p in dict.fromkeys(presets)]
            self._infos[name] = replace(info, error=None, provides=tuple(provides))
        self._collected = total
        return total


def _registered_names(
    mine: _Contributions, owners: Mapping[tuple[str, str], str], plugin_name: str
) -> list[tuple[str, str]]:
    """The ``(kind, name)`` pairs a plugin registered, in order.

    Raises:
        PluginError: A name is registered by a plugin before this one (the
            message names both) or twice by this one.
    """
    names: list[tuple[str, str]] = []
    for kind, items in (
        ("aligner", mine.aligners),
        ("representation", mine.representations),
        ("dataset", mine.datasets),
        ("evaluation", mine.evaluations),
        ("checkpoint reader", mine.checkpoint_readers),
    ):
        for item in items:
            key = (kind, item.name)
            if key in owners:
                raise PluginError(
                    f"{kind} {item.name!r} is registered by both plugin {owners[key]!r} "
                    f"and plugin {plugin_name!r} (the first one loaded keeps it)"
                )
            if key in names:
                raise PluginError(f"{kind} {item.name!r} is registered twice by {plugin_name!r}")
            names.append(key)
    return names


def _first_line(doc: str | None) -> str:
    """The first line of a docstring, without reStructuredText double backticks."""
    lines = (doc or "").strip().splitlines()
    return lines[0].strip().replace("``", "") if lines else ""


def config_names(url: str, group: str) -> list[str]:
    """Names of the ``<group>/*.yaml`` configs under a Hydra search-path URL (sorted).

    Files starting with ``_`` (shared bases) are left out; an unreadable location
    gives an empty list.
    """
    try:
        if url.startswith("pkg://"):
            root: Any = resources.files(url[len("pkg://") :].strip("/").replace("/", "."))
        elif url.startswith("file://"):
            root = Path(url[len("file://") :])
        else:
            return []
        folder = root.joinpath(group)
        if not folder.is_dir():
            return []
        names = [f.name[:-5] for f in folder.iterdir() if f.name.endswith(".yaml")]
    except (ImportError, OSError, TypeError, ValueError):
        return []
    return sorted(n for n in names if not n.startswith("_"))


def _hook_problem(plugin: object, target: str, hooks: tuple[str, ...]) -> str | None:
    """What is wrong with an entry-point plugin's hooks, or ``None``.

    Args:
        plugin: The loaded entry-point object (usually a module).
        target: The entry point's value (``module`` or ``module:attr``), for the message.
        hooks: The hooks pluggy found implemented.
    """
    functions = {
        attr: value
        for attr in dir(plugin)
        if not attr.startswith("_")
        and callable(value := getattr(plugin, attr, None))
        and (inspect.isfunction(value) or inspect.ismethod(value))
    }
    marker = f"{ENTRY_POINT_GROUP}_impl"
    unmarked = {
        a: f for a, f in functions.items() if a.startswith("register") and not hasattr(f, marker)
    }
    foreign = sorted(
        a
        for a, f in unmarked.items()
        if any(k.endswith("_impl") for k in getattr(f, "__dict__", {}))
    )
    undecorated = sorted(a for a in unmarked if a in _HOOKS)
    if undecorated or (foreign and not hooks):
        names = undecorated or foreign
        why = " (marked by another project's HookimplMarker)" if set(names) & set(foreign) else ""
        return (
            f"{target}: {', '.join(names)} is not decorated with "
            f"@skelagnostic.plugins.hookimpl{why}, so skelagnostic never calls it"
        )
    if hooks:
        return None
    close = sorted(a for a in unmarked if difflib.get_close_matches(a, _HOOKS, n=1, cutoff=0.8))
    hint = f" (misspelt hook? {', '.join(close)})" if close else ""
    return (
        f"{target} implements no skelagnostic hook{hint}: decorate functions named "
        f"{', '.join(_HOOKS)} with @skelagnostic.plugins.hookimpl"
    )


def _config_urls(path: str, plugin_name: str) -> list[str]:
    """Hydra search-path URLs for a registered config path.

    Hydra's ``pkg://`` source expects a regular package: for a directory without
    ``__init__.py`` (a namespace package) it warns that the path "is not
    available" (and whether it still reads the files depends on the Python
    version and the installation). Such a package is registered as the
    ``file://`` URL of its directory (or directories) instead.

    Raises:
        PluginError: A ``pkg://`` URL names no importable package.
    """
    if not path.startswith("pkg://"):
        return [path]
    package = path[len("pkg://") :].strip("/").replace("/", ".")
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError) as exc:
        spec, error = None, f" ({_error_text(exc)})"
    else:
        error = ""
    if spec is None or spec.submodule_search_locations is None:
        what = "a module, not a package" if spec is not None else "not importable"
        raise PluginError(
            f"plugin {plugin_name!r}: config path {path!r}: {package!r} is {what}{error}; "
            f"it must be a package directory of YAML files with an __init__.py, "
            f"shipped as package data"
        )
    if spec.origin is not None:  # a regular package: Hydra reads it
        return [path]
    return [Path(location).resolve().as_uri() for location in spec.submodule_search_locations]


def read_model_config(package: str, name: str) -> dict[str, Any]:
    """Read ``model/<name>.yaml`` of a plugin's config package: an aligner's defaults.

    The file holds ``_target_`` (the dotted path of the aligner class) and every
    constructor argument with its default; it is both the Hydra config
    ``model/<name>`` (when ``package`` is registered with ``register_config_paths``)
    and the ``config=`` a plugin passes to ``register_aligners``, so the defaults
    live in one place.

    Args:
        package: The config package, e.g. ``"skelagnostic_humot.conf"``.
        name: The aligner name (the file's stem).

    Returns:
        The file's mapping, ``_target_`` included.

    Raises:
        PluginError: The file is missing, is not valid YAML, is not a mapping or has
            no ``_target_``; the message names the file.
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException
    from yaml import YAMLError

    where = f"{package}/model/{name}.yaml"
    try:
        text = resources.files(package).joinpath("model", f"{name}.yaml").read_text("utf-8")
    except (ImportError, OSError) as exc:
        raise PluginError(f"model config {where}: cannot be read ({_error_text(exc)})") from exc
    try:
        node = OmegaConf.create(text) if text.strip() else None
    except (YAMLError, OmegaConfBaseException) as exc:
        raise PluginError(f"model config {where}: invalid YAML ({_error_text(exc)})") from exc
    if node is None or not OmegaConf.is_dict(node):
        raise PluginError(f"model config {where}: expected a mapping of constructor arguments")
    config: dict[str, Any] = OmegaConf.to_container(node, resolve=False)  # type: ignore[assignment]
    if not isinstance(config.get("_target_"), str):
        raise PluginError(
            f"model config {where}: needs '_target_', the dotted path of the "
            "aligner class (e.g. 'my_plugin.aligner.MyAligner')"
        )
    return config


def target_of(cls: type) -> str:
    """The ``_target_`` naming ``cls``: ``"<module>.<qualname>"``."""
    return f"{cls.__module__}.{cls.__qualname__}"


def _check_target(name: str, target: Any, module: type) -> None:
    """Raise :class:`PluginError` when a config's ``_target_`` does not name ``module``."""
    resolved: Any = None
    if isinstance(target, str) and "." in target:
        module_name, _, attr = target.rpartition(".")
        try:
            resolved = getattr(importlib.import_module(module_name), attr, None)
        except ImportError:
            resolved = None
    if resolved is not module:
        raise PluginError(
            f"aligner {name!r}: config _target_={target!r} does not name the "
            f"registered module {target_of(module)!r}"
        )


def _lookup(table: Mapping[str, Any], name: str, kind: str) -> Any:
    if name not in table:
        known = ", ".join(sorted(table)) or "none"
        raise PluginError(f"unknown {kind} {name!r}; registered: {known}")
    return table[name]


def _call_hooks(pm: pluggy.PluginManager, plugin: object, plugin_name: str) -> _Contributions:
    """Call one plugin's registration hooks and return what it registered."""
    out = _Contributions()

    def register_aligner(
        name: str,
        module: type,
        datamodule: type | None = None,
        config: Mapping[str, Any] | None = None,
        description: str = "",
        data: Mapping[str, Any] | None = None,
        data_options: Mapping[str, Any] | None = None,
        trainer_options: Mapping[str, Any] | None = None,
    ) -> None:
        from skelagnostic.aligners import Aligner
        from skelagnostic.data import MotionDataModule

        datamodule = MotionDataModule if datamodule is None else datamodule
        if not (isinstance(module, type) and issubclass(module, Aligner)):
            raise PluginError(
                f"aligner {name!r}: module must be an Aligner subclass, got {module!r}"
            )
        if not (isinstance(datamodule, type) and issubclass(datamodule, MotionDataModule)):
            raise PluginError(
                f"aligner {name!r}: datamodule must be a MotionDataModule subclass, "
                f"got {datamodule!r}"
            )
        config = dict(config or {})
        if "_target_" in config:
            _check_target(name, config.pop("_target_"), module)
        if "name" in config:
            raise PluginError(f"aligner {name!r}: config key 'name' is reserved")
        data = dict(data or {})
        if data and "source" not in data:
            raise PluginError(f"aligner {name!r}: data needs a 'source' (a registered dataset)")
        out.aligners.append(
            AlignerSpec(
                name,
                module,
                datamodule,
                MappingProxyType(config),
                description,
                plugin_name,
                MappingProxyType(data),
                MappingProxyType(dict(data_options or {})),
                MappingProxyType(dict(trainer_options or {})),
            )
        )

    def register_representation(name: str, cls: type) -> None:
        from skelagnostic.representations import MotionRepresentation

        if not (isinstance(cls, type) and issubclass(cls, MotionRepresentation)):
            raise PluginError(
                f"representation {name!r}: cls must be a MotionRepresentation subclass, got {cls!r}"
            )
        out.representations.append(RepresentationSpec(name, cls, plugin_name))

    def register_dataset(name: str, factory: Callable[..., Any], description: str = "") -> None:
        if not callable(factory):
            raise PluginError(f"dataset {name!r}: factory must be callable, got {factory!r}")
        out.datasets.append(DatasetSpec(name, factory, description, plugin_name))

    def register_config_path(path: str) -> None:
        if not isinstance(path, str) or "://" not in path:
            raise PluginError(
                f"config path {path!r}: expected a Hydra search-path URL such as "
                "'pkg://my_plugin.conf' or 'file:///abs/dir'"
            )
        for url in _config_urls(path, plugin_name):
            out.config_paths.append((url, plugin_name))

    def register_evaluation(
        name: str,
        function: Callable[..., Any],
        model: str,
        description: str = "",
        default: bool = False,
    ) -> None:
        if not callable(function):
            raise PluginError(f"evaluation {name!r}: function must be callable, got {function!r}")
        if not isinstance(model, str) or not model:
            raise PluginError(f"evaluation {name!r}: model must be an aligner name, got {model!r}")
        if default and any(e.default and e.model == model for e in out.evaluations):
            raise PluginError(f"evaluation {name!r}: model={model} already has a default protocol")
        out.evaluations.append(
            EvaluationSpec(
                name,
                function,
                model,
                description or _first_line(function.__doc__),
                bool(default),
                plugin_name,
            )
        )

    def register_checkpoint_reader(
        scheme: str, reader: Callable[[str], Any], model: str, description: str = ""
    ) -> None:
        if not isinstance(scheme, str) or not CHECKPOINT_SCHEME.fullmatch(scheme):
            raise PluginError(
                f"checkpoint reader {scheme!r}: the scheme must be a lower-case "
                "word of two or more letters, digits or underscores"
            )
        if not callable(reader):
            raise PluginError(
                f"checkpoint reader {scheme!r}: reader must be callable, got {reader!r}"
            )
        if not isinstance(model, str) or not model:
            raise PluginError(
                f"checkpoint reader {scheme!r}: model must be an aligner name, got {model!r}"
            )
        out.checkpoint_readers.append(
            CheckpointReaderSpec(
                scheme, reader, model, description or _first_line(reader.__doc__), plugin_name
            )
        )

    callbacks = {
        "register_aligners": register_aligner,
        "register_checkpoint_readers": register_checkpoint_reader,
        "register_evaluations": register_evaluation,
        "register_representations": register_representation,
        "register_datasets": register_dataset,
        "register_config_paths": register_config_path,
    }
    for hook_name in _HOOKS:
        for impl in getattr(pm.hook, hook_name).get_hookimpls():
            if impl.plugin is plugin:
                impl.function(register=callbacks[hook_name])
    return out
