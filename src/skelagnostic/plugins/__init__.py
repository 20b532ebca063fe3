"""Plugins: how aligners, representations, datasets and configs get into skelagnostic.

A plugin is a module with :data:`hookimpl` functions named after the hooks in
:mod:`skelagnostic.plugins.hookspecs`, exposed through the ``skelagnostic``
entry-point group. The built-in components use the same path
(:mod:`skelagnostic.plugins.builtin`).

``SKELAGNOSTIC_LOAD_PLUGINS=a,b`` restricts which entry points are loaded
(empty: none); the built-in plugin is always loaded.

Examples:
    >>> import skelagnostic.plugins as plugins
    >>> "local_quaternions" in plugins.list_representations()
    True
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from skelagnostic.plugins.configs import read_aligner_config, target_of
from skelagnostic.plugins.hookspecs import hookimpl
from skelagnostic.plugins.manager import (
    ENTRY_POINT_GROUP,
    LOAD_PLUGINS_ENV,
    PluginManager,
)
from skelagnostic.plugins.protocols import (
    AlignerConfigSource,
    RegisterAligner,
    RegisterCheckpointReader,
    RegisterConfigPath,
    RegisterDataset,
    RegisterEvaluation,
    RegisterRepresentation,
)
from skelagnostic.plugins.specs import (
    AlignerSpec,
    CheckpointReaderSpec,
    DatasetSpec,
    EvaluationSpec,
    PluginError,
    PluginInfo,
    PluginLoadWarning,
    RepresentationSpec,
)

if TYPE_CHECKING:
    from skelagnostic.aligners import Aligner

__all__ = [
    "ENTRY_POINT_GROUP",
    "LOAD_PLUGINS_ENV",
    "AlignerConfigSource",
    "AlignerSpec",
    "CheckpointReaderSpec",
    "DatasetSpec",
    "EvaluationSpec",
    "PluginError",
    "PluginInfo",
    "PluginLoadWarning",
    "PluginManager",
    "RegisterAligner",
    "RegisterCheckpointReader",
    "RegisterConfigPath",
    "RegisterDataset",
    "RegisterEvaluation",
    "RegisterRepresentation",
    "RepresentationSpec",
    "get_plugin_manager",
    "hookimpl",
    "list_aligners",
    "list_datasets",
    "list_representations",
    "load_aligner",
    "read_aligner_config",
    "target_of",
]


@lru_cache(maxsize=1)
def get_plugin_manager() -> PluginManager:
    """The process-wide :class:`PluginManager`, created (and plugins loaded) on first use.

    ``get_plugin_manager.cache_clear()`` forgets it, e.g. after changing
    ``SKELAGNOSTIC_LOAD_PLUGINS``.
    """
    return PluginManager()


def list_aligners() -> list[str]:
    """Names of the registered aligners, sorted (the values ``model=`` accepts)."""
    return sorted(get_plugin_manager().aligners)


def list_representations() -> list[str]:
    """Names of the registered motion representations, sorted."""
    return sorted(get_plugin_manager().representations)


def list_datasets() -> list[str]:
    """Names of the registered dataset readers/presets, sorted (values of ``data.source``)."""
    return sorted(get_plugin_manager().datasets)


def load_aligner(name: str, checkpoint: str | Path | None = None, **overrides: Any) -> Aligner:
    """Build a registered aligner, from its default config or from a checkpoint.

    Args:
        name: Registered aligner name (see :func:`list_aligners`).
        checkpoint: A Lightning checkpoint written by ``skelagnostic fit``, or
            ``"<scheme>:<path>"`` read by a registered checkpoint reader (for example
            ``"authors:<run dir>"``; ``overrides`` are then not accepted); ``None``
            builds an untrained aligner from the registered default config.
        **overrides: Keyword arguments replacing the default (or saved) hyper-parameters.

    Returns:
        The aligner, in eval mode.

    The checkpoint is read with ``torch.load(weights_only=True)``, which never
    unpickles code (see :func:`skelagnostic.aligners.checkpoints.read_checkpoint`).

    Raises:
        PluginError: ``name`` is not registered.
        CheckpointError: ``checkpoint`` does not exist (a ``CheckpointNotFoundError``,
            also a ``FileNotFoundError``), is not a readable checkpoint, holds
            Python objects a safe load refuses, was written by another aligner or
            has a different architecture.
    """
    pm = get_plugin_manager()
    spec = pm.aligner(name)
    if checkpoint is not None:
        external = pm.read_external_checkpoint(checkpoint, name)
        if external is not None:
            if overrides:
                raise PluginError(
                    f"checkpoint {str(checkpoint)!r}: a checkpoint reader takes no "
                    f"hyperparameter overrides, got {sorted(overrides)}"
                )
            return external
    if checkpoint is None:
        model = spec.module(**{**spec.config, **overrides})
    else:
        from skelagnostic.aligners.checkpoints import load_checkpoint

        model = load_checkpoint(
            spec.module, Path(checkpoint), aligners=pm.aligner_classes(), **overrides
        )
    return model.eval()
