"""Shared pieces of the benchmark suites: results, timing, memory, machine info.

A suite is a module with ``run(size: str) -> list[Result]`` (``size`` is one of
:data:`SIZES`) and, optionally, ``BASELINE_PACKAGES``: the distributions whose
versions the report should record (e.g. ``("pybvh",)``). Register it in
``benchmarks/run.py``.

Every process a benchmark starts dies with the process that started it, so
killing ``benchmarks/run.py`` (even with ``SIGKILL``) leaves no measurement
running: start subprocesses with :func:`run_process` (or :func:`run_child`), and
call :func:`die_with_parent` first thing in a forked child.

A process start that fails on the machine's state (``EAGAIN``: no process slot or
memory to fork; ``ENOMEM``) is retried a few times with a growing pause
(:func:`retry_busy`, which :func:`run_process` and the scaling suite's fork use, and
the tests' ``subprocess.Popen``, see ``tests/conftest.py``); after the last attempt it
raises :class:`MachineBusyError`, which the tests report as a skip, not a failure.
"""

from __future__ import annotations

import ctypes
import errno
import functools
import gc
import importlib
import importlib.metadata
import json
import os
import platform
import resource
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parents[1]
SIZES = ("smoke", "default", "large")
_CHILD_MARK = "@@benchmark-child@@"
#: Environment variable holding the torch thread count for suites and children.
THREADS_ENV = "SKELAGNOSTIC_BENCH_THREADS"
#: Seconds between two looks at the parent by :func:`watch_parent` (where ``prctl`` is missing).
PARENT_POLL_S = 0.5
#: ``prctl`` option asking Linux to signal a process when its parent exits (``linux/prctl.h``).
_PR_SET_PDEATHSIG = 1
#: ``errno`` of a process start that failed on the machine's state, not on the command.
BUSY_ERRNOS = frozenset({errno.EAGAIN, errno.ENOMEM})
#: Attempts of :func:`retry_busy`, and its first pause in seconds (doubled after each
#: failure: 0.5 + 1 + 2 + 4 = 7.5 s of waiting at most).
SPAWN_ATTEMPTS = 5
SPAWN_BACKOFF_S = 0.5


@dataclass
class Result:
    """One figure of a suite.

    ``value`` and ``baseline_value`` are measured in the same run; ``speedup`` is
    derived so that > 1 always means skelagnostic is better.
    """

    name: str
    unit: str
    value: float
    baseline: str | None = None
    baseline_value: float | None = None
    higher_is_better: bool = False

    @property
    def speedup(self) -> float | None:
        """``value / baseline`` (higher is better) or ``baseline / value``; ``None`` if undefined.

        Undefined means no baseline, or a zero denominator (e.g. an overlap of 0
        on both sides): a ratio with a zero numerator is a real 0.
        """
        if self.baseline_value is None:
            return None
        if self.higher_is_better:
            num, den = self.value, self.baseline_value
        else:
            num, den = self.baseline_value, self.value
        return None if den == 0 else num / den

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "unit": self.unit,
            "value": float(self.value),
            "baseline": self.baseline,
            "baseline_value": None if self.baseline_value is None else float(self.baseline_value),
            "speedup": self.speedup,
            "higher_is_better": bool(self.higher_is_better),
        }


def timeit_median(fn: Callable[[], object], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(max(1, repeats)):
        gc.collect()
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def shared_data(*required: str) -> Path | None:
    """The real clips' root (``$SKELAGNOSTIC_TEST_DATA``, else ``../shared/data``).

    Args:
        *required: Sub-directories that must exist (e.g. ``"human/cmu"``).

    Returns:
        The root, or ``None`` when it or one of ``required`` is missing (the
        suites then fall back to procedural data).
    """
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    root = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    return root if all((root / sub).is_dir() for sub in required) else None


def peak_rss() -> float:
    """Peak resident set size of this process so far, in MiB."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # Linux reports KiB, macOS bytes
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


def _set_pdeathsig() -> bool:
    """Linux: have the kernel send ``SIGKILL`` to this process when its parent exits.

    Returns:
        False where ``prctl(PR_SET_PDEATHSIG)`` is unavailable (not Linux, or it failed).
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return False
    return prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0


def watch_parent(parent: int, interval: float = PARENT_POLL_S) -> threading.Thread:
    """Kill this process (``SIGKILL``) once ``parent`` is no longer its parent.

    The portable fallback of :func:`die_with_parent`: a daemon thread compares
    ``os.getppid()`` with ``parent`` every ``interval`` seconds (an orphan is
    re-parented, so its parent pid changes when its parent dies).

    Args:
        parent: Pid of the process this one must not outlive.
        interval: Seconds between two looks.

    Returns:
        The watching thread (started).
    """

    def poll() -> None:
        while os.getppid() == parent:
            time.sleep(interval)
        os.kill(os.getpid(), signal.SIGKILL)

    thread = threading.Thread(target=poll, name="benchmark-watch-parent", daemon=True)
    thread.start()
    return thread


def die_with_parent(parent: int) -> None:
    """Make this process, a child of ``parent``, die when ``parent`` dies.

    On Linux ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (which also holds after ``exec``;
    a parent that died before the call kills this process at once; the signal
    comes when the parent's *thread* that started this process ends, so start
    children from a thread that lives as long as they must), elsewhere
    :func:`watch_parent`. Call it first thing in a forked child, or as the
    ``preexec_fn`` of a subprocess (:func:`run_process` does).

    Args:
        parent: Pid of the process that started this one.
    """
    if not _set_pdeathsig():
        watch_parent(parent)
    elif os.getppid() != parent:  # the parent died before the call: no signal will come
        os.kill(os.getpid(), signal.SIGKILL)


class MachineBusyError(OSError):
    """A process could not be started in :data:`SPAWN_ATTEMPTS` attempts: no memory or slot.

    Its ``errno`` is that of the last attempt (``EAGAIN`` or ``ENOMEM``).
    """


_retrying = threading.local()


def retry_busy(
    start: Callable[[], T],
    what: str = "a process",
    *,
    attempts: int | None = None,
    backoff: float | None = None,
    sleep: Callable[[float], object] | None = None,
) -> T:
    """``start()``, again after a pause while it fails with ``EAGAIN`` or ``ENOMEM``.

    ``start`` starts a process (``subprocess.Popen(...)``, ``os.fork``); on a busy
    machine the kernel can refuse the fork for lack of memory or process slots
    (``BlockingIOError: [Errno 11]``), which says nothing about the command. A failed
    start leaves no child behind, so trying again is safe. Other errors (a missing
    program, a bad argument) are raised at once. A call inside another's ``start``
    (a ``Popen`` that retries, called by a helper that retries) makes one attempt:
    the outer call does the retrying.

    Args:
        start: Starts the process and returns what stands for it.
        what: The process, for the message (e.g. the program's name).
        attempts: How many times to try (default :data:`SPAWN_ATTEMPTS`).
        backoff: Seconds to wait after the first failure, doubled after each next one
            (default :data:`SPAWN_BACKOFF_S`).
        sleep: The pause (default ``time.sleep``).

    Returns:
        What ``start`` returned.

    Raises:
        MachineBusyError: Every attempt failed with ``EAGAIN`` or ``ENOMEM``.
    """
    attempts = SPAWN_ATTEMPTS if attempts is None else attempts
    backoff = SPAWN_BACKOFF_S if backoff is None else backoff
    sleep = time.sleep if sleep is None else sleep
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1, not {attempts}")
    if getattr(_retrying, "active", False):
        return start()
    _retrying.active = True
    try:
        for attempt in range(attempts):
            try:
                return start()
            except OSError as error:
                if error.errno not in BUSY_ERRNOS or isinstance(error, MachineBusyError):
                    raise
                if attempt + 1 == attempts:
                    raise MachineBusyError(
                        error.errno,
                        f"could not start {what} in {attempts} attempts over "
                        f"{backoff * (2 ** (attempts - 1) - 1):g} s: {error.strerror} "
                        "(the machine is out of memory or processes)",
                    ) from error
                sleep(backoff * 2**attempt)
    finally:
        _retrying.active = False
    raise AssertionError("unreachable: the last attempt returns or raises")


def run_process(
    args: list[str], *, input: str | None = None, **kwargs: Any
) -> subprocess.CompletedProcess[str]:
    """``subprocess.run(args, capture_output=True, text=True)`` with a child that dies with us.

    On Linux the child calls :func:`die_with_parent` before ``exec``
    (``preexec_fn``), so even a ``SIGKILL`` of this process ends it. Elsewhere
    the child gets a session of its own and is killed with its process group
    when this process leaves the call early (an exception, Ctrl-C); a Python child
    can also call :func:`die_with_parent` itself (:func:`run_child` does).

    Args:
        args: The command line.
        input: Text written to the child's standard input.
        **kwargs: More ``subprocess.Popen`` arguments (``cwd``, ``env``, ...).

    Returns:
        The finished process (``returncode``, ``stdout``, ``stderr``); a failure is
        not raised (``check=False``).

    Raises:
        MachineBusyError: The process could not be started (:func:`retry_busy`).
    """
    if sys.platform.startswith("linux"):
        kwargs["preexec_fn"] = functools.partial(die_with_parent, os.getpid())
    else:
        kwargs["start_new_session"] = True
    popen = retry_busy(
        lambda: subprocess.Popen(
            args,
            stdin=None if input is None else subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            **kwargs,
        ),
        what=repr(Path(args[0]).name),
    )
    with popen as proc:
        try:
            stdout, stderr = proc.communicate(input)
        except BaseException:
            if "start_new_session" in kwargs:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            proc.kill()
            raise
    return subprocess.CompletedProcess(args, proc.returncode, stdout, stderr)


def run_child(
    target: str, *, child_env: Mapping[str, str] | None = None, **kwargs: Any
) -> tuple[Any, float]:
    """Run ``module:function(**kwargs)`` in a fresh Python process.

    The function must return something JSON-serialisable. A fresh process makes
    its peak RSS a measure of that work alone. The child dies with this process
    (:func:`run_process`, and :func:`die_with_parent` in the child). Its
    environment is ``child_env`` (default: this process's), with the repository
    put on ``PYTHONPATH``.

    Returns:
        ``(return value, peak RSS of the child in MiB)``.
    """
    module, function = target.split(":")
    code = (
        "import json, sys\n"
        "from benchmarks.harness import _child_main\n"
        f"_child_main({module!r}, {function!r}, json.loads(sys.stdin.read()), {os.getpid()})\n"
    )
    env = dict(os.environ if child_env is None else child_env)
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(REPO_ROOT), str(REPO_ROOT / "src"), env.get("PYTHONPATH")) if p
    )
    proc = run_process(
        [sys.executable, "-c", code], input=json.dumps(kwargs), cwd=REPO_ROOT, env=env
    )
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith(_CHILD_MARK):
            payload = json.loads(line[len(_CHILD_MARK) :])
            return payload["result"], payload["peak_rss_mib"]
    raise RuntimeError(
        f"benchmark child {target} failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}"
    )


def apply_threads() -> None:
    """Set torch's intra-op thread count from ``SKELAGNOSTIC_BENCH_THREADS`` (if set)."""
    threads = os.environ.get(THREADS_ENV)
    if threads:
        import torch

        torch.set_num_threads(int(threads))


def _child_main(module: str, function: str, kwargs: dict[str, Any], parent: int) -> None:
    die_with_parent(parent)
    apply_threads()
    result = getattr(importlib.import_module(module), function)(**kwargs)
    payload = {"result": result, "peak_rss_mib": peak_rss()}
    print(_CHILD_MARK + json.dumps(payload), flush=True)


def _ram_bytes() -> int | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def machine_info() -> dict[str, Any]:
    """CPU count, platform, processor and RAM of this machine, and the memory allocator."""
    from skelagnostic.cli.allocator import active_allocator

    processor = platform.processor()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                processor = line.split(":", 1)[1].strip()
                break
    ram = _ram_bytes()
    threads = os.environ.get(THREADS_ENV)
    return {
        "cpu_count": os.cpu_count(),
        "torch_threads": int(threads) if threads else None,
        "platform": platform.platform(),
        "processor": processor,
        "ram_gib": None if ram is None else round(ram / 2**30, 2),
        "allocator": active_allocator(),
    }


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def versions(extra: tuple[str, ...] = ()) -> dict[str, str | None]:
    """Versions of python, torch, numpy, skelagnostic and the given baseline packages."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in ("torch", "numpy", "skelagnostic", *extra):
        out[name] = _version(name)
    return out
