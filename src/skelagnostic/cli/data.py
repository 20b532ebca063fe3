"""``skelagnostic data prepare|get``: install a dataset from its archive.

``prepare PRESET --zip FILE --dest DIR`` verifies the archive's SHA-256 (the
checksum stored for the preset, or ``--sha256``), extracts it safely to
``DIR/<preset>/``, reads every BVH file and writes the window cache; ``get
PRESET --dest DIR`` first downloads the preset's public archive. Both end by
printing the ``data.root=`` and ``SKELAGNOSTIC_DATA=`` that find the files.
See :mod:`skelagnostic.data.prepare` and ``docs/data.md``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    DownloadColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeRemainingColumn,
)

from skelagnostic.core.paths import expand_path
from skelagnostic.data.prepare import (
    DataPrepareError,
    Opener,
    PreparedDataset,
    check_bvh_files,
    dataset_folder,
    default_datamodule,
    download,
    extract_archive,
    held_out_files,
    known_archive,
    verify_archive,
    write_window_cache,
)
from skelagnostic.data.sources import DATA_ROOT_ENV, PRESETS
from skelagnostic.errors import SkelagnosticError, error_line

__all__ = ["get", "main", "prepare"]

_NAMES = (*PRESETS, "bvh")


@contextmanager
def _bar(
    console: Console, label: str, total: int | None, in_bytes: bool
) -> Iterator[tuple[Callable[[int], None], Callable[[int], None]]]:
    """A Rich progress bar: yields ``(advance, set_total)``."""
    columns = [
        TextColumn("{task.description}"),
        BarColumn(),
        DownloadColumn() if in_bytes else MofNCompleteColumn(),
        TimeRemainingColumn(),
    ]
    with Progress(*columns, console=console, disable=not console.is_terminal) as progress:
        task = progress.add_task(label, total=total)
        yield (lambda n: progress.advance(task, n), lambda n: progress.update(task, total=n))


def _datamodule(preset: str, root: Path, cache_dir: Path | None, overrides: Sequence[str]) -> Any:
    """The data module whose cache ``prepare`` writes (see ``--help``)."""
    if not overrides:
        return default_datamodule(preset, root, cache_dir)
    if not any(o.split("=", 1)[0] == "model" for o in overrides):
        raise DataPrepareError(
            f"the overrides {' '.join(overrides)} choose an aligner's data module: add "
            "model=NAME (skelagnostic plugins lists them)"
        )
    from skelagnostic.cli.app import compose
    from skelagnostic.cli.build import build_datamodule
    from skelagnostic.plugins import get_plugin_manager

    extra = []
    if not any(o.split("=", 1)[0].lstrip("+~") == "data" for o in overrides):
        where = f"data.paths=['{root}']" if preset == "bvh" else f"data.root='{root}'"
        extra = [f"data={preset}", where]
    if cache_dir is not None:
        extra.append(f"data.cache_dir='{cache_dir}'")
    pm = get_plugin_manager()
    cfg = compose([*extra, *overrides], plugin_manager=pm)
    return build_datamodule(cfg, pm)


def prepare(
    preset: str,
    archive: Path,
    dest: Path,
    sha256: str | None = None,
    cache: bool = True,
    cache_dir: Path | None = None,
    overrides: Sequence[str] = (),
    console: Console | None = None,
) -> PreparedDataset:
    """Verify, extract and check ``archive``, then write the window cache.

    Args:
        preset: A dataset preset (:data:`~skelagnostic.data.PRESETS`) or ``bvh``.
        archive: The zip file.
        dest: Folder that receives ``<preset>/`` (``SKELAGNOSTIC_DATA``).
        sha256: The expected checksum; required when the preset stores none.
        cache: Write the window cache.
        cache_dir: The window cache directory (default: the one training uses).
        overrides: Config overrides choosing the data module of the cache
            (e.g. ``model=humot``); none: :class:`~skelagnostic.data.MotionDataModule`'s defaults.
        console: Where progress goes.

    Returns:
        What was installed.

    Raises:
        DataPrepareError: No checksum to compare with, a checksum mismatch, an unsafe
            or damaged archive, an unwritable ``dest`` or BVH files that do not parse.
    """
    console = console or Console(stderr=True)
    stored = known_archive(preset)
    expected = sha256 or (stored.sha256 if stored else None)
    if expected is None:
        raise DataPrepareError(
            f"no checksum is stored for {preset!r} archives: pass --sha256 HEX (the SHA-256 "
            "published with your archive, or 'sha256sum FILE' of a copy you trust)"
        )
    if not archive.is_file():
        raise DataPrepareError(f"--zip {archive}: no such file")
    root = dataset_folder(preset, dest)
    with _bar(console, "checksum", archive.stat().st_size, True) as (step, _):
        verify_archive(archive, expected, step)
    with _bar(console, "extract", None, True) as (step, set_total):
        files, written = extract_archive(archive, root, step, set_total)
    bvhs = sorted(p for p in files if p.suffix.lower() == ".bvh")
    if not bvhs:
        raise DataPrepareError(f"{archive}: the archive holds no .bvh file")
    with _bar(console, "parse", len(bvhs), False) as (step, _):
        check_bvh_files(bvhs, root, step)
    windows, where = 0, None
    if cache:
        datamodule = _datamodule(preset, root, cache_dir, overrides)
        with _bar(console, "cache", None, False) as (step, set_total):
            windows = write_window_cache(datamodule, step, set_total)
        where = Path(datamodule.cache.root)
    return PreparedDataset(
        preset,
        root,
        tuple(bvhs),
        tuple(held_out_files(preset, root)),
        len(files),
        written,
        windows,
        where,
    )


def get(
    preset: str,
    dest: Path,
    url: str | None = None,
    sha256: str | None = None,
    cache: bool = True,
    cache_dir: Path | None = None,
    overrides: Sequence[str] = (),
    opener: Opener | None = None,
    console: Console | None = None,
) -> PreparedDataset:
    """Download ``preset``'s public archive into ``dest`` and :func:`prepare` it.

    An archive already in ``dest`` with the right checksum is not downloaded again.

    Args:
        preset: A dataset preset or ``bvh``.
        dest: Folder that receives the archive and ``<preset>/``.
        url: Another address of the archive (a mirror); default: the stored one.
        sha256: The expected checksum (default: the stored one).
        cache: Write the window cache.
        cache_dir: The window cache directory.
        overrides: See :func:`prepare`.
        opener: Opens the URL (tests pass one; default ``urllib.request.urlopen``).
        console: Where progress goes.

    Returns:
        What was installed.

    Raises:
        DataPrepareError: No public archive is known for ``preset`` and no ``url``
            was given, the download failed, or any error of :func:`prepare`.
    """
    console = console or Console(stderr=True)
    stored = known_archive(preset)
    if url is None and stored is None:
        raise DataPrepareError(
            f"no public archive with a fixed layout and a published checksum is known for "
            f"{preset!r}: download its files yourself, then run 'skelagnostic data prepare "
            f"{preset} --zip FILE --sha256 HEX --dest DIR' on a zip of them, or point "
            f"data.root= (or ${DATA_ROOT_ENV}) at a folder of its BVH files (docs/data.md)"
        )
    address = url or stored.url  # type: ignore[union-attr]
    expected = sha256 or (stored.sha256 if stored else None)
    if expected is None:
        raise DataPrepareError(
            f"no checksum is stored for {preset!r} archives: pass --sha256 HEX with --url"
        )
    target = dest / (address.rstrip("/").rsplit("/", 1)[-1] or f"{preset}.zip")
    if not (target.is_file() and _matches(target, expected)):
        size = stored.size if stored and url is None else None
        with _bar(console, f"download {target.name}", size, True) as (step, set_total):
            download(address, target, opener, step, set_total)
    return prepare(preset, target, dest, expected, cache, cache_dir, overrides, console)


def _matches(path: Path, sha256: str) -> bool:
    """``path`` has the checksum ``sha256`` (an archive already downloaded)."""
    try:
        verify_archive(path, sha256)
    except DataPrepareError:
        return False
    return True


def report(result: PreparedDataset, dest: Path) -> str:
    """What ``prepare`` prints: where the files are and how to use them."""
    kept = result.members - result.extracted
    lines = [
        f"{result.preset}: {len(result.files)} BVH file(s) in {result.root} "
        f"({result.extracted} archive file(s) written"
        + (f", {kept} already in place)" if kept else ")")
    ]
    if result.preset == "bvh":
        lines.append(f"use: data=bvh data.paths=[{result.root}]")
    else:
        lines.append(
            f"test split: {len(result.test_files)} file(s): "
            + (", ".join(p.name for p in result.test_files) or "none")
        )
        lines.append(f"use: data={result.preset} data.root={result.root}")
        lines.append(f"  or: {DATA_ROOT_ENV}={dest} (finds {result.root.name}/ there)")
    if result.cache_dir is not None:
        lines.append(f"window cache: {result.cached_windows} window(s) in {result.cache_dir}")
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    names = ", ".join(_NAMES)
    parser = argparse.ArgumentParser(
        prog="skelagnostic data",
        description="Install a motion dataset: 'prepare' verifies a downloaded archive's "
        "SHA-256, extracts it to DEST/<preset>/ (no path traversal), checks that "
        "every BVH file parses and writes the window cache; 'get' downloads the "
        f"preset's public archive first. Presets: {names}.",
    )
    verbs = parser.add_subparsers(dest="action", required=True, metavar="{prepare,get}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("preset", choices=_NAMES, metavar="PRESET", help=f"one of: {names}")
    common.add_argument(
        "--dest",
        type=expand_path,
        required=True,
        metavar="DIR",
        help=f"folder receiving <preset>/ (the {DATA_ROOT_ENV} to use)",
    )
    common.add_argument(
        "--sha256",
        metavar="HEX",
        help="expected SHA-256 of the archive (required for presets without a "
        "stored one, e.g. bvh)",
    )
    common.add_argument("--no-cache", action="store_true", help="do not write the window cache")
    common.add_argument(
        "--cache-dir",
        type=expand_path,
        metavar="DIR",
        help="window cache directory (default: $SKELAGNOSTIC_CACHE or ~/.cache/skelagnostic)",
    )
    common.add_argument(
        "overrides",
        nargs="*",
        metavar="OVERRIDE",
        help="config overrides choosing the cached data module, e.g. "
        "model=humot (default: MotionDataModule's defaults: fps=30, "
        "window=32, stride=16, world joint positions)",
    )
    p = verbs.add_parser(
        "prepare",
        parents=[common],
        help="verify, extract, check, cache",
        description="Verify a local archive, extract, check, cache.",
    )
    p.add_argument(
        "--zip", type=expand_path, required=True, metavar="FILE", help="the downloaded archive"
    )
    g = verbs.add_parser(
        "get",
        parents=[common],
        help="download the public archive, prepare",
        description="Download the preset's public archive (LaFAN1's is "
        "stored in the code) into DIR, then prepare it.",
    )
    g.add_argument(
        "--url",
        metavar="URL",
        help="another address of the archive (a mirror; the stored checksum still "
        "applies unless --sha256 is given)",
    )
    return parser


def main(argv: Sequence[str], opener: Opener | None = None) -> int:
    """Run ``skelagnostic data prepare`` or ``skelagnostic data get``.

    Args:
        argv: Arguments after the verb.
        opener: Opens download URLs (default ``urllib.request.urlopen``).

    Returns:
        The exit code: 0, 1 for an error (one message on stderr), 2 for a usage error.
    """
    parser = _parser()
    args, extra = parser.parse_known_args(list(argv))  # overrides may follow the options
    unknown = [a for a in extra if a.startswith("-") or "=" not in a]
    if unknown:
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    args.overrides = [*args.overrides, *extra]
    console = Console(stderr=True)
    options = {
        "sha256": args.sha256,
        "cache": not args.no_cache,
        "cache_dir": args.cache_dir,
        "overrides": args.overrides,
        "console": console,
    }
    try:
        if args.action == "prepare":
            result = prepare(args.preset, args.zip, args.dest, **options)
        else:
            result = get(args.preset, args.dest, url=args.url, opener=opener, **options)
    except SkelagnosticError as exc:
        print(error_line(f"skelagnostic data {args.action}", exc), file=sys.stderr)
        return 1
    print(report(result, args.dest))
    return 0
