"""``skelagnostic plugins [NAME]``: what each plugin provides; one aligner's defaults.

Without ``NAME``: per plugin its version, source, status (with the error of a
failed plugin), description, aligners, experiments, data presets, datasets and
representations. With ``NAME`` (an aligner, or a plugin: then each of its
aligners): the aligner's capabilities and its default config, i.e. what
``skelagnostic fit model=NAME`` starts from.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Sequence
from dataclasses import asdict
from typing import Any

from rich.console import Console
from rich.markup import escape

from skelagnostic.plugins import (
    AlignerSpec,
    PluginInfo,
    PluginLoadWarning,
    PluginManager,
    get_plugin_manager,
)

#: ``provides`` kinds in display order, with their labels and the setting they fill.
_KINDS = (
    ("aligner", "aligners", "model="),
    ("experiment", "experiments", "experiment="),
    ("data_preset", "data presets", "data="),
    ("dataset", "datasets", "data.source="),
    ("representation", "representations", "data.representation="),
    ("checkpoint reader", "checkpoint readers", "ckpt=<scheme>:<path>"),
)
#: The capabilities ``skelagnostic plugins NAME`` always answers (label, capability).
HEADLINE_CAPABILITIES = (
    ("retarget", "retarget"),
    ("interpolate", "interpolate"),
    ("transfer", "transfer"),
    ("unseen topology", "unseen_topology"),
)


def _grouped(items: Sequence[str]) -> dict[str, list[str]]:
    by_kind: dict[str, list[str]] = {}
    for item in items:
        kind, name = item.split(":", 1)
        by_kind.setdefault(kind, []).append(name)
    return by_kind


def _status(info: PluginInfo) -> str:
    if info.status == "loaded":
        return "[green]loaded[/]"
    if info.status == "failed":
        return f"[red]failed[/]: {escape(info.error or '')}"
    return f"[dim]{info.status}[/]"


def _print_plugin(console: Console, info: PluginInfo) -> None:
    version = f" {info.version}" if info.version else ""
    console.print(
        f"[bold]{escape(info.name)}[/]{version} ({escape(info.source)}) {_status(info)}",
        highlight=False,
    )
    if info.description:
        console.print(f"  {escape(info.description)}", highlight=False)
    grouped = _grouped(info.provides)
    for kind, label, setting in _KINDS:
        if grouped.get(kind):
            console.print(f"  {label} ({setting}): {', '.join(grouped[kind])}", highlight=False)


def aligner_details(spec: AlignerSpec) -> dict[str, Any]:
    """What ``skelagnostic plugins NAME`` shows about one aligner, as plain data.

    Args:
        spec: The registered aligner.

    Returns:
        ``name``, ``plugin``, ``description``, ``module``, ``datamodule``,
        ``capabilities`` (the headline ones as booleans), ``declared`` (every
        declared capability), ``config`` (the ``model/<name>`` defaults), ``data``,
        ``data_options`` and ``trainer_options``.
    """
    declared = sorted(getattr(spec.module, "capabilities", ()))
    return {
        "name": spec.name,
        "plugin": spec.plugin,
        "description": spec.description,
        "module": f"{spec.module.__module__}.{spec.module.__qualname__}",
        "datamodule": f"{spec.datamodule.__module__}.{spec.datamodule.__qualname__}",
        "capabilities": {cap: cap in declared for _, cap in HEADLINE_CAPABILITIES},
        "declared": declared,
        "config": _plain(spec.config),
        "data": _plain(spec.data),
        "data_options": _plain(spec.data_options),
        "trainer_options": _plain(spec.trainer_options),
    }


def _plain(mapping: Any) -> dict[str, Any]:
    """A JSON-able copy of a (read-only) mapping of config values."""
    return json.loads(json.dumps(dict(mapping), default=str))


def _print_aligner(console: Console, details: dict[str, Any], info: PluginInfo | None) -> None:
    from omegaconf import OmegaConf

    plugin = details["plugin"] + (f" {info.version}, {info.source}" if info else "")
    console.print(
        f"[bold]aligner {escape(details['name'])}[/] (plugin {escape(plugin)})", highlight=False
    )
    if details["description"]:
        console.print(f"  {escape(details['description'])}", highlight=False)
    console.print(
        f"  module: {details['module']}\n  datamodule: {details['datamodule']}", highlight=False
    )
    console.print("capabilities:")
    for label, cap in HEADLINE_CAPABILITIES:
        mark = "[green]yes[/]" if details["capabilities"][cap] else "[dim]no[/]"
        console.print(f"  {label}: {mark}")
    console.print(f"  declared: {', '.join(details['declared']) or 'none'}", highlight=False)
    sections = (
        ("defaults (model.<key>=...)", "config"),
        ("default data (used without data=...)", "data"),
        ("data options (data.<key>=...)", "data_options"),
        ("trainer options (trainer.<key>=...)", "trainer_options"),
    )
    for title, key in sections:
        if details[key]:
            console.print(f"{title}:")
            text = OmegaConf.to_yaml(OmegaConf.create(details[key])).rstrip()
            console.print(
                "\n".join(f"  {line}" for line in text.splitlines()), highlight=False, markup=False
            )


def main(argv: Sequence[str]) -> int:
    """List the plugins, or show one aligner (``--json`` for machine-readable output).

    Broken plugins are listed with status ``failed`` and their error; the
    command still succeeds.

    Args:
        argv: Arguments after the verb.

    Returns:
        The exit code: 0, or 2 when ``NAME`` is neither an aligner nor a plugin.
    """
    parser = argparse.ArgumentParser(
        prog="skelagnostic plugins",
        description="List plugins (version, status, description, aligners, experiments, data "
        "presets) or, with NAME, one aligner's capabilities and default config.",
    )
    parser.add_argument(
        "name",
        nargs="?",
        metavar="NAME",
        help="an aligner (model=NAME) or a plugin (each of its aligners)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    args = parser.parse_args(list(argv))
    with warnings.catch_warnings():  # failures are shown in the listing instead
        warnings.simplefilter("ignore", PluginLoadWarning)
        pm = get_plugin_manager()
        listed = pm.plugins()
    infos: dict[str, PluginInfo] = {}
    for info in listed:  # a name two distributions claim: the one loaded first
        infos.setdefault(info.name, info)
    console = Console(soft_wrap=True)
    if args.name is None:
        if args.json:
            print(json.dumps([asdict(info) for info in listed], indent=2))
            return 0
        for info in listed:
            _print_plugin(console, info)
        return 0
    if args.name in pm.aligners:
        specs = [pm.aligners[args.name]]
    elif args.name in infos:
        specs = [s for s in pm.aligners.values() if s.plugin == args.name]
    else:
        print(
            f"skelagnostic plugins: {args.name!r} is neither an aligner nor a plugin; "
            f"aligners: {', '.join(sorted(pm.aligners)) or 'none'}; "
            f"plugins: {', '.join(infos)}",
            file=sys.stderr,
        )
        return 2
    details = [aligner_details(spec) for spec in specs]
    if args.json:
        print(
            json.dumps(
                details[0]
                if args.name in pm.aligners
                else {"plugin": asdict(infos[args.name]), "aligners": details},
                indent=2,
            )
        )
        return 0
    if args.name not in pm.aligners:
        _print_plugin(console, infos[args.name])
    for item in details:
        _print_aligner(console, item, infos.get(item["plugin"]))
    return 0


def protocols_text(pm: PluginManager) -> str:
    """The registered protocols, one line each: name, model, description (``*``: default).

    ``skelagnostic evaluate --help`` prints it before Hydra's help; the protocols'
    modules are not imported for it (they register by reference).
    """
    specs = sorted(pm.evaluations.values(), key=lambda e: (e.model, not e.default, e.name))
    if not specs:
        return (
            "Evaluation protocols: none registered (a plugin registers them with "
            "register_evaluations)."
        )
    width = max(len(e.name) for e in specs) + 2
    lines = ["Evaluation protocols (protocol=NAME; * = the model's default):"]
    for e in specs:
        mark = "*" if e.default else " "
        lines.append(f"  {mark} {e.name:<{width}} model={e.model}: {e.description}")
    return "\n".join(lines) + "\n"
