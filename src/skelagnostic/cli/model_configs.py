"""Hydra configs of the registered aligners, made from what each plugin registered.

A plugin registers an aligner with its config file; the plugin manager reads it once
(:func:`skelagnostic.plugins.read_aligner_config`) into the aligner's
:class:`~skelagnostic.plugins.AlignerSpec`. :func:`register_model_configs` turns each
spec into the config groups ``model=<name>``, ``data/<name>`` and ``_aligner/<name>``
that ``model=<name>`` brings along, so Hydra never reads the file a second time and
``conf/config.yaml`` names no aligner setting.
"""

from __future__ import annotations

import re
from typing import Any

from hydra.core.config_store import ConfigStore

from skelagnostic.plugins import AlignerSpec, PluginManager

#: Provider name of the configs this module puts into Hydra's ConfigStore.
PROVIDER = "skelagnostic"
#: Config group of the per-aligner ``model.name``, data and trainer options (internal).
ALIGNER_GROUP = "_aligner"
#: Hydra's refusal of a file ``model/<name>.yaml`` named like a registered aligner.
_SHADOWED = re.compile(
    r"'model/(?P<name>[^']+)' is validated against ConfigStore schema with the same name.*"
    r"(?:See https://\S+ for migration instructions\.)?"
)


def register_model_configs(pm: PluginManager) -> None:
    """Store each registered aligner's configs in Hydra's ConfigStore.

    For every aligner ``<name>``:

    * ``model/<name>``: ``_target_`` and the registered defaults (the ``model``
      section of the aligner's config file), with a defaults list that selects the
      two below (:func:`_model_defaults`);
    * ``_aligner/<name>`` (global package): ``model.name`` and the aligner's
      ``data_options`` and ``trainer_options``;
    * ``data/<name>`` (chosen for ``data`` unless the command line or an experiment
      names ``data=``): the aligner's default data, else ``procedural``.

    Hydra's ConfigStore is one per process: the entries stored for an earlier
    plugin manager (tagged with the provider ``skelagnostic``) are removed
    first, so it lists exactly the aligners of ``pm``.
    """
    store = ConfigStore.instance()
    for group in ("model", "data", ALIGNER_GROUP):
        nodes = store.repo.get(group, {})
        for key in [k for k, v in nodes.items() if getattr(v, "provider", None) == PROVIDER]:
            del nodes[key]
    for name, spec in pm.aligners.items():
        model = {
            "defaults": _model_defaults(name),
            "_target_": spec.target,
            **dict(spec.config),
        }
        store.store(group="model", name=name, node=model, provider=PROVIDER)
        store.store(group="data", name=name, node=_data_node(spec), provider=PROVIDER)
        store.store(
            group=ALIGNER_GROUP,
            name=name,
            node=_aligner_node(spec),
            package="_global_",
            provider=PROVIDER,
        )


def _model_defaults(name: str) -> list[Any]:
    """The defaults list of ``model/<name>``: its aligner options, then its default data.

    ``_aligner/<name>`` is merged after the model (so its ``data_options`` win over any
    data, and an experiment or the command line wins over them); ``override /data``
    makes ``data/<name>`` the data unless the command line or an experiment names one
    (Hydra wants overrides last in a defaults list).
    """
    return [
        "_self_",
        {f"/{ALIGNER_GROUP}@_global_": name},
        {"override /data@_global_.data": name},
    ]


def _data_node(spec: AlignerSpec) -> dict[str, Any]:
    """``data/<name>``: the aligner's default data over the shared keys, else ``procedural``."""
    data: dict[str, Any] = dict(spec.data) if spec.data else {}
    base = "/data_defaults@_here_" if data else "/data/procedural@_here_"
    return {"defaults": [base, "_self_"], **data}


def _aligner_node(spec: AlignerSpec) -> dict[str, Any]:
    """``_aligner/<name>``: ``model.name`` and the aligner's data and trainer options."""
    node: dict[str, Any] = {"model": {"name": spec.name}}
    if spec.data_options:
        node["data"] = dict(spec.data_options)
    if spec.trainer_options:
        node["trainer"] = dict(spec.trainer_options)
    return node


def explain_shadowed_model(message: str) -> str:
    """``message`` with Hydra's refusal of a same-named ``model/<name>.yaml`` made plain.

    A file of the user's on the search path named like a registered aligner cannot be
    merged over its config (which has a defaults list, :func:`_model_defaults`); Hydra
    says so in terms of its own schema matching. The plain message names the file and
    the fix (a variant under a new name, docs/configuration.md).

    Args:
        message: An error message, Hydra's lines joined.

    Returns:
        The message, that part rewritten when present.

    Examples:
        >>> text = explain_shadowed_model(
        ...     "'model/humot' is validated against ConfigStore schema with the same name."
        ... )
        >>> text.startswith("model/humot.yaml on the config search path is named like")
        True
    """
    return _SHADOWED.sub(
        lambda m: (
            f"model/{m['name']}.yaml on the config search path is named like the registered "
            f"aligner {m['name']!r}, whose config it cannot replace: rename it (e.g. "
            f"model/{m['name']}_mine.yaml, used as model={m['name']}_mine) and start it with "
            f"'defaults: [{m['name']}, _self_]' (see docs/configuration.md)"
        ),
        message,
        count=1,
    )
