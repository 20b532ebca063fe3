"""Shared fixtures: the real clips in ../shared/data, an isolated window cache, method plugins.

The method plugins' packages (``skelagnostic_humot``, ``skelagnostic_pcmrl``,
``skelagnostic_vqpae``) ship in the distribution, so the tests import them like
users do; their shared fixtures (a plugin manager per method, small network
sizes) live here, once.

A busy machine does not fail tests: every ``subprocess.Popen`` a test starts (also
through ``subprocess.run``) retries a start the kernel refused for lack of memory or
process slots (``EAGAIN``/``ENOMEM``, :func:`benchmarks.harness.retry_busy`); a start
that still fails, and an allocation the machine could give when idle but not now
(a ``MemoryError`` or torch's "can't allocate memory" for no more than its RAM), skip
the test with the reason instead of failing it. A request larger than the machine's
RAM still fails: that is a bug, not the machine's state.
"""

from __future__ import annotations

import importlib
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

# Tests run in 2 xdist workers on 2-core machines: one intra-op thread per worker
# (and per subprocess, through the environment) avoids oversubscription, which
# makes torch's elementwise kernels an order of magnitude slower.
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest
import torch

if TYPE_CHECKING:
    from skelagnostic.plugins import PluginManager

torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
try:
    from benchmarks.harness import MachineBusyError, retry_busy
finally:
    sys.path.remove(str(REPO_ROOT))


# ------------------------------------------------------------------------ a busy machine
_Popen = subprocess.Popen


class RetryingPopen(_Popen):  # type: ignore[type-arg]
    """``subprocess.Popen`` whose start is retried on ``EAGAIN``/``ENOMEM`` (``retry_busy``).

    A failed start closes the pipes it opened and leaves no child, so ``__init__``
    can run again on the same object.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        command = args[0] if args else kwargs.get("args")
        first = command if isinstance(command, (str, bytes)) else next(iter(command or ()), "")
        retry_busy(lambda: _Popen.__init__(self, *args, **kwargs), what=repr(os.fspath(first)))


@pytest.fixture(autouse=True, scope="session")
def _retrying_popen() -> Iterator[None]:
    """Every test's ``subprocess.Popen`` (also under ``run``) is a :class:`RetryingPopen`."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(subprocess, "Popen", RetryingPopen)
        yield


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_as_on_a_terminal() -> Iterator[None]:
    """Ctrl-C (SIGINT) raises KeyboardInterrupt here and in every command a test starts.

    A shell starts background jobs with SIGINT ignored (``cmd &`` without job
    control), and an ignored signal stays ignored across ``exec``: the tests that
    interrupt a command would then see it run to the end. A Python handler, unlike
    ``SIG_IGN``, is reset to the default in a child, so children handle Ctrl-C again.
    """
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    if ignored:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if ignored:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _ram_bytes() -> int | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


#: torch's CPU allocator failure: "... you tried to allocate 123 bytes. Error code 12 ...".
_TORCH_ALLOC = re.compile(r"can't allocate memory: you tried to allocate (\d+) bytes")


def machine_state_reason(error: BaseException) -> str | None:
    """Why ``error`` is the machine's state rather than the code's, or ``None`` if it is not.

    Args:
        error: What a test (or its set-up) raised.

    Returns:
        A skip reason for a process start that failed after the retries
        (:class:`~benchmarks.harness.MachineBusyError`), or for a ``MemoryError`` /
        torch allocation failure of at most the machine's RAM (a request of unknown
        size counts as one); ``None`` for anything else, a larger request included.
    """
    if isinstance(error, MachineBusyError):
        return f"the machine is busy: {error.strerror}"
    requested: int | None = None
    if isinstance(error, MemoryError):
        requested = getattr(error, "_total_size", None)  # numpy's _ArrayMemoryError
    elif isinstance(error, RuntimeError) and (found := _TORCH_ALLOC.search(str(error))):
        requested = int(found.group(1))
    else:
        return None
    ram = _ram_bytes()
    if requested is not None and ram is not None and requested > ram:
        return None  # more than the machine has: a bug
    size = "" if requested is None else f" of {requested / 2**20:.0f} MiB"
    return f"the machine's memory is full: an allocation{size} failed ({type(error).__name__})"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    """A fixture that could not start a process or allocate for the machine's state: a skip."""
    try:
        return (yield)
    except (OSError, MemoryError, RuntimeError) as error:
        if (reason := machine_state_reason(error)) is None:
            raise
        pytest.skip(reason)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A test that could not start a process or allocate for the machine's state: a skip."""
    try:
        return (yield)
    except (OSError, MemoryError, RuntimeError) as error:
        if (reason := machine_state_reason(error)) is None:
            raise
        pytest.skip(reason)


def shared_data_dir() -> Path | None:
    """Where the real motion clips live, or None when they are not available.

    ``SKELAGNOSTIC_TEST_DATA`` wins; the default is ``../shared/data`` next to the
    repository checkout.
    """
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    path = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    return path if path.is_dir() else None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of the real clips (human/, dog/); skips the test when absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip(
            "real clips not found: set SKELAGNOSTIC_TEST_DATA or place them in ../shared/data"
        )
    return path


@pytest.fixture(scope="session")
def lafan_clip(shared_data: Path) -> Path:
    """The short LaFAN1 clip (391 frames, 30 fps)."""
    return shared_data / "human" / "lafan1" / "Lafan1_example.bvh"


@pytest.fixture(scope="session")
def _session_window_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One window cache per test session (per xdist worker)."""
    return tmp_path_factory.mktemp("window-cache")


@pytest.fixture(autouse=True)
def _isolated_window_cache(
    monkeypatch: pytest.MonkeyPatch, _session_window_cache: Path
) -> Iterator[None]:
    """Point ``$SKELAGNOSTIC_CACHE`` at a temporary directory for every test.

    Data modules built without ``cache_dir`` (and CLI runs without
    ``data.cache_dir``, subprocesses included) would otherwise write into the
    user's ``~/.cache/skelagnostic``. A test may still set its own.
    """
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(_session_window_cache))
    yield


# --------------------------------------------------------------------------- method plugins

#: A small HuMoT network for fast tests (the paper's sizes are checked separately).
HUMOT_SMALL = {"dim": 32, "latent": 16, "blocks": 1, "heads": 4, "kernel_size": 3}
#: A small PC-MRL stage-1 network for fast tests (the paper's sizes are checked separately).
PCMRL_TINY = {
    "dim": 8,
    "stages": 2,
    "point_heads": 2,
    "temporal_dim": 16,
    "temporal_layers": 1,
    "temporal_heads": 2,
    "num_source_points": 64,
    "num_target_points": 128,
}


def method_plugin_manager(name: str) -> PluginManager:
    """A plugin manager with the built-ins and the method plugin ``name`` (no entry points)."""
    from skelagnostic.plugins import PluginManager

    plugin = importlib.import_module(f"skelagnostic_{name}.plugin")
    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, name, source=f"skelagnostic-{name}")
    return pm


@pytest.fixture
def humot_pm() -> PluginManager:
    """A plugin manager with the built-ins and HuMoT."""
    return method_plugin_manager("humot")


@pytest.fixture
def pcmrl_pm() -> PluginManager:
    """A plugin manager with the built-ins and PC-MRL."""
    return method_plugin_manager("pcmrl")


@pytest.fixture
def vqpae_pm() -> PluginManager:
    """A plugin manager with the built-ins and VQ-PAE."""
    return method_plugin_manager("vqpae")


@pytest.fixture
def humot_small() -> dict[str, int]:
    """Constructor arguments of a small HuMoT network (a fresh copy per test)."""
    return dict(HUMOT_SMALL)


@pytest.fixture
def pcmrl_tiny() -> dict[str, int]:
    """Constructor arguments of a small PC-MRL stage-1 network (a fresh copy per test)."""
    return dict(PCMRL_TINY)
