"""Processes the benchmarks start die with the process that started them.

Each test starts a parent (a fresh interpreter, as ``benchmarks/run.py``) that starts a
child the way the suites do (``run_child``, ``run_process``, the scaling suite's
``forked``, and the polling fallback ``watch_parent`` alone); the child writes its pid
and sleeps. The parent is then killed with ``SIGKILL``, which it cannot handle: the
child must be gone (exited, or a zombie nobody reaps) within a few seconds.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
try:
    from benchmarks import harness
finally:
    sys.path.remove(str(REPO_ROOT))

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX processes")

#: Imported by the child of ``run_child`` (the parent puts its folder on PYTHONPATH).
SLEEPER = """
import os
import time
from pathlib import Path


def sleep(pidfile: str) -> None:
    tmp = Path(pidfile + ".tmp")
    tmp.write_text(str(os.getpid()))
    tmp.rename(pidfile)
    time.sleep(300)
"""
#: The parent's script per way of starting the child; ``pidfile`` is set before it.
PARENTS = {
    "run_child": """
        from benchmarks.harness import run_child
        run_child("children_sleeper:sleep", pidfile=pidfile)
    """,
    "run_process": """
        import sys
        from benchmarks.harness import run_process
        run_process([sys.executable, "-c",
                     f"import children_sleeper; children_sleeper.sleep({pidfile!r})"])
    """,
    "forked": """
        import children_sleeper
        from benchmarks.suites.scaling import collect, forked
        collect(forked(children_sleeper.sleep, pidfile), "sleeper")
    """,
    "watch_parent": """
        import os, time
        import children_sleeper
        from benchmarks.harness import watch_parent
        parent = os.getpid()
        if os.fork() == 0:
            watch_parent(parent, interval=0.1)  # the fallback alone, no prctl
            children_sleeper.sleep(pidfile)
        time.sleep(300)
    """,
}


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs: it exists and is not a zombie (Linux ``/proc``)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    try:
        # the state follows the command name in parentheses
        return stat.read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, IndexError):
        return not stat.parent.parent.is_dir()  # no /proc: trust os.kill


def _wait_for(check: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if check():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("how", list(PARENTS))
def test_child_dies_when_the_parent_is_killed(how: str, tmp_path: Path) -> None:
    (tmp_path / "children_sleeper.py").write_text(SLEEPER)
    pidfile = tmp_path / "child.pid"
    script = f"pidfile = {str(pidfile)!r}\n" + textwrap.dedent(PARENTS[how])
    env = dict(os.environ)
    env.pop(harness.THREADS_ENV, None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT), str(tmp_path)])
    parent = subprocess.Popen(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    child = None
    try:
        started = _wait_for(lambda: pidfile.exists() or parent.poll() is not None, 120)
        assert started and parent.poll() is None, parent.stderr.read().decode()[-3000:]
        child = int(pidfile.read_text())
        assert child != parent.pid and _alive(child)
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=30)
        assert _wait_for(lambda: not _alive(child), 5.0), f"{how}: child {child} outlived"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        if child is not None and _alive(child):
            os.kill(child, signal.SIGKILL)
        parent.stderr.close()


def test_die_with_parent_kills_a_child_whose_parent_is_already_gone() -> None:
    """The parent died before the call (the child's parent pid is not the one given)."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            harness.die_with_parent(os.getppid() + 1 if os.getppid() > 1 else 2)
            time.sleep(5)  # the polling fallback needs a moment
        finally:
            os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


def test_run_process_returns_output_and_status(tmp_path: Path) -> None:
    proc = harness.run_process(
        [sys.executable, "-c", "import sys; print(sys.stdin.read()[::-1]); sys.exit(3)"],
        input="abc",
        cwd=tmp_path,
    )
    assert (proc.returncode, proc.stdout, proc.stderr) == (3, "cba\n", "")
