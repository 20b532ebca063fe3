"""Reading plugin configs: an aligner's model YAML file and the Hydra search paths plugins register.

This module imports neither Hydra nor pluggy (OmegaConf reads the YAML).
"""

from __future__ import annotations

import importlib
import importlib.util
from importlib import resources
from pathlib import Path
from typing import Any

from skelagnostic.plugins.specs import PluginError, error_text


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
        raise PluginError(f"model config {where}: cannot be read ({error_text(exc)})") from exc
    try:
        node = OmegaConf.create(text) if text.strip() else None
    except (YAMLError, OmegaConfBaseException) as exc:
        raise PluginError(f"model config {where}: invalid YAML ({error_text(exc)})") from exc
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
