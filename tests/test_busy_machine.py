"""A busy machine does not fail tests or benchmarks (issue 48, item 12).

A process start the kernel refuses for lack of memory or process slots
(``BlockingIOError: [Errno 11]`` from ``subprocess.Popen``, seen when the
machine's memory was full) is retried a few times with a growing pause
(``benchmarks.harness.retry_busy``, used by the harness and, through
``tests/conftest.py``, by every test's ``subprocess.Popen``); when it still fails
the test is skipped with the reason. The starts here fail on purpose: ``Popen``
(or its ``_execute_child``) is replaced by one that raises a few times.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
try:
    from benchmarks import harness
finally:
    sys.path.remove(str(REPO_ROOT))


def failing(times: int, real: Callable[..., Any], err: int = errno.EAGAIN) -> Callable[..., Any]:
    """``real``, which raises ``OSError(err)`` (``BlockingIOError`` for EAGAIN) ``times`` times."""
    calls = {"n": 0}

    def start(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] <= times:
            raise OSError(err, os.strerror(err))  # OSError(EAGAIN, ...) is a BlockingIOError
        return real(*args, **kwargs)

    start.calls = calls  # type: ignore[attr-defined]
    return start


def children() -> set[int]:
    """Pids of this process's live (not zombie) children, from Linux ``/proc``."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[1]) == os.getpid() and fields[0] != "Z":
            found.add(int(stat.parent.name))
    return found


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="Linux /proc")


def test_retry_busy_retries_eagain_and_enomem_with_a_growing_pause() -> None:
    sleeps: list[float] = []
    for err in (errno.EAGAIN, errno.ENOMEM):
        start = failing(2, lambda: "started", err)
        assert harness.retry_busy(start, attempts=5, backoff=0.5, sleep=sleeps.append) == "started"
        assert start.calls["n"] == 3  # type: ignore[attr-defined]
    assert sleeps == [0.5, 1.0, 0.5, 1.0]


def test_retry_busy_gives_up_after_its_attempts() -> None:
    sleeps: list[float] = []
    start = failing(10, lambda: "never")
    with pytest.raises(harness.MachineBusyError) as caught:
        harness.retry_busy(start, "'sleep'", attempts=4, backoff=0.25, sleep=sleeps.append)
    assert start.calls["n"] == 4  # type: ignore[attr-defined]
    assert sleeps == [0.25, 0.5, 1.0]  # no pause after the last attempt
    assert caught.value.errno == errno.EAGAIN
    assert "could not start 'sleep' in 4 attempts over 1.75 s" in str(caught.value)
    assert isinstance(caught.value.__cause__, BlockingIOError)


def test_retry_busy_raises_other_errors_at_once() -> None:
    sleeps: list[float] = []
    start = failing(1, lambda: "never", errno.ENOENT)
    with pytest.raises(FileNotFoundError):
        harness.retry_busy(start, sleep=sleeps.append)
    assert sleeps == []


def test_run_process_starts_its_child_after_refused_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    """The harness's ``Popen`` (``benchmarks/harness.py``, where the error was seen)."""
    monkeypatch.setattr(harness, "SPAWN_BACKOFF_S", 0.001)
    popen = failing(3, subprocess.Popen)
    monkeypatch.setattr(harness.subprocess, "Popen", popen)
    before = children()
    proc = harness.run_process([sys.executable, "-c", "print('hello')"])
    assert (proc.returncode, proc.stdout) == (0, "hello\n")
    assert popen.calls["n"] == 4  # type: ignore[attr-defined]
    assert children() == before  # the child was reaped; the failed starts made none


def test_run_process_reports_a_machine_that_stays_busy(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(harness, "SPAWN_BACKOFF_S", 0.001)
    monkeypatch.setattr(harness.subprocess, "Popen", failing(99, subprocess.Popen))
    before = children()
    with pytest.raises(harness.MachineBusyError, match="could not start 'python"):
        harness.run_process([sys.executable, "-c", "pass"])
    assert children() == before


def test_the_tests_popen_retries_a_refused_fork(monkeypatch: pytest.MonkeyPatch) -> None:
    """``subprocess.run`` in a test goes through the conftest's retrying ``Popen``."""
    assert subprocess.Popen.__name__ == "RetryingPopen"
    monkeypatch.setattr(harness, "SPAWN_BACKOFF_S", 0.001)
    # the kernel's refusal comes from the fork inside Popen.__init__, after the pipes exist
    execute = failing(2, subprocess.Popen._execute_child)
    monkeypatch.setattr(subprocess.Popen, "_execute_child", execute)
    fds, before = open_fds(), children()
    done = subprocess.run(
        [sys.executable, "-c", "import sys; print(sys.stdin.read()[::-1])"],
        input="abc",
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout == "cba\n"
    assert execute.calls["n"] == 3  # type: ignore[attr-defined]
    assert open_fds() == fds  # the failed starts closed their pipes
    assert children() == before


#: Run by a separate pytest with the repository's hooks: how each outcome is reported.
OUTCOMES = """
import errno, subprocess, sys
import pytest
from benchmarks.harness import MachineBusyError


def test_busy():
    raise MachineBusyError(errno.EAGAIN, "could not start 'x' in 5 attempts")


def test_memory_full():
    raise MemoryError()


def test_torch_allocation_that_fits():
    raise RuntimeError("[enforce fail] DefaultCPUAllocator: can't allocate memory: "
                       "you tried to allocate 1048576 bytes. Error code 12")


def test_torch_allocation_beyond_the_machine():
    raise RuntimeError("DefaultCPUAllocator: can't allocate memory: "
                       "you tried to allocate 1000000000000000000 bytes. Error code 12")


def test_other_oserror():
    raise PermissionError(errno.EACCES, "denied")


@pytest.fixture
def busy_fixture():
    raise MachineBusyError(errno.ENOMEM, "could not start 'y' in 5 attempts")


def test_busy_in_setup(busy_fixture):
    pass


def test_refused_then_started(monkeypatch):
    import benchmarks.harness as harness
    monkeypatch.setattr(harness, "SPAWN_BACKOFF_S", 0.001)
    real, calls = subprocess.Popen._execute_child, []

    def execute(self, *args, **kwargs):
        calls.append(1)
        if len(calls) < 3:
            raise BlockingIOError(errno.EAGAIN, "Resource temporarily unavailable")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(subprocess.Popen, "_execute_child", execute)
    assert subprocess.run([sys.executable, "-c", "pass"]).returncode == 0


def test_refused_every_time(monkeypatch):
    import benchmarks.harness as harness
    monkeypatch.setattr(harness, "SPAWN_BACKOFF_S", 0.001)

    def execute(self, *args, **kwargs):
        raise BlockingIOError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(subprocess.Popen, "_execute_child", execute)
    subprocess.run([sys.executable, "-c", "pass"])
"""


def test_machine_state_is_a_skip_and_code_errors_are_failures(tmp_path: Path) -> None:
    (tmp_path / "conftest.py").write_text(
        textwrap.dedent(f"""
        import importlib.util, sys
        sys.path.insert(0, {str(REPO_ROOT)!r})
        spec = importlib.util.spec_from_file_location(
            "repo_conftest", {str(REPO_ROOT / "tests" / "conftest.py")!r})
        repo = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(repo)
        _retrying_popen = repo._retrying_popen
        pytest_runtest_setup = repo.pytest_runtest_setup
        pytest_runtest_call = repo.pytest_runtest_call
        """)
    )
    (tmp_path / "test_outcomes.py").write_text(OUTCOMES)
    pytest_args = ["-v", "-rs", "-n", "0", "-p", "no:cacheprovider", "--rootdir", str(tmp_path)]
    done = subprocess.run(
        [sys.executable, "-m", "pytest", *pytest_args, "-c", os.devnull, "test_outcomes.py"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    out = done.stdout
    outcomes = {
        line.split()[0].split("::")[1]: line.split()[1]
        for line in out.splitlines()
        if line.startswith("test_outcomes.py::")
    }
    assert outcomes == {
        "test_busy": "SKIPPED",
        "test_memory_full": "SKIPPED",
        "test_torch_allocation_that_fits": "SKIPPED",
        "test_torch_allocation_beyond_the_machine": "FAILED",
        "test_other_oserror": "FAILED",
        "test_busy_in_setup": "SKIPPED",
        "test_refused_then_started": "PASSED",
        "test_refused_every_time": "SKIPPED",
    }, out
    assert "the machine is busy: could not start 'x' in 5 attempts" in out
    assert "an allocation of 1 MiB failed (RuntimeError)" in out
