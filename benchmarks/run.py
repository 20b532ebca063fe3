"""Run a benchmark suite, print a table and optionally write JSON.

Usage::

    python benchmarks/run.py --suite matching [--size smoke|default|large] [--json OUT]
                             [--threads N]
    python benchmarks/run.py --suite all --size smoke
    python benchmarks/run.py --suite training --authors-repo walkthedog=DIR,pcmrl=DIR
    python benchmarks/run.py --suite scaling [--data-root DIR] [--methods NAME,...] [--compile]
                             [--plot DIR] [--allocator tcmalloc|jemalloc|system]
    python benchmarks/run.py --suite allocators [--methods NAME,...]

``--authors-repo`` names checkouts of the methods' official repositories; the
suites that compare with them (``training``, ``matching``) then time the authors'
code in the same run as the baseline of their rows (see ``benchmarks/authors.py``).
Without it those baselines are absent (``null``).

``--data-root DIR`` is the folder of the training corpora (``DIR/lafan1``) the
``scaling`` suite reads (default ``$SKELAGNOSTIC_DATA``, else ``../shared/datasets``);
``--methods`` limits it to some methods, ``--compile`` also times ``torch.compile``d
models there; ``--plot DIR`` writes the figures of the suites that draw some (a
module-level ``plot(report, out_dir, date, size)``) as PNG files into ``DIR``.
``--methods`` also limits the ``allocators`` suite.

``--allocator NAME`` restarts the run on that memory allocator (as
``SKELAGNOSTIC_ALLOCATOR=NAME`` does for the ``skelagnostic`` command; see
:mod:`skelagnostic.cli.allocator`), so every suite and its children measure with it;
``machine["allocator"]`` in the JSON records the one in use.

The JSON (read by external tooling; keep the format stable) is::

    {"suite": str, "machine": {...}, "versions": {...},
     "results": [{"name", "unit", "value", "baseline", "baseline_value",
                  "speedup", "higher_is_better"}, ...]}

With ``--suite all`` the suite is ``"all"`` and every result name is prefixed
with ``"<suite>/"``. Every suite's last result is ``wall_time``: the wall time
of the whole suite (seconds), and ``machine`` records the 1-minute load average
before and after the run (``load_average_start``, ``load_average_end``), so a
reader can tell a quiet run from a contended one.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from benchmarks.authors import (  # noqa: E402
    AuthorsRepoError,
    export_authors_repos,
    parse_authors_repos,
)
from benchmarks.harness import (  # noqa: E402
    SIZES,
    THREADS_ENV,
    Result,
    apply_threads,
    machine_info,
    versions,
)
from benchmarks.suites.scaling import COMPILE_ENV, DATA_ENV, METHODS_ENV, selected_methods  # noqa: E402

#: Suite name -> module exposing ``run(size) -> list[Result]``.
SUITES: dict[str, str] = {
    "io": "benchmarks.suites.io",
    "kinematics": "benchmarks.suites.kinematics",
    "matching": "benchmarks.suites.matching",
    "bigdata": "benchmarks.suites.bigdata",
    "training": "benchmarks.suites.training",
    "quality": "benchmarks.suites.quality",
    "inference": "benchmarks.suites.inference",
    "scaling": "benchmarks.suites.scaling",
    "allocators": "benchmarks.suites.allocators",
    "startup": "benchmarks.suites.startup",
}
#: Parts of a suite that also run alone (``--suite training_humot``); ``all`` runs them only
#: inside their suite.
PARTS: dict[str, str] = {
    "training_humot": "benchmarks.suites.training_humot",
    "training_pcmrl": "benchmarks.suites.training_pcmrl",
    "training_options": "benchmarks.suites.training_options",
}


def _format(value: float | None) -> str:
    if value is None:
        return "-"
    return f"{value:.4g}"


def print_table(suite: str, size: str, results: list[Result]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"benchmarks: {suite} ({size})")
    table.add_column("name", overflow="fold", max_width=56)
    for column in ("value", "unit"):
        table.add_column(column, justify="right", no_wrap=True)
    table.add_column("baseline", overflow="fold", max_width=28)
    for column in ("baseline value", "speedup"):
        table.add_column(column, justify="right", no_wrap=True)
    for r in results:
        speedup = r.speedup
        text = "-" if speedup is None else f"{speedup:.2f}x"
        style = "" if speedup is None else ("green" if speedup >= 1 else "red")
        table.add_row(
            r.name,
            _format(r.value),
            r.unit,
            r.baseline or "-",
            _format(r.baseline_value),
            f"[{style}]{text}[/]" if style else text,
        )
    Console(width=max(Console().width, 120)).print(table)


def run_suites(
    names: list[str], size: str, prefix: bool = False
) -> tuple[list[Result], tuple[str, ...]]:
    results: list[Result] = []
    baselines: tuple[str, ...] = ()
    for name in names:
        module = importlib.import_module({**SUITES, **PARTS}[name])
        start = time.perf_counter()
        suite_results = module.run(size)
        suite_results.append(Result("wall_time", "s", time.perf_counter() - start))
        if prefix:
            for r in suite_results:
                r.name = f"{name}/{r.name}"
        results.extend(suite_results)
        baselines += tuple(getattr(module, "BASELINE_PACKAGES", ()))
    return results, baselines


#: Set in the environment of a run restarted by ``--allocator`` (it is not restarted again).
RESTARTED_ENV = "SKELAGNOSTIC_BENCH_ALLOCATOR_SET"


def _restart_on(allocator: str, parser: argparse.ArgumentParser, argv: list[str]) -> None:
    """Replace this process by the same run on ``allocator`` unless it already runs on it."""
    from skelagnostic.cli.allocator import (
        SYSTEM,
        AllocatorError,
        active_allocator,
        allocator_environment,
    )

    if os.environ.get(RESTARTED_ENV) == allocator:
        return
    if active_allocator() == ("system" if allocator.lower() in SYSTEM else allocator):
        return
    try:
        env = allocator_environment(allocator)
    except AllocatorError as err:
        parser.error(f"--allocator: {err}")
    env[RESTARTED_ENV] = allocator
    library = env.get("LD_PRELOAD", "no preloaded library").split(":")[0]
    print(f"run.py: restarting on {allocator} ({library})", file=sys.stderr, flush=True)
    sys.stdout.flush()
    os.execve(sys.executable, [sys.executable, str(Path(__file__).resolve()), *argv], env)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", required=True, choices=[*SUITES, *PARTS, "all"])
    parser.add_argument("--size", default="default", choices=SIZES)
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="torch intra-op threads for every measurement (default: torch's choice); "
        "1 gives steadier figures on a busy machine",
    )
    parser.add_argument(
        "--authors-repo",
        action="append",
        default=[],
        metavar="NAME=DIR[,NAME=DIR]",
        help="checkouts of the official code to time in the same run as the baseline: "
        "walkthedog=DIR (github PeizhuoLi/walk-the-dog), pcmrl=DIR (github MiniEval/PC-MRL)",
    )
    parser.add_argument(
        "--data-root",
        type=Path,
        default=None,
        help="folder of the training corpora, e.g. DIR/lafan1 (scaling suite; default "
        "$SKELAGNOSTIC_DATA, else ../shared/datasets)",
    )
    parser.add_argument(
        "--compile",
        action="store_true",
        help="scaling suite: also time every method with torch.compile (against eager)",
    )
    parser.add_argument(
        "--methods",
        default=None,
        metavar="NAME[,NAME]",
        help="scaling suite: measure only these methods (vqpae, humot, pcmrl_recon, "
        "pcmrl_interp; default: all)",
    )
    parser.add_argument(
        "--plot", type=Path, default=None, metavar="DIR", help="write the suites' figures here"
    )
    parser.add_argument(
        "--allocator",
        default=None,
        metavar="NAME",
        help="restart on this memory allocator first: tcmalloc, jemalloc, system, or a "
        "library path (see SKELAGNOSTIC_ALLOCATOR in docs/cli.md)",
    )
    args = parser.parse_args(argv)
    if args.allocator is not None:
        _restart_on(args.allocator, parser, sys.argv[1:] if argv is None else argv)
    try:
        repos = parse_authors_repos(args.authors_repo)
    except AuthorsRepoError as err:
        parser.error(str(err))
    export_authors_repos(repos)
    if args.threads is not None:
        os.environ[THREADS_ENV] = str(args.threads)
    if args.data_root is not None:
        if not (args.data_root / "lafan1").is_dir():
            parser.error(f"--data-root {args.data_root}: no lafan1/ folder of BVH files in it")
        os.environ[DATA_ENV] = str(args.data_root.expanduser().resolve())
    if args.compile:
        os.environ[COMPILE_ENV] = "1"
    if args.methods is not None:
        try:
            selected_methods(args.methods)
        except ValueError as err:
            parser.error(f"--methods: {err}")
        os.environ[METHODS_ENV] = args.methods
    apply_threads()
    names = list(SUITES) if args.suite == "all" else [args.suite]
    load_start = os.getloadavg()[0]
    results, baselines = run_suites(names, args.size, prefix=args.suite == "all")
    print_table(args.suite, args.size, results)
    machine = machine_info()
    machine["load_average_start"] = round(load_start, 2)
    machine["load_average_end"] = round(os.getloadavg()[0], 2)
    report: dict[str, Any] = {
        "suite": args.suite,
        "machine": machine,
        "versions": {
            **versions(baselines),
            **{f"{name} (official code)": str(path) for name, path in repos.items()},
        },
        "results": [r.to_dict() for r in results],
    }
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    if args.plot is not None:
        for name in names:
            module = importlib.import_module({**SUITES, **PARTS}[name])
            if hasattr(module, "plot"):
                date = time.strftime("%Y-%m-%d")
                for path in module.plot(report, args.plot, date=date, size=args.size):
                    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
