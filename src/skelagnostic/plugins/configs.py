"""Reading plugin configs: an aligner's YAML file and the Hydra search paths plugins register.

An aligner's configuration lives in one YAML file, which its plugin names when it
registers the aligner (``register(name, module, datamodule, config=<file>)``);
skelagnostic reads it once, here, and Hydra's ``model/<name>``, ``data/<name>``
and ``_aligner/<name>`` configs are made from what was read (see
:mod:`skelagnostic.cli.model_configs`). The file has up to four sections::

    model:            # model/<name>: _target_ (the aligner class) and every constructor argument
      _target_: my_plugin.aligner.MyAligner
      hidden: 64
    data:             # data/<name>: the default data when the command line names no data=
      source: procedural
      kinds: [biped22]
    data_options:     # data-module keys the aligner needs whatever the data
      window: 30
    trainer_options:  # trainer keys it needs by default (never a limit such as max_steps)
      gradient_clip_val: 1.0

This module imports neither Hydra nor pluggy (OmegaConf reads the YAML).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from skelagnostic.plugins.specs import PluginError, error_text

if TYPE_CHECKING:
    from skelagnostic.plugins.protocols import AlignerConfigSource

#: The sections of an aligner's config file, in order.
ALIGNER_SECTIONS = ("model", "data", "data_options", "trainer_options")


def read_aligner_config(source: AlignerConfigSource) -> dict[str, dict[str, Any]]:
    """Read an aligner's config file: ``model``, ``data``, ``data_options``, ``trainer_options``.

    Args:
        source: The YAML file (a path or an ``importlib.resources`` traversable), or
            its content as a mapping.

    Returns:
        Every section (empty when the file leaves it out), unresolved; ``model``
        keeps its ``_target_``.

    Raises:
        PluginError: The file cannot be read, is not valid YAML, is not a mapping of
            the sections above, or a section is not a mapping; a file's ``model``
            needs a ``_target_``. The message names the file.
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException
    from yaml import YAMLError

    if isinstance(source, Mapping):
        where, content = "config", OmegaConf.to_container(OmegaConf.create(dict(source)))
    else:
        where = f"aligner config {source}"
        try:
            text = _read_text(source)
        except OSError as exc:
            raise PluginError(f"{where}: cannot be read ({error_text(exc)})") from exc
        try:
            node = OmegaConf.create(text) if text.strip() else None
        except (YAMLError, OmegaConfBaseException) as exc:
            raise PluginError(f"{where}: invalid YAML ({error_text(exc)})") from exc
        if node is None or not OmegaConf.is_dict(node):
            raise PluginError(f"{where}: expected a mapping with a 'model' section")
        content = OmegaConf.to_container(node, resolve=False)
    return _sections(content, where, needs_target=not isinstance(source, Mapping))


def _read_text(source: Any) -> str:
    """The text of a path or a traversable."""
    if hasattr(source, "read_text") and not isinstance(source, (str, os.PathLike)):
        return str(source.read_text(encoding="utf-8"))
    return Path(source).read_text(encoding="utf-8")


def _sections(content: Any, where: str, *, needs_target: bool) -> dict[str, dict[str, Any]]:
    """Check the sections of an aligner config; every one present, as a plain dict."""
    unknown = sorted(set(content) - set(ALIGNER_SECTIONS))
    if unknown:
        raise PluginError(
            f"{where}: unknown section(s) {', '.join(map(repr, unknown))}; an aligner "
            f"config has {', '.join(ALIGNER_SECTIONS)} (the constructor's arguments go "
            "under 'model')"
        )
    sections: dict[str, dict[str, Any]] = {}
    for key in ALIGNER_SECTIONS:
        value = content.get(key) or {}
        if not isinstance(value, Mapping):
            raise PluginError(f"{where}: '{key}' must be a mapping, got {value!r}")
        sections[key] = dict(value)
    if needs_target and not isinstance(sections["model"].get("_target_"), str):
        raise PluginError(
            f"{where}: 'model' needs '_target_', the dotted path of the "
            "aligner class (e.g. 'my_plugin.aligner.MyAligner')"
        )
    return sections


def target_of(cls: type) -> str:
    """The ``_target_`` naming ``cls``: ``"<module>.<qualname>"``."""
    return f"{cls.__module__}.{cls.__qualname__}"


def check_target(name: str, target: Any, module: type) -> None:
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


def config_urls(path: str, plugin_name: str) -> list[str]:
    """Hydra search-path URLs for a registered config path.

    Hydra's ``pkg://`` source expects a regular package: for a directory without
    ``__init__.py`` (a namespace package) it warns that the path "is not
    available" (and whether it still reads the files depends on the Python
    version and the installation). Such a package is registered as the
    ``file://`` URL of its directory (or directories) instead.

    Raises:
        PluginError: ``path`` is no search-path URL, or a ``pkg://`` URL names no
            importable package.
    """
    if not isinstance(path, str) or "://" not in path:
        raise PluginError(
            f"config path {path!r}: expected a Hydra search-path URL such as "
            "'pkg://my_plugin.conf' or 'file:///abs/dir'"
        )
    if not path.startswith("pkg://"):
        return [path]
    package = path[len("pkg://") :].strip("/").replace("/", ".")
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError) as exc:
        spec, error = None, f" ({error_text(exc)})"
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
