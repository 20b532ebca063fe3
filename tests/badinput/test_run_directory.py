"""A run directory belongs to one run (issue 47, items 1 and 13).

``hydra.run.dir=<a directory holding files>`` is refused before anything is
written (the line says how to resume); a directory another command holds the
lock file of is refused too; a lock file left by a dead process is taken over.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from test_badinput import SMOKE, documented, error_line

from skelagnostic import cli
from skelagnostic.cli.runs import LOCK_FILE, RunDirectoryLock


def snapshot(root: Path) -> dict[str, tuple[bytes, int]]:
    """Every file below ``root`` with its bytes and modification time (ns)."""
    return {
        str(p.relative_to(root)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def old_run(run_dir: Path) -> Path:
    """A finished run's files: config, checkpoints, metrics, summary."""
    (run_dir / "checkpoints").mkdir(parents=True)
    (run_dir / "csv").mkdir()
    (run_dir / ".hydra").mkdir()
    (run_dir / "config.yaml").write_text("model:\n  name: example\n")
    (run_dir / ".hydra" / "config.yaml").write_text("old: true\n")
    (run_dir / "checkpoints" / "best.ckpt").write_bytes(b"old best weights")
    (run_dir / "checkpoints" / "last.ckpt").write_bytes(b"old last weights")
    (run_dir / "csv" / "metrics.csv").write_text("epoch,step,val/loss\n0,9,0.5\n")
    (run_dir / "summary.md").write_text("# the old run\n")
    return run_dir


def fit(tmp_path: Path, run_dir: Path, *extra: str) -> int:
    return cli.main(
        [
            "fit",
            *SMOKE,
            f"hydra.run.dir={run_dir}",
            f"data.cache_dir={tmp_path / 'cache'}",
            *extra,
        ]
    )


def test_fit_into_a_finished_run_is_refused_before_writing(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = old_run(tmp_path / "run")
    before = snapshot(run_dir)
    assert fit(tmp_path, run_dir) == 1
    line = error_line(capsys)
    assert line == (
        f"skelagnostic fit: error: hydra.run.dir={str(run_dir)!r} is not empty (it holds "
        ".hydra/, checkpoints/, config.yaml, csv/, ...); a run directory belongs to one run: "
        "name a new or empty directory, or leave hydra.run.dir out (each run then gets a new "
        f"one); to continue that run, resume it with ckpt_path={run_dir}/checkpoints/last.ckpt "
        "(the resumed run writes a new directory)"
    )
    assert snapshot(run_dir) == before  # nothing written, nothing deleted, no best-v1.ckpt
    assert not (run_dir / LOCK_FILE).exists()
    documented(line, tmp_path)


def test_other_verbs_do_not_write_into_a_run_either(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "notes"
    run_dir.mkdir()
    (run_dir / "notes.txt").write_text("mine")
    code = cli.main(["validate", *SMOKE, f"hydra.run.dir={run_dir}"])
    assert code == 1
    err = capsys.readouterr().err
    assert err.strip() == (
        f"skelagnostic validate: error: hydra.run.dir={str(run_dir)!r} is not empty (it holds "
        "notes.txt); a run directory belongs to one run: name a new or empty directory, or "
        "leave hydra.run.dir out (each run then gets a new one)"
    )
    assert sorted(p.name for p in run_dir.iterdir()) == ["notes.txt"]


def test_an_empty_existing_directory_can_be_the_run_directory(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "empty"
    run_dir.mkdir()
    assert fit(tmp_path, run_dir, "data.window=0") == 1  # got past the guard to the data
    assert error_line(capsys) == "skelagnostic fit: error: data.window must be > 0, got 0"


HOLDER = textwrap.dedent(
    """
    import sys
    from skelagnostic.cli.runs import RunDirectoryLock
    lock = RunDirectoryLock(sys.argv[1])
    lock.acquire()
    print("locked", flush=True)
    sys.stdin.read()  # hold until the test closes stdin
    lock.release()
    """
)


def test_a_directory_locked_by_a_running_command_is_refused(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "busy"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(run_dir)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        assert fit(tmp_path, run_dir) == 1
        line = error_line(capsys)
        assert line == (
            f"skelagnostic fit: error: hydra.run.dir={str(run_dir)!r} is in use by another "
            f"command (process {holder.pid} holds {LOCK_FILE}); a run directory belongs to one "
            "run: name another directory, or leave hydra.run.dir out (each run then gets a new "
            "one)"
        )
        assert sorted(p.name for p in run_dir.iterdir()) == [LOCK_FILE]  # the holder's only
        documented(line.replace(str(holder.pid), "<pid>"), tmp_path)
    finally:
        holder.communicate("", timeout=60)
    assert holder.returncode == 0
    assert not run_dir.joinpath(LOCK_FILE).exists()  # released by its holder


def test_a_stale_lock_of_a_dead_process_is_taken_over(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        check=True,
        capture_output=True,
        text=True,
    )
    run_dir = tmp_path / "stale"
    run_dir.mkdir()
    (run_dir / LOCK_FILE).write_text(dead.stdout)  # its process has ended
    assert fit(tmp_path, run_dir, "data.window=0") == 1
    assert error_line(capsys) == "skelagnostic fit: error: data.window must be > 0, got 0"
    assert not run_dir.exists()  # only bookkeeping (and the lock): discarded as before


def test_the_lock_is_released_when_the_command_ends(
    site: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "kept"
    run_dir.mkdir()
    lock = RunDirectoryLock(run_dir)
    lock.acquire()
    assert (run_dir / LOCK_FILE).read_text() == f"{os.getpid()}\n"
    lock.release()
    assert fit(tmp_path, run_dir, "data.window=0") == 1
    capsys.readouterr()
    second = RunDirectoryLock(run_dir)
    second.acquire()  # nobody holds it any more
    second.release()
    assert not (run_dir / LOCK_FILE).exists()
