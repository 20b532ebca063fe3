"""Turn benchmark JSON files into a Markdown table (for docs/reports/performance.md).

Usage::

    python benchmarks/report.py results/*.json                  # print the table
    python benchmarks/report.py results/*.json --update docs/reports/performance.md

``--update`` replaces what lies between the ``<!-- benchmarks:start -->`` and
``<!-- benchmarks:end -->`` lines of the file; with ``--block NAME``, between
``<!-- benchmarks:NAME:start -->`` and ``<!-- benchmarks:NAME:end -->`` (a page can
hold several generated blocks, e.g. ``--block authors`` for the comparison with
the official code).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

START, END = "<!-- benchmarks:start -->", "<!-- benchmarks:end -->"


def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def render(reports: list[dict[str, Any]]) -> str:
    """One Markdown section per JSON report: machine line and a results table."""
    parts = []
    for report in reports:
        machine, versions = report["machine"], report["versions"]
        threads = machine.get("torch_threads")
        parts.append(
            f"**Suite `{report['suite']}`**: {machine['cpu_count']} CPUs "
            f"({machine['processor']}), {machine['ram_gib']} GiB RAM"
            + (f", {threads} torch thread(s)" if threads else "")
            + (
                f", {machine['allocator']} allocator"
                if machine.get("allocator", "system") != "system"
                else ""
            )
            + (
                f", load average {machine['load_average_start']:g} -> "
                f"{machine['load_average_end']:g}"
                if "load_average_start" in machine
                else ""
            )
            + "; "
            + ", ".join(f"{name} {version}" for name, version in versions.items() if version)
            + "\n"
        )
        rows = [
            "| figure | value | unit | baseline | baseline value | speedup |",
            "|---|---:|---|---|---:|---:|",
        ]
        for r in report["results"]:
            speedup = "-" if r["speedup"] is None else f"{r['speedup']:.2f}x"
            rows.append(
                f"| `{r['name']}` | {_num(r['value'])} | {r['unit']} | {r['baseline'] or '-'} "
                f"| {_num(r['baseline_value'])} | {speedup} |"
            )
        parts.append("\n".join(rows) + "\n")
    return "\n".join(parts)


def markers(block: str | None) -> tuple[str, str]:
    """The start and end lines of the generated block ``block`` (None: the main block)."""
    if block is None:
        return START, END
    return f"<!-- benchmarks:{block}:start -->", f"<!-- benchmarks:{block}:end -->"


def update(path: Path, table: str, block: str | None = None) -> None:
    """Replace the marked block of ``path`` (the main one, or ``block``) with ``table``."""
    start, end = markers(block)
    text = path.read_text()
    if start not in text or end not in text:
        raise SystemExit(f"{path}: no {start} ... {end} block to update")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{start}\n{table}{end}{tail}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reports", nargs="+", type=Path, help="JSON files from run.py --json")
    parser.add_argument("--update", type=Path, default=None, help="Markdown file to update")
    parser.add_argument(
        "--block", default=None, help="generated block to update (default: the main one)"
    )
    args = parser.parse_args(argv)
    table = render([json.loads(p.read_text()) for p in args.reports])
    if args.update is None:
        print(table)
    else:
        update(args.update, table, args.block)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
