"""Two ``fit`` commands started at once into one ``hydra.run.dir`` (issue 47, item 13).

One runs; the other refuses with one line (the lock file, or the files the first
one wrote), instead of a CSV ``ValueError`` and a run directory mixing both runs.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_signals import SMALL

from skelagnostic.cli.runs import LOCK_FILE


@pytest.mark.slow
def test_two_fits_started_at_once_into_one_directory(
    cli_env: dict[str, str], tmp_path: Path
) -> None:
    """Issue 47 item 13: one runs, the other refuses (no CSV ValueError, no mixed files)."""
    run_dir = tmp_path / "run"
    cmd = [
        sys.executable,
        "-m",
        "skelagnostic.cli",
        "fit",
        *SMALL,
        "trainer.max_steps=3",
        f"hydra.run.dir={run_dir}",
    ]
    procs = [
        subprocess.Popen(
            cmd,
            env=cli_env,
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    results = [(p.pid, *p.communicate(timeout=300), p.returncode) for p in procs]
    codes = sorted(code for *_, code in results)
    assert codes == [0, 1], [err[-2000:] for _, _, err, _ in results]
    (winner,) = [pid for pid, *_, code in results if code == 0]
    (refused,) = [err for _, _, err, code in results if code == 1]
    assert "Traceback" not in refused and "ValueError" not in refused, refused
    (line,) = [s for s in refused.splitlines() if s.startswith("skelagnostic fit: ")]
    assert line.startswith(f"skelagnostic fit: error: hydra.run.dir={str(run_dir)!r} is ")
    assert (f"in use by another command (process {winner} " in line) or ("is not empty" in line)
    assert not (run_dir / LOCK_FILE).exists()
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["best.ckpt", "last.ckpt"]


def test_a_demo_into_an_out_another_command_writes_is_refused(tmp_path: Path, capsys) -> None:
    """Two demos into one ``out=`` at once never mix their clips: the second refuses."""
    import os

    from skelagnostic import cli
    from skelagnostic.cli.runs import RunDirectoryLock

    out = tmp_path / "demo"
    held = RunDirectoryLock(out, key="out")
    held.acquire()  # as a running demo holds it
    try:
        assert cli.main(["demo", f"out={out}", "seconds=0.2", "gif=false"]) == 1
    finally:
        held.release()
    err = capsys.readouterr().err.strip()
    assert err == (
        f"skelagnostic demo: error: out='{out}' is in use by another command "
        f"(process {os.getpid()} holds {LOCK_FILE}); name another out= or wait until it ends"
    )
    assert sorted(p.name for p in out.iterdir()) == []
    line = err.replace(str(tmp_path), "<tmp>").replace(str(os.getpid()), "<pid>")
    assert line in (Path(__file__).parents[2] / "docs" / "troubleshooting.md").read_text()


def test_a_lock_that_cannot_be_written_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    """A full disk while the lock file is written: no stale lock file, no empty run folder."""
    import errno
    import os

    from skelagnostic.cli.runs import RunDirectoryLock

    def full(fd: int, length: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "ftruncate", full)
    with pytest.raises(OSError, match="No space left"):
        RunDirectoryLock(tmp_path / "run").acquire()
    assert list(tmp_path.iterdir()) == []


def test_demo_takes_its_lock_without_the_training_stack(tmp_path: Path) -> None:
    """``demo`` locks ``out=`` with :mod:`skelagnostic.cli.lock`: no Lightning, Hydra or pluggy."""
    code = (
        "import sys\n"
        "from skelagnostic.cli import demo\n"
        f"assert demo.main(['out={tmp_path / 'demo'}', 'seconds=0.2', 'gif=false']) == 0\n"
        "print([m for m in ('lightning', 'hydra', 'pluggy') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout
