"""``SKELAGNOSTIC_ALLOCATOR=<path>`` that is not a loadable shared library (issue 47, item 16).

Before: the command restarted itself with the file in ``LD_PRELOAD``, the dynamic
linker printed its warning and the verb ran on the C library's allocator, exit 0.
Now: one line naming the variable, the file and the cause, exit 2, no restart.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from skelagnostic.cli.allocator import ALLOCATOR_ENV, AllocatorError, find_allocator

REPO = Path(__file__).resolve().parents[2]
TROUBLESHOOTING = REPO / "docs" / "troubleshooting.md"

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="allocators are chosen on Linux only"
)


def _loaded_library(stem: str) -> str:
    """The path of a shared library this process has mapped (e.g. ``libm.so``)."""
    for line in Path("/proc/self/maps").read_text().splitlines():
        path = line.split()[-1]
        if Path(path).name.startswith(stem):
            return path
    pytest.skip(f"no {stem} mapped into this process")


def _elf(path: Path, e_type: int, machine: int, bits: int = 2) -> Path:
    """A file with just an ELF header of the given type, machine and class."""
    ident = b"\x7fELF" + bytes([bits, 1, 1]) + bytes(9)
    path.write_bytes(ident + struct.pack("<HH", e_type, machine) + bytes(44))
    return path


@pytest.fixture
def cli_env(tmp_path: Path) -> dict[str, str]:
    """The environment of the CLI: no allocator chosen or preloaded, no plugin loaded."""
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", ALLOCATOR_ENV)}
    env["PYTHONPATH"] = str(REPO / "src")
    env["SKELAGNOSTIC_LOAD_PLUGINS"] = ""
    env["SKELAGNOSTIC_CACHE"] = str(tmp_path / "cache")
    return env


def _run(env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "cache", "info"],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_paths_that_are_not_shared_libraries_are_named(tmp_path: Path) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a library\n")
    cases = {
        str(text): "not a shared library (no ELF header)",
        str(tmp_path): "a directory, not a shared library file",
        str(tmp_path / "missing.so"): "no such shared library file",
        str(_elf(tmp_path / "prog", 2, 62)): "an executable, not a shared library",
        str(_elf(tmp_path / "obj.o", 1, 62)): "a relocatable object file, not a shared library",
        str(_elf(tmp_path / "libarm.so", 3, 40, bits=1)): "a shared library for 32-bit ARM",
    }
    for name, cause in cases.items():
        with pytest.raises(AllocatorError) as caught:
            find_allocator(name)
        assert str(caught.value).startswith(f"{ALLOCATOR_ENV}={name!r}: {cause}"), caught.value
    # an ELF shared object the dynamic linker still refuses: a position-independent
    # executable (what most distributions build); the linker's reason is quoted
    with pytest.raises(AllocatorError, match=r"the dynamic linker cannot preload it \(.+\)"):
        find_allocator("/bin/ls" if Path("/bin/ls").is_file() else sys.executable)
    libm = _loaded_library("libm.so")
    assert find_allocator(libm) == str(Path(libm).resolve())


def test_cli_refuses_a_text_file_with_one_line(tmp_path: Path, cli_env: dict[str, str]) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a library\n")
    for value, cause in (
        (str(text), "not a shared library (no ELF header); give tcmalloc, jemalloc, 'system', "
         "or the path of a lib*.so file"),
        (str(tmp_path), "a directory, not a shared library file"),
        (str(tmp_path / "none.so"), "no such shared library file"),
    ):  # fmt: skip
        proc = _run({**cli_env, ALLOCATOR_ENV: value}, tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.strip() == f"skelagnostic: error: {ALLOCATOR_ENV}={value!r}: {cause}"
        assert "ld.so" not in proc.stderr and "restarting" not in proc.stderr
        assert proc.stdout == ""  # the verb did not run
    page = TROUBLESHOOTING.read_text(encoding="utf-8")
    assert (
        f"skelagnostic: error: {ALLOCATOR_ENV}='<tmp>/notes.txt': not a shared library (no ELF "
        "header); give tcmalloc, jemalloc, 'system', or the path of a lib*.so file" in page
    )


def test_cli_runs_on_a_library_path_that_loads(tmp_path: Path, cli_env: dict[str, str]) -> None:
    libm = str(Path(_loaded_library("libm.so")).resolve())
    proc = _run({**cli_env, ALLOCATOR_ENV: libm}, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("restarting on") == 1 and "ld.so" not in proc.stderr
    assert proc.stdout.startswith("cache: ")


def test_a_preloaded_path_that_did_not_load_is_an_error(
    tmp_path: Path, cli_env: dict[str, str]
) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a library\n")
    # as after a restart: LD_PRELOAD already names the file, the linker ignored it
    env = {**cli_env, ALLOCATOR_ENV: str(text), "LD_PRELOAD": str(text)}
    proc = _run(env, tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        f"skelagnostic: error: {ALLOCATOR_ENV}={str(text)!r}: LD_PRELOAD names it but it is "
        "not loaded (the dynamic linker refused it; see its message above)"
    )
    assert proc.stdout == ""
