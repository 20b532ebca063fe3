"""``scripts/peak_memory.py`` sums the memory of a command's whole process tree."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

#: A parent and its child each hold 200 MiB of their own (written, so resident) for a while.
TREE = """
import subprocess, sys, time
hold = "import time; b = bytearray(200 * 2**20); time.sleep(3)"
child = subprocess.Popen([sys.executable, "-c", hold])
b = bytearray(200 * 2**20)
time.sleep(3)
child.wait()
sys.exit(7)
"""


@pytest.mark.skipif(not Path("/proc/self/smaps_rollup").exists(), reason="Linux /proc")
def test_the_peak_covers_parent_and_child_and_the_exit_status_passes(tmp_path: Path) -> None:
    out = tmp_path / "peak.json"
    options = ["--interval", "0.2", "--json", str(out)]
    done = subprocess.run(
        [sys.executable, "scripts/peak_memory.py", *options, "--", sys.executable, "-c", TREE],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 7, done.stderr
    report = json.loads(out.read_text())
    assert report["exit_code"] == 7 and report["max_processes"] == 2
    # both processes' 200 MiB: more than either alone (0.2 GiB), at most a sane total
    assert 0.39 <= report["peak_pss_gib"] <= 1.5
    assert report["peak_rss_sum_gib"] >= report["peak_pss_gib"]
    assert "peak_memory: peak" in done.stderr
