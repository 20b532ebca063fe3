"""``skelagnostic plugins``: name, version, source and status of each plugin."""

from __future__ import annotations

import argparse
import json
import warnings
from collections.abc import Sequence
from dataclasses import asdict

from rich.console import Console
from rich.table import Table

from skelagnostic.plugins import PluginLoadWarning, get_plugin_manager


def _provides(items: Sequence[str]) -> str:
    by_kind: dict[str, list[str]] = {}
    for item in items:
        kind, name = item.split(":", 1)
        by_kind.setdefault(kind, []).append(name)
    return "\n".join(f"{kind}s: {', '.join(names)}" for kind, names in by_kind.items())


def main(argv: Sequence[str]) -> int:
    """List the plugins (``--json`` for machine-readable output).

    Broken plugins are listed with status ``failed`` and their error; the
    command still succeeds.

    Args:
        argv: Arguments after the verb.

    Returns:
        The exit code (0).
    """
    parser = argparse.ArgumentParser(
        prog="skelagnostic plugins",
        description="List plugins: name, version, source, status and what they provide.",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(list(argv))
    with warnings.catch_warnings():  # failures are shown in the table instead
        warnings.simplefilter("ignore", PluginLoadWarning)
        infos = get_plugin_manager().plugins()
    if args.json:
        print(json.dumps([asdict(info) for info in infos], indent=2))
        return 0
    table = Table(title="skelagnostic plugins")
    for column in ("name", "version", "source", "status", "provides"):
        table.add_column(column, overflow="fold")
    for info in infos:
        status = "[green]loaded[/]" if info.status == "loaded" else (
            f"[red]failed[/]: {info.error}" if info.status == "failed" else f"[dim]{info.status}[/]"
        )
        table.add_row(info.name, info.version, info.source, status, _provides(info.provides))
    Console().print(table)
    return 0
