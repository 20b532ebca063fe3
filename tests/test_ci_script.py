"""``scripts/test.sh`` (what ``.ci/run`` runs) runs every stage and reports each one.

The stages' tools are stand-ins in a fake virtual environment
(``SKELAGNOSTIC_VENV``): each logs its command line and fails when told to, so
the script's control flow is checked in a second, without running the suite.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
STAGES = [
    "setup (venv, pip install)", "ruff check", "ruff format --check", "pytest", "doctests",
    "docs build",
]  # fmt: skip

#: A stand-in tool: logs ``<tool> <args>``; exits 3 when $FAIL names its stage.
FAKE_TOOL = """#!/usr/bin/env bash
echo "$(basename "$0") $*" >> "$FAKE_LOG"
case " $* " in
  *" pip install "*) stage=setup ;;
  *" --doctest-modules "*) stage=doctests ;;
  *" pytest "*) stage=pytest ;;
  *" format "*) stage=format ;;
  *" check "*) stage=check ;;
  *" build "*) stage=docs ;;
  *) stage=other ;;
esac
case ",$FAIL," in *",$stage,"*) echo "$stage failed on purpose" >&2; exit 3 ;; esac
exit 0
"""


def run_script(tmp_path: Path, fail: str) -> tuple[subprocess.CompletedProcess[str], list[str]]:
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    for tool in ("python", "ruff", "mkdocs"):
        path = venv / "bin" / tool
        path.write_text(FAKE_TOOL)
        path.chmod(0o755)
    log = tmp_path / "log"
    log.touch()
    env = {**os.environ, "SKELAGNOSTIC_VENV": str(venv), "FAKE_LOG": str(log), "FAIL": fail}
    proc = subprocess.run(
        ["bash", "scripts/test.sh", "-k", "bvh"],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    return proc, log.read_text().splitlines()


def table(stdout: str) -> dict[str, str]:
    """Stage -> status, from the final table."""
    rows = {}
    for line in stdout.splitlines():
        for name in STAGES:
            if line.startswith(name + " "):
                rows[name] = line[len(name) :].split()[0]
    return rows


def test_every_stage_runs_after_failures_and_the_exit_is_nonzero(tmp_path: Path) -> None:
    proc, log = run_script(tmp_path, fail="check,pytest")
    assert proc.returncode != 0
    # the stages after the failing ruff check and pytest still ran
    tools = ["python", "ruff", "ruff", "python", "python", "mkdocs"]
    assert [line.split()[0] for line in log] == tools
    assert "-k bvh" in log[3]  # extra arguments go to pytest
    assert "--doctest-modules" in log[4] and "build --strict" in log[5]
    assert table(proc.stdout) == {
        "setup (venv, pip install)": "ok",
        "ruff check": "FAILED",
        "ruff format --check": "ok",
        "pytest": "FAILED",
        "doctests": "ok",
        "docs build": "ok",
    }
    assert "2 of 6 stages failed" in proc.stderr
    for line in proc.stdout.splitlines():
        if line.startswith("pytest "):
            assert float(line.split()[-1]) >= 0  # the seconds column


def test_all_stages_pass(tmp_path: Path) -> None:
    proc, log = run_script(tmp_path, fail="")
    assert proc.returncode == 0, proc.stderr
    assert len(log) == 6
    assert set(table(proc.stdout).values()) == {"ok"}
    assert "all 6 stages passed" in proc.stdout


@pytest.mark.parametrize("fail", ["docs", "doctests"])
def test_a_failing_last_stage_fails_the_script(tmp_path: Path, fail: str) -> None:
    proc, _ = run_script(tmp_path, fail=fail)
    assert proc.returncode != 0
    assert "1 of 6 stages failed" in proc.stderr


def test_a_failed_setup_stops_before_the_checks(tmp_path: Path) -> None:
    proc, log = run_script(tmp_path, fail="setup")
    assert proc.returncode != 0
    assert len(log) == 1  # nothing ran on a broken environment
    assert table(proc.stdout) == {"setup (venv, pip install)": "FAILED"}
