"""Run a command and report the peak memory of its whole process tree (Linux).

``/usr/bin/time -v`` reports the largest *single* process; a test suite under
pytest-xdist is several processes at once (the controller, the workers and the
children they start), so this samples the tree instead: every ``--interval``
seconds it sums, over the command and all its descendants, the proportional set
size (``Pss`` of ``/proc/PID/smaps_rollup``: shared pages split between the
processes that share them, so the sum is what the tree occupies) and the
resident set size (``VmRSS``, which counts shared pages once per process: an
upper bound). Short peaks between two samples are missed.

Usage::

    python scripts/peak_memory.py [--interval S] [--json OUT] -- COMMAND [ARG ...]

Prints one line at the end (to stderr) and exits with the command's status.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path


def _children() -> dict[int, list[int]]:
    """Parent pid -> child pids of every process visible in ``/proc``."""
    tree: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        tree.setdefault(ppid, []).append(int(stat.parent.name))
    return tree


def descendants(root: int) -> list[int]:
    """``root`` and every process below it."""
    tree, found, todo = _children(), [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo.extend(tree.get(pid, []))
    return found


def _kib(path: Path, field: str) -> int:
    try:
        for line in path.read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 0  # the process ended meanwhile, or is a zombie


def tree_memory(root: int) -> tuple[int, int, int]:
    """``(summed Pss KiB, summed VmRSS KiB, number of processes)`` of ``root``'s tree."""
    pids = descendants(root)
    pss = sum(_kib(Path(f"/proc/{pid}/smaps_rollup"), "Pss") for pid in pids)
    rss = sum(_kib(Path(f"/proc/{pid}/status"), "VmRSS") for pid in pids)
    return pss, rss, len(pids)


def main(argv: list[str] | None = None) -> int:
    """Run the command of ``argv`` (default ``sys.argv[1:]``); its exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--interval", type=float, default=1.0, help="seconds between samples")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND [ARG ...]")
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("give the command to run after --")
    start = time.monotonic()
    proc = subprocess.Popen(command)
    peak = {"pss_kib": 0, "rss_kib": 0, "processes": 0, "at_s": 0.0}
    try:
        while proc.poll() is None:
            pss, rss, count = tree_memory(proc.pid)
            if pss > peak["pss_kib"]:
                peak.update(pss_kib=pss, at_s=round(time.monotonic() - start, 1))
            peak["rss_kib"] = max(peak["rss_kib"], rss)
            peak["processes"] = max(peak["processes"], count)
            time.sleep(args.interval)
    except KeyboardInterrupt:
        proc.terminate()
    code = proc.wait()
    wall = time.monotonic() - start
    report = {
        "command": command,
        "exit_code": code,
        "wall_s": round(wall, 1),
        "peak_pss_gib": round(peak["pss_kib"] / 2**20, 2),
        "peak_rss_sum_gib": round(peak["rss_kib"] / 2**20, 2),
        "peak_at_s": peak["at_s"],
        "max_processes": peak["processes"],
        "load_average_end": round(os.getloadavg()[0], 2),
    }
    print(
        f"peak_memory: peak {report['peak_pss_gib']} GiB PSS ({report['peak_rss_sum_gib']} GiB "
        f"summed RSS) at {peak['at_s']} s, up to {peak['processes']} processes; wall "
        f"{wall:.0f} s; exit {code}",
        file=sys.stderr,
    )
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
