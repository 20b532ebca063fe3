"""The ``register`` callbacks handed to one plugin's hooks, and the check of the names it took.

:func:`call_hooks` calls a plugin's hook implementations, each with the matching
method of a :class:`Registrar` bound to that plugin; the methods check what they
are given (a :class:`~skelagnostic.plugins.PluginError` otherwise) and record it,
so every contribution is attributed to its plugin.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import pluggy

from skelagnostic.plugins.configs import check_target, config_urls, read_aligner_config
from skelagnostic.plugins.specs import (
    AlignerSpec,
    CheckpointReaderSpec,
    Contributions,
    DatasetSpec,
    EvaluationSpec,
    PluginError,
    Ref,
    RepresentationSpec,
    first_line,
    is_ref,
    ref_target,
)

if TYPE_CHECKING:
    from skelagnostic.plugins.protocols import AlignerConfigSource

#: The hooks of :mod:`skelagnostic.plugins.hookspecs`, in the order they are called.
HOOKS = (
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


class Registrar:
    """The ``register`` callbacks of one plugin; :attr:`out` collects what it registered.

    Args:
        plugin_name: The plugin's name, recorded in every spec.
    """

    def __init__(self, plugin_name: str) -> None:
        self.plugin_name = plugin_name
        self.out = Contributions()

    def callbacks(self) -> dict[str, Callable[..., None]]:
        """The ``register`` callback of each hook, by hook name."""
        return {
            "register_aligners": self.aligner,
            "register_representations": self.representation,
            "register_datasets": self.dataset,
            "register_config_paths": self.config_path,
            "register_evaluations": self.evaluation,
            "register_checkpoint_readers": self.checkpoint_reader,
        }

    def aligner(
        self,
        name: str,
        module: Ref,
        datamodule: Ref = None,
        config: AlignerConfigSource | None = None,
        description: str = "",
    ) -> None:
        """``register`` of ``register_aligners``: reads the aligner's config file, once."""
        _check_aligner_classes(name, module, datamodule)
        sections = read_aligner_config({} if config is None else config)
        model = sections["model"]
        if "_target_" in model:
            target = model.pop("_target_")
            if is_ref(module):  # compared as text: nothing is imported
                if target != ref_target(module):
                    raise PluginError(
                        f"aligner {name!r}: config _target_={target!r} does not name the "
                        f"registered module {ref_target(module)!r}"
                    )
            else:
                check_target(name, target, module)
        if "name" in model:
            raise PluginError(f"aligner {name!r}: config key 'name' is reserved")
        if sections["data"] and "source" not in sections["data"]:
            raise PluginError(f"aligner {name!r}: data needs a 'source' (a registered dataset)")
        self.out.aligners.append(
            AlignerSpec(
                name,
                module,
                datamodule,
                MappingProxyType(model),
                description,
                self.plugin_name,
                MappingProxyType(sections["data"]),
                MappingProxyType(sections["data_options"]),
                MappingProxyType(sections["trainer_options"]),
            )
        )

    def representation(self, name: str, cls: Ref) -> None:
        """``register`` of ``register_representations``."""
        spec = RepresentationSpec(name, _ref_or(cls, "representation", name), self.plugin_name)
        if not is_ref(cls):
            spec.cls  # noqa: B018 - an object is checked now (a reference when first used)
        self.out.representations.append(spec)

    def dataset(self, name: str, factory: Ref, description: str = "") -> None:
        """``register`` of ``register_datasets``."""
        if not (is_ref(factory) or callable(factory)):
            raise PluginError(f"dataset {name!r}: factory must be callable, got {factory!r}")
        self.out.datasets.append(DatasetSpec(name, factory, description, self.plugin_name))

    def config_path(self, path: str) -> None:
        """``register`` of ``register_config_paths``."""
        for url in config_urls(path, self.plugin_name):
            self.out.config_paths.append((url, self.plugin_name))

    def evaluation(
        self,
        name: str,
        function: Ref,
        model: str,
        description: str = "",
        default: bool = False,
    ) -> None:
        """``register`` of ``register_evaluations``."""
        if not (is_ref(function) or callable(function)):
            raise PluginError(f"evaluation {name!r}: function must be callable, got {function!r}")
        _require_model(f"evaluation {name!r}", model)
        if default and any(e.default and e.model == model for e in self.out.evaluations):
            raise PluginError(f"evaluation {name!r}: model={model} already has a default protocol")
        description = description or first_line(getattr(function, "__doc__", None))
        self.out.evaluations.append(
            EvaluationSpec(name, function, model, description, bool(default), self.plugin_name)
        )

    def checkpoint_reader(
        self, scheme: str, reader: Ref, model: str, description: str = ""
    ) -> None:
        """``register`` of ``register_checkpoint_readers``."""
        if not isinstance(scheme, str) or not CHECKPOINT_SCHEME.fullmatch(scheme):
            raise PluginError(
                f"checkpoint reader {scheme!r}: the scheme must be a lower-case "
                "word of two or more letters, digits or underscores"
            )
        if not (is_ref(reader) or callable(reader)):
            raise PluginError(
                f"checkpoint reader {scheme!r}: reader must be callable, got {reader!r}"
            )
        _require_model(f"checkpoint reader {scheme!r}", model)
        description = description or first_line(getattr(reader, "__doc__", None))
        self.out.checkpoint_readers.append(
            CheckpointReaderSpec(scheme, reader, model, description, self.plugin_name)
        )


def _check_aligner_classes(name: str, module: Any, datamodule: Any) -> None:
    """Check ``module`` and ``datamodule`` of an aligner now when they are objects.

    A reference (``"package.module:Class"``) is checked when it is first used,
    so registering it imports nothing.
    """
    spec = AlignerSpec(
        name, _ref_or(module, "aligner", name), _ref_or(datamodule, "aligner", name, none=True)
    )
    if not is_ref(module):
        spec.module  # noqa: B018 - the check is the property's
    if datamodule is not None and not is_ref(datamodule):
        spec.datamodule  # noqa: B018


def _ref_or(obj: Any, kind: str, name: str, none: bool = False) -> Any:
    """``obj``, unless it is a string that is not a reference (a clear error then)."""
    if isinstance(obj, str) and not is_ref(obj):
        raise PluginError(
            f"{kind} {name!r}: {obj!r} is neither an object nor a reference 'package.module:name'"
        )
    if obj is None and not none:
        raise PluginError(f"{kind} {name!r}: got None")
    return obj


def _require_model(what: str, model: Any) -> None:
    """Raise :class:`PluginError` unless ``model`` is a non-empty aligner name."""
    if not isinstance(model, str) or not model:
        raise PluginError(f"{what}: model must be an aligner name, got {model!r}")


def call_hooks(pm: pluggy.PluginManager, plugin: object, plugin_name: str) -> Contributions:
    """Call one plugin's registration hooks and return what it registered."""
    registrar = Registrar(plugin_name)
    callbacks = registrar.callbacks()
    for hook_name in HOOKS:
        for impl in getattr(pm.hook, hook_name).get_hookimpls():
            if impl.plugin is plugin:
                impl.function(register=callbacks[hook_name])
    return registrar.out


def registered_names(
    mine: Contributions, owners: Mapping[tuple[str, str], str], plugin_name: str
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
