"""SKELAGNOSTIC_ALLOCATOR: finding tcmalloc/jemalloc, the preload environment, the CLI restart."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from skelagnostic.cli import allocator
from skelagnostic.cli.allocator import (
    ALLOCATOR_ENV,
    AllocatorError,
    active_allocator,
    find_allocator,
    preload_environment,
)


def installed(name: str) -> str | None:
    try:
        return find_allocator(name)
    except AllocatorError:
        return None


def fake_library(folder: Path, file: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / file).write_bytes(b"\x7fELF")
    return folder / file


def test_find_prefers_the_virtual_environment(tmp_path: Path) -> None:
    lib = fake_library(tmp_path / "venv" / "lib", "libjemalloc.so.2")
    found = find_allocator("jemalloc", {"VIRTUAL_ENV": str(tmp_path / "venv")})
    assert found == str(lib)
    # tcmalloc: the minimal build first (no heap profiler), the full one otherwise
    fake_library(tmp_path / "conda" / "lib", "libtcmalloc.so.4")
    minimal = fake_library(tmp_path / "conda" / "lib", "libtcmalloc_minimal.so.4")
    assert find_allocator("tcmalloc", {"CONDA_PREFIX": str(tmp_path / "conda")}) == str(minimal)


def test_find_names_the_package_when_missing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(allocator, "_search_dirs", lambda environ: [tmp_path])
    monkeypatch.setattr("ctypes.util.find_library", lambda name: None)
    with pytest.raises(AllocatorError) as err:
        find_allocator("tcmalloc", {})
    message = str(err.value)
    assert f"{ALLOCATOR_ENV}='tcmalloc'" in message and "libtcmalloc_minimal.so" in message
    assert "apt install libtcmalloc-minimal4" in message and str(tmp_path) in message


def test_find_rejects_unknown_names_and_missing_paths(tmp_path: Path) -> None:
    with pytest.raises(AllocatorError, match=r"unknown allocator.*tcmalloc, jemalloc"):
        find_allocator("mimalloc")
    with pytest.raises(AllocatorError, match="no such shared library file"):
        find_allocator(str(tmp_path / "libnothing.so"))
    # a path must be a shared library the dynamic linker loads (not just a file):
    # one this process has mapped will do (tests/reliability/test_allocator_paths.py)
    lib = next(
        Path(line.split()[-1])
        for line in Path("/proc/self/maps").read_text().splitlines()
        if Path(line.split()[-1]).name.startswith("libm.so")
    )
    assert find_allocator(str(lib)) == str(lib.resolve())


def test_preload_environment(tmp_path: Path) -> None:
    lib = fake_library(tmp_path / "lib", "libtcmalloc_minimal.so.4")
    environ = {"VIRTUAL_ENV": str(tmp_path), "LD_PRELOAD": "/opt/other.so", "KEEP": "1"}
    env = preload_environment("tcmalloc", environ, active="system")
    assert env is not None and env["LD_PRELOAD"] == f"{lib}:/opt/other.so" and env["KEEP"] == "1"
    assert environ["LD_PRELOAD"] == "/opt/other.so"  # the caller's mapping is left alone
    # nothing to do: the system allocator, or the one already running
    for name in ("system", "glibc", "", " "):
        assert preload_environment(name, environ, active="jemalloc") is None
    assert preload_environment("tcmalloc", environ, active="tcmalloc") is None
    # already preloaded but not running: the library failed to load; restarting would loop
    with pytest.raises(AllocatorError, match="failed to load"):
        preload_environment("tcmalloc", env, active="system")


def test_switching_allocators_takes_the_preloaded_one_out(tmp_path: Path) -> None:
    from skelagnostic.cli.allocator import allocator_environment

    jemalloc = fake_library(tmp_path / "lib", "libjemalloc.so.2")
    environ = {
        "VIRTUAL_ENV": str(tmp_path),
        "LD_PRELOAD": "/usr/lib/libtcmalloc_minimal.so.4 /opt/keep.so",
    }
    env = preload_environment("jemalloc", environ, active="tcmalloc")
    assert env is not None and env["LD_PRELOAD"] == f"{jemalloc}:/opt/keep.so"
    # a new process on the C library's allocator, whatever this one runs on
    assert allocator_environment("system", environ)["LD_PRELOAD"] == "/opt/keep.so"
    alone = allocator_environment("system", {"LD_PRELOAD": "libjemalloc.so.2"})
    assert "LD_PRELOAD" not in alone and "MALLOC_CONF" not in alone
    assert allocator_environment("jemalloc", environ)["LD_PRELOAD"] == env["LD_PRELOAD"]
    assert environ["LD_PRELOAD"].startswith("/usr/lib/libtcmalloc")  # left alone


def test_system_takes_an_inherited_preloaded_allocator_out() -> None:
    environ = {"LD_PRELOAD": "/usr/lib/libtcmalloc_minimal.so.4:/opt/keep.so", "KEEP": "1"}
    env = preload_environment("system", environ, active="tcmalloc")
    assert env is not None and env["LD_PRELOAD"] == "/opt/keep.so" and env["KEEP"] == "1"
    assert environ["LD_PRELOAD"].startswith("/usr/lib/libtcmalloc")  # left alone
    alone = preload_environment("glibc", {"LD_PRELOAD": "libjemalloc.so.2"}, active="jemalloc")
    assert alone is not None and "LD_PRELOAD" not in alone
    # already on the system allocator, or the running one is not preloaded (a restart
    # could not change it, and must not loop)
    assert preload_environment("system", environ, active="system") is None
    assert preload_environment("system", {"LD_PRELOAD": "/opt/keep.so"}, active="tcmalloc") is None


def test_jemalloc_gets_options_unless_the_user_set_some(tmp_path: Path) -> None:
    fake_library(tmp_path / "lib", "libjemalloc.so.2")
    environ = {"VIRTUAL_ENV": str(tmp_path)}
    env = preload_environment("jemalloc", environ, active="system")
    assert env is not None and env["MALLOC_CONF"] == allocator.JEMALLOC_CONF
    assert "dirty_decay_ms:-1" in env["MALLOC_CONF"]
    mine = preload_environment("jemalloc", {**environ, "MALLOC_CONF": "narenas:1"}, "system")
    assert mine is not None and mine["MALLOC_CONF"] == "narenas:1"
    fake_library(tmp_path / "lib", "libtcmalloc_minimal.so.4")
    tcmalloc = preload_environment("tcmalloc", environ, active="system")
    assert tcmalloc is not None and "MALLOC_CONF" not in tcmalloc


def test_preload_environment_off_linux(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "darwin")
    with pytest.raises(AllocatorError, match="Linux only"):
        preload_environment("jemalloc", {}, active="system")
    assert preload_environment("system", {}, active="system") is None


@pytest.mark.parametrize("name", ["tcmalloc", "jemalloc"])
def test_active_allocator_reads_the_loaded_library(name: str) -> None:
    library = installed(name)
    if library is None:
        pytest.skip(f"{name} is not installed")
    code = "from skelagnostic.cli.allocator import active_allocator; print(active_allocator())"
    env = preload_environment(name, active="system")
    assert env is not None
    env.pop(ALLOCATOR_ENV, None)
    got = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert got.stdout.strip() == name
    assert active_allocator() in ("system", name)  # this process: whatever pytest runs on


def test_cli_restarts_on_the_allocator(subprocess_env: dict[str, str], tmp_path: Path) -> None:
    library = installed("tcmalloc")
    if library is None:
        pytest.skip("tcmalloc is not installed")
    env = {**subprocess_env, ALLOCATOR_ENV: "tcmalloc"}
    env.pop("LD_PRELOAD", None)
    cmd = [sys.executable, "-m", "skelagnostic.cli", "plugins"]
    proc = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    # the restarted process runs on tcmalloc, else it would refuse to restart again (exit 2)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stderr.count("restarting on") == 1 and library in proc.stderr
    assert "example" in proc.stdout  # the verb itself ran, with the same arguments

    env[ALLOCATOR_ENV] = "mimalloc"
    # shell completion answers at once, without a restart (nor its error)
    line = {"COMP_LINE": "skelagnostic plu", "COMP_POINT": "16"}
    done = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "-sc", "query=bash"],
        env={**env, **line}, cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0 and "restarting" not in done.stderr, done.stderr
    assert "plugins" in done.stdout
    proc = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"skelagnostic: error: {ALLOCATOR_ENV}='mimalloc': unknown allocator; use one of "
        "tcmalloc, jemalloc, 'system', or the path of a shared library"
    )


def test_cli_restarts_without_an_inherited_allocator(
    subprocess_env: dict[str, str], tmp_path: Path
) -> None:
    library = installed("tcmalloc")
    if library is None:
        pytest.skip("tcmalloc is not installed")
    env = {**subprocess_env, ALLOCATOR_ENV: "system", "LD_PRELOAD": library}
    cmd = [sys.executable, "-m", "skelagnostic.cli", "plugins"]
    proc = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    # one restart: the restarted process runs on the system allocator and stays
    assert proc.stderr.count("restarting on the C library's allocator") == 1, proc.stderr
    assert "example" in proc.stdout


def test_cli_in_process_never_restarts(monkeypatch: pytest.MonkeyPatch) -> None:
    from skelagnostic import cli

    monkeypatch.setenv(ALLOCATOR_ENV, "mimalloc")  # would be an error at a process start
    assert cli.main(["--help"]) == 0


def test_kernel_time_hint_only_for_long_kernel_heavy_runs_on_the_system_allocator() -> None:
    from skelagnostic.cli.allocator import kernel_time_hint

    hint = kernel_time_hint(60.0, 40.0, "system")
    assert hint is not None and hint.startswith("40 % of this run's CPU time")
    assert f"{ALLOCATOR_ENV}=tcmalloc" in hint
    assert kernel_time_hint(60.0, 15.0, "system") is None  # 20 % in the kernel
    assert kernel_time_hint(60.0, 20.0, "system") is not None  # 25 %: the threshold
    assert kernel_time_hint(6.0, 4.0, "system") is None  # too short to judge
    assert kernel_time_hint(60.0, 40.0, "tcmalloc") is None


def test_fit_prints_the_hint_after_its_table(
    example_plugin: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from skelagnostic import cli
    from skelagnostic.cli import app

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    fast = ["model=example", "experiment=smoke", "data.seconds=2.0", "data.clips_per_gait=1",
            "data.window=16", "data.stride=8", "model.hidden=16", "model.latent=4"]  # fmt: skip
    monkeypatch.setattr(allocator, "active_allocator", lambda: "system")
    # the command's own CPU time counts: (500, 100) before it, (570, 130) after it
    times = iter([(500.0, 100.0), (570.0, 130.0)])
    monkeypatch.setattr(app, "_cpu_times", lambda: next(times))
    assert cli.main(["fit", *fast, "runs_dir=a"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("skelagnostic fit: hint: 30 % of this run's CPU time")
    times = iter([(500.0, 100.0), (590.0, 110.0)])  # 10 % in the kernel: no hint
    assert cli.main(["fit", *fast, "runs_dir=b"]) == 0
    assert "hint" not in capsys.readouterr().err
