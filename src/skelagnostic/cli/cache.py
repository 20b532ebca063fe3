"""``skelagnostic cache info|clear``: what the window cache holds, and emptying it."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from skelagnostic.data.cache import CACHE_ENV, WindowCache, default_cache_dir
from skelagnostic.errors import SkelagnosticError, error_line, printable


def _size(num: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if num < 1024 or unit == "GiB":
            return f"{num:.0f} {unit}" if unit == "B" else f"{num:.1f} {unit}"
        num /= 1024
    return f"{num:.1f} GiB"  # pragma: no cover


def info(cache: WindowCache, verbose: bool) -> int:
    """Print the directory, entry count and size; with ``verbose`` one line per entry."""
    rows = list(cache.entries())
    print(printable(f"cache: {cache.root}"))
    print(f"entries: {len(rows)}, size: {_size(cache.size())}")
    if verbose:
        for key, array, meta in rows:
            size = array.stat().st_size + (
                array.with_suffix(".json").stat().st_size
                if array.with_suffix(".json").exists()
                else 0
            )
            what = (
                "(unreadable metadata)"
                if meta is None
                else f"{meta.get('clip', '?')} (motion for augmentation)"
                if meta.get("kind") == "motion"
                else f"{meta.get('clip', '?')} ({len(meta.get('starts', []))} windows)"
            )
            print(printable(f"  {key[:12]}  {_size(size):>10}  {what}"))
    return 0


#: Paths left alone that ``cache clear`` names one by one (the others are counted).
SHOWN_KEPT = 10


def clear(cache: WindowCache) -> int:
    """Delete every file the cache wrote; print what was freed and what was left alone.

    Files in the cache's folders that it did not write (a note, a link, a folder)
    are not deleted (:meth:`WindowCache.clear`); one line on stderr names them.
    """
    report = cache.clear()
    print(
        printable(f"cache: {cache.root}: removed {report.entries} entries ({_size(report.freed)})")
    )
    if report.kept:
        shown = ", ".join(printable(p) for p in report.kept[:SHOWN_KEPT])
        more = len(report.kept) - SHOWN_KEPT
        print(
            f"skelagnostic cache: left alone {len(report.kept)} path(s) the cache did not "
            f"write: {shown}{f' and {more} more' if more > 0 else ''}",
            file=sys.stderr,
        )
    return 0


def main(argv: Sequence[str]) -> int:
    """Run ``skelagnostic cache info`` or ``skelagnostic cache clear``.

    Args:
        argv: Arguments after the verb.

    Returns:
        The exit code: 0, 1 when the cache cannot be read or a file of it cannot be
        deleted, or 2 for a usage error.
    """
    parser = argparse.ArgumentParser(
        prog="skelagnostic cache",
        description="Show or empty the window cache (data.cache_dir; default "
        f"${CACHE_ENV} or ~/.cache/skelagnostic).",
    )
    parser.add_argument(
        "action",
        choices=("info", "clear"),
        help="info: directory, entries and size; clear: delete every entry (files the "
        "cache did not write are left alone and named)",
    )
    parser.add_argument(
        "--cache-dir",
        type=Path,
        default=None,
        help="the cache directory (default: the one training uses)",
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="info: one line per entry (key, size, clip, windows)",
    )
    args = parser.parse_args(list(argv))
    cache = WindowCache(args.cache_dir if args.cache_dir is not None else default_cache_dir())
    if cache.root.exists() and not cache.root.is_dir():
        where = "--cache-dir " if args.cache_dir is not None else "the default cache directory "
        message = f"{where}{cache.root} is not a directory"
        print(error_line("skelagnostic cache", message), file=sys.stderr)
        return 1
    try:
        return info(cache, args.verbose) if args.action == "info" else clear(cache)
    except SkelagnosticError as exc:
        print(error_line("skelagnostic cache", str(exc)), file=sys.stderr)
        return 1
