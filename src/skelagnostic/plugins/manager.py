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
import inspect
import os
import signal
import threading
import warnings
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from importlib import metadata
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pluggy

from skelagnostic.errors import printable
from skelagnostic.plugins import hookspecs
from skelagnostic.plugins.configs import config_names
from skelagnostic.plugins.registration import (
    CHECKPOINT_SCHEME,
    HOOKS,
    call_hooks,
    registered_names,
)
from skelagnostic.plugins.specs import (
    AlignerSpec,
    CheckpointReaderSpec,
    Contributions,
    DatasetSpec,
    EvaluationSpec,
    PluginError,
    PluginInfo,
    PluginLoadWarning,
    RepresentationSpec,
    error_text,
    first_line,
)

#: The pluggy project name and the entry-point group plugins register under.
ENTRY_POINT_GROUP = "skelagnostic"
#: Comma-separated entry-point names to load; unset loads all, empty loads none.
LOAD_PLUGINS_ENV = "SKELAGNOSTIC_LOAD_PLUGINS"
#: Name of the built-in plugin (the package's own representations and datasets).
BUILTIN_NAME = "skelagnostic"


def _allowed_plugins() -> frozenset[str] | None:
    value = os.environ.get(LOAD_PLUGINS_ENV)
    if value is None:
        return None
    return frozenset(name.strip() for name in value.split(",") if name.strip())


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
        self._collected: Contributions | None = None
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
            description = first_line(getattr(plugin, "__doc__", None))
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
            summary = (dist.metadata.get("Summary") or "") if dist is not None else ""
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
                    described = first_line(getattr(plugin, "__doc__", None)) or summary
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
            printable(f"skelagnostic plugin {name!r} ({source}) skipped: {error_text(exc)}"),
            PluginLoadWarning,
            stacklevel=3,
        )
        key = name if key is None else key
        old = self._infos.get(key)
        hooks = old.hooks if old is not None else ()
        description = old.description if old is not None else ""
        self._infos[key] = PluginInfo(
            name, version, source, "failed", error_text(exc), hooks, description=description
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

    def _collect(self) -> Contributions:
        if self._collected is not None:
            return self._collected
        total = Contributions()
        owners: dict[tuple[str, str], str] = {}
        for name, info in list(self._infos.items()):
            if info.status != "loaded":
                continue
            plugin = self._pm.get_plugin(name)
            with _user_interrupts() as interrupts:
                try:
                    mine = call_hooks(self._pm, plugin, name)
                    names = registered_names(mine, owners, name)
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
    undecorated = sorted(a for a in unmarked if a in HOOKS)
    if undecorated or (foreign and not hooks):
        names = undecorated or foreign
        why = " (marked by another project's HookimplMarker)" if set(names) & set(foreign) else ""
        return (
            f"{target}: {', '.join(names)} is not decorated with "
            f"@skelagnostic.plugins.hookimpl{why}, so skelagnostic never calls it"
        )
    if hooks:
        return None
    close = sorted(a for a in unmarked if difflib.get_close_matches(a, HOOKS, n=1, cutoff=0.8))
    hint = f" (misspelt hook? {', '.join(close)})" if close else ""
    return (
        f"{target} implements no skelagnostic hook{hint}: decorate functions named "
        f"{', '.join(HOOKS)} with @skelagnostic.plugins.hookimpl"
    )


def _lookup(table: Mapping[str, Any], name: str, kind: str) -> Any:
    if name not in table:
        known = ", ".join(sorted(table)) or "none"
        raise PluginError(f"unknown {kind} {name!r}; registered: {known}")
    return table[name]
