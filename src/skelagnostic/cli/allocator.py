"""Choose the process's memory allocator: glibc's, tcmalloc or jemalloc.

PyTorch's CPU tensors come from ``malloc``. glibc serves every block above its
``mmap`` threshold (at most 32 MiB) with a fresh ``mmap`` and returns it to the
kernel on ``free``, so a training step whose activations are large maps and
zeroes them again at every step: page faults, counted as system time. PC-MRL's
stage 1 at the paper's batch spends about a third of its step there
(docs/reports/performance.md, "Suite `allocators`"). tcmalloc keeps freed blocks for the
next step; PyTorch's own CPU tuning guide recommends it or jemalloc.

An allocator has to be loaded before the process starts (``LD_PRELOAD``), so
the ``skelagnostic`` command re-executes itself once when
``SKELAGNOSTIC_ALLOCATOR`` asks for one that is not loaded
(:func:`reexec_with_allocator`); ``benchmarks/run.py --allocator`` does the
same. Only Linux (and glibc-based systems) is supported; elsewhere the
variable is an error.

Example:
    >>> from skelagnostic.cli.allocator import active_allocator
    >>> active_allocator() in ("system", "tcmalloc", "jemalloc")
    True
"""

from __future__ import annotations

import os
import re
import struct
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

from skelagnostic.errors import SkelagnosticError


class AllocatorError(SkelagnosticError, ValueError):
    """``SKELAGNOSTIC_ALLOCATOR`` names an allocator that cannot be loaded here."""


#: Environment variable naming the allocator of the ``skelagnostic`` command.
ALLOCATOR_ENV = "SKELAGNOSTIC_ALLOCATOR"
#: Allocator -> library names searched, in order (``lib<name>.so*``).
LIBRARIES: dict[str, tuple[str, ...]] = {
    "tcmalloc": ("tcmalloc_minimal", "tcmalloc"),
    "jemalloc": ("jemalloc",),
}
#: Names that keep the C library's allocator.
SYSTEM = ("system", "glibc", "default", "")
#: ``MALLOC_CONF`` given to jemalloc when the environment sets none: the options of
#: PyTorch's CPU launcher (``torch.backends.xeon.run_cpu``) plus no decay, so freed
#: pages stay mapped for the next step as with tcmalloc. With jemalloc's defaults, or
#: the launcher's options alone, training steps were slower than on glibc here
#: (docs/reports/performance.md, "Suite `allocators`").
JEMALLOC_CONF = (
    "oversize_threshold:1,background_thread:true,metadata_thp:auto,"
    "dirty_decay_ms:-1,muzzy_decay_ms:-1"
)
#: Where to get each allocator, for the error message.
PACKAGES: dict[str, str] = {
    "tcmalloc": "Debian/Ubuntu: apt install libtcmalloc-minimal4; conda: conda install gperftools",
    "jemalloc": "Debian/Ubuntu: apt install libjemalloc2; conda: conda install jemalloc",
}


def _search_dirs(environ: Mapping[str, str]) -> list[Path]:
    """Library folders searched before the linker's cache: environments first."""
    import sysconfig

    dirs = [Path(environ[v]) / "lib" for v in ("VIRTUAL_ENV", "CONDA_PREFIX") if environ.get(v)]
    dirs.append(Path(sys.prefix) / "lib")
    multiarch = sysconfig.get_config_var("MULTIARCH")
    for root in ("/usr/local/lib", "/usr/lib", "/lib"):
        if multiarch:
            dirs.append(Path(root) / multiarch)
        dirs.append(Path(root))
    dirs += [Path("/usr/lib64"), Path("/usr/local/lib64")]
    return dirs


#: ``e_type`` of an ELF file -> what it is (for the message); 3 is a shared object.
_ELF_TYPES = {1: "a relocatable object file", 2: "an executable", 4: "a core dump"}
#: ``e_machine`` of an ELF file -> the architecture's name (for the message).
_MACHINES = {3: "x86", 20: "PowerPC", 21: "PowerPC64", 22: "S390", 40: "ARM", 62: "x86-64"}
_MACHINES |= {183: "AArch64", 243: "RISC-V", 258: "LoongArch"}
#: What the dynamic linker writes when a preload fails; its reason in parentheses.
_LD_SO_REFUSAL = re.compile(r"cannot be preloaded \((?P<reason>.*)\): ignored")


def _elf_header(path: Path) -> tuple[int, int, int, int] | None:
    """``(class, byte order, e_type, e_machine)`` of an ELF file, or ``None`` for another file.

    Raises:
        OSError: The file cannot be read.
    """
    with path.open("rb") as fh:
        head = fh.read(20)
    if len(head) < 20 or head[:4] != b"\x7fELF" or head[5] not in (1, 2):
        return None
    e_type, machine = struct.unpack("<HH" if head[5] == 1 else ">HH", head[16:20])
    return head[4], head[5], e_type, machine


def _describe_elf(header: tuple[int, int, int, int]) -> str:
    bits = {1: "32-bit", 2: "64-bit"}.get(header[0], f"class {header[0]}")
    return f"{bits} {_MACHINES.get(header[3], f'machine {header[3]}')}"


def _preload_failure(library: str, environ: Mapping[str, str]) -> str | None:
    """Why the dynamic linker refuses to preload ``library``, or ``None`` if it loads.

    A Python interpreter is started with the library in ``LD_PRELOAD`` (``python
    -S -c ''``: some tens of milliseconds) and the linker's message is read.
    """
    import subprocess

    env = {**environ, "LD_PRELOAD": library}
    try:
        done = subprocess.run(
            [sys.executable, "-S", "-c", ""], env=env, capture_output=True, text=True, timeout=60
        )
    except (OSError, subprocess.SubprocessError):
        return None  # no verdict: the restart itself will tell
    refused = _LD_SO_REFUSAL.search(done.stderr)
    if refused:
        return refused.group("reason")
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines()
        return f"a process started with it exited with {done.returncode}" + (
            f": {lines[-1]}" if lines else ""
        )
    return None


def check_library(name: str, environ: Mapping[str, str] | None = None) -> str:
    """The absolute path of the shared library file ``name``, checked before a restart on it.

    ``LD_PRELOAD`` of a file that is not a loadable shared library only makes the
    dynamic linker print a warning and go on with the C library's allocator, so
    the file is checked first: it exists, is a file, is an ELF shared object of
    this interpreter's class and machine, and the dynamic linker preloads it into
    a short test process (which catches the rest: a position-independent
    executable, missing dependencies).

    Args:
        name: The value of ``SKELAGNOSTIC_ALLOCATOR`` (a path).
        environ: The environment of the test process (default: this process's).

    Returns:
        The resolved path.

    Raises:
        AllocatorError: One line naming the variable, the file and the cause.
    """
    environ = os.environ if environ is None else environ
    where = f"{ALLOCATOR_ENV}={name!r}"
    path = Path(name)
    if path.is_dir():
        raise AllocatorError(f"{where}: a directory, not a shared library file")
    if not path.is_file():
        raise AllocatorError(f"{where}: no such shared library file")
    try:
        header = _elf_header(path)
    except OSError as exc:
        raise AllocatorError(f"{where}: cannot read the file ({exc.strerror or exc})") from exc
    if header is None:
        raise AllocatorError(
            f"{where}: not a shared library (no ELF header); give tcmalloc, jemalloc, "
            "'system', or the path of a lib*.so file"
        )
    if header[2] != 3:
        what = _ELF_TYPES.get(header[2], f"an ELF file of type {header[2]}")
        raise AllocatorError(f"{where}: {what}, not a shared library")
    try:
        ours = _elf_header(Path(sys.executable).resolve())
    except OSError:
        ours = None
    if ours is not None and (header[0], header[1], header[3]) != (ours[0], ours[1], ours[3]):
        raise AllocatorError(
            f"{where}: a shared library for {_describe_elf(header)}; this Python is "
            f"{_describe_elf(ours)}"
        )
    library = str(path.resolve())
    reason = _preload_failure(library, environ)
    if reason is not None:
        raise AllocatorError(f"{where}: the dynamic linker cannot preload it ({reason})")
    return library


def _mapped(library: str) -> bool:
    """Whether ``library`` is mapped into this process (``True`` where that cannot be read)."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return True
    return any(line.endswith(" " + library) for line in maps.splitlines())


def find_allocator(name: str, environ: Mapping[str, str] | None = None) -> str:
    """The shared library to preload for allocator ``name``.

    Args:
        name: ``"tcmalloc"`` or ``"jemalloc"``, or the path of a shared library
            (a build of your own).
        environ: The environment whose ``VIRTUAL_ENV`` / ``CONDA_PREFIX`` are searched
            (default: this process's).

    Returns:
        A path (or, when only the linker's cache knows it, a library file name
        the dynamic linker finds).

    Raises:
        AllocatorError: Unknown name, a path that is not a shared library the
            dynamic linker can preload (:func:`check_library`), or the library is
            not installed (the message says which package provides it).
    """
    environ = os.environ if environ is None else environ
    if "/" in name:
        return check_library(name, environ)
    if name not in LIBRARIES:
        raise AllocatorError(
            f"{ALLOCATOR_ENV}={name!r}: unknown allocator; use one of "
            f"{', '.join(LIBRARIES)}, 'system', or the path of a shared library"
        )
    dirs = _search_dirs(environ)
    for library in LIBRARIES[name]:
        for folder in dirs:
            found = sorted(folder.glob(f"lib{library}.so*"))
            if found:
                return str(found[0])
    import ctypes.util

    for library in LIBRARIES[name]:
        soname = ctypes.util.find_library(library)
        if soname:
            return soname
    raise AllocatorError(
        f"{ALLOCATOR_ENV}={name!r}: no lib{LIBRARIES[name][0]}.so found (looked in "
        f"{', '.join(str(d) for d in dirs if d.is_dir())} and the linker's cache); "
        f"install it ({PACKAGES[name]}) or unset {ALLOCATOR_ENV}"
    )


def active_allocator() -> str:
    """The allocator this process runs on: ``"tcmalloc"``, ``"jemalloc"`` or ``"system"``.

    Read from the libraries mapped into the process (``/proc/self/maps``);
    ``"system"`` where that file does not exist.
    """
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return "system"
    for line in maps.splitlines():
        library = line.rsplit("/", 1)[-1]
        for name, candidates in LIBRARIES.items():
            if any(library.startswith(f"lib{c}.so") for c in candidates):
                return name
    return "system"


def preload_environment(
    name: str, environ: Mapping[str, str] | None = None, active: str | None = None
) -> dict[str, str] | None:
    """The environment that starts a process on allocator ``name``, or ``None`` if this one will do.

    Args:
        name: A value of ``SKELAGNOSTIC_ALLOCATOR`` (see :func:`find_allocator`;
            ``"system"`` or empty: the C library's own).
        environ: The current environment (default: this process's).
        active: The allocator this process runs on (default: :func:`active_allocator`).

    Returns:
        ``environ`` with the library put first in ``LD_PRELOAD`` and any other known
        allocator taken out (see :func:`allocator_environment`; for jemalloc,
        ``MALLOC_CONF`` set to :data:`JEMALLOC_CONF` unless it is set); for the system
        allocator while a preloaded one runs (inherited ``LD_PRELOAD``), ``environ``
        with the known allocators taken out of ``LD_PRELOAD``. ``None`` when ``name``
        is already the active allocator, or the active one is not preloaded (linked
        in: a restart could not change it).

    Raises:
        AllocatorError: See :func:`find_allocator`; on a system other than Linux; when
            ``LD_PRELOAD`` already names the library but it is not active (it failed
            to load: restarting again would loop).
    """
    environ = dict(os.environ if environ is None else environ)
    name = name.strip()
    active = active_allocator() if active is None else active
    if name.lower() in SYSTEM:
        if active == "system":
            return None
        env = _with_library(dict(environ), name, None)
        return None if _preloads(env) == _preloads(environ) else env
    if name in LIBRARIES and active == name:
        return None
    if not sys.platform.startswith("linux"):
        raise AllocatorError(
            f"{ALLOCATOR_ENV}={name!r}: choosing the allocator is supported on Linux only "
            f"(this is {sys.platform}); unset {ALLOCATOR_ENV}"
        )
    if "/" in name and str(Path(name).resolve()) in _preloads(environ):  # after the restart
        if _mapped(str(Path(name).resolve())):  # a custom library: it is what was asked for
            return None
        raise AllocatorError(
            f"{ALLOCATOR_ENV}={name!r}: LD_PRELOAD names it but it is not loaded (the "
            "dynamic linker refused it; see its message above)"
        )
    library = find_allocator(name, environ)
    if library in _preloads(environ):
        raise AllocatorError(
            f"{ALLOCATOR_ENV}={name!r}: LD_PRELOAD already names {library} but the process "
            f"runs on the {active} allocator (the library failed to load; see the dynamic "
            "linker's message above)"
        )
    return _with_library(environ, name, library)


def allocator_environment(name: str, environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of a new process on allocator ``name``, whatever this one runs on.

    Any allocator of :data:`LIBRARIES` already in ``LD_PRELOAD`` is taken out (two
    preloaded allocators would each claim ``malloc``); other preloads stay.

    Args:
        name: ``"tcmalloc"``, ``"jemalloc"``, a library path, or ``"system"`` (the
            C library's allocator: the preloaded allocators taken out only).
        environ: The environment to start from (default: this process's).

    Returns:
        A new environment (``environ`` is not changed).

    Raises:
        AllocatorError: See :func:`find_allocator`.
    """
    environ = dict(os.environ if environ is None else environ)
    name = name.strip()
    if name.lower() in SYSTEM:
        return _with_library(environ, name, None)
    return _with_library(environ, name, find_allocator(name, environ))


def _preloads(environ: Mapping[str, str]) -> list[str]:
    """The entries of ``LD_PRELOAD`` (colon- or space-separated)."""
    return [p for p in environ.get("LD_PRELOAD", "").replace(" ", ":").split(":") if p]


def _with_library(environ: dict[str, str], name: str, library: str | None) -> dict[str, str]:
    """``environ`` with the known allocators out of ``LD_PRELOAD`` and ``library`` first."""
    known = tuple(f"lib{lib}.so" for libs in LIBRARIES.values() for lib in libs)
    kept = [p for p in _preloads(environ) if not os.path.basename(p).startswith(known)]
    preload = ([library] if library else []) + kept
    if preload:
        environ["LD_PRELOAD"] = ":".join(preload)
    else:
        environ.pop("LD_PRELOAD", None)
    if name == "jemalloc":
        environ.setdefault("MALLOC_CONF", JEMALLOC_CONF)
    return environ


def kernel_time_hint(
    user_s: float,
    system_s: float,
    allocator: str | None = None,
    minimum_s: float = 60.0,
    share: float = 0.25,
) -> str | None:
    """A hint to try tcmalloc, when a run on the system allocator spent much CPU time in the kernel.

    Args:
        user_s: The run's CPU time in user mode (seconds).
        system_s: Its CPU time in the kernel (page faults are counted there).
        allocator: The allocator it ran on (default: :func:`active_allocator`).
        minimum_s: Runs shorter than this (user + system) get no hint.
        share: The kernel's share of the CPU time from which the hint is given.

    Returns:
        One sentence, or ``None`` (a short run, a small kernel share, another
        allocator already, or a system other than Linux).
    """
    total = user_s + system_s
    if total < minimum_s or system_s < share * total or not sys.platform.startswith("linux"):
        return None
    if (active_allocator() if allocator is None else allocator) != "system":
        return None
    return (
        f"{100 * system_s / total:.0f} % of this run's CPU time was spent in the kernel, "
        "mostly page faults of large tensors on the C library's malloc; "
        f"{ALLOCATOR_ENV}=tcmalloc may train faster with the same results "
        "(docs: CLI, 'Memory allocator')"
    )


def reexec_with_allocator(args: Sequence[str], environ: Mapping[str, str] | None = None) -> None:
    """Restart ``python -m skelagnostic.cli ARGS`` on the allocator of ``SKELAGNOSTIC_ALLOCATOR``.

    Returns without doing anything when the variable is unset or names the allocator
    already running (``system`` while a preloaded allocator runs restarts without
    it). Otherwise prints one line to stderr and replaces this process
    (``os.execve``; nothing after it runs).

    Args:
        args: The command's arguments (without the program name).
        environ: The environment (default: this process's).

    Raises:
        AllocatorError: See :func:`preload_environment`.
    """
    environ = os.environ if environ is None else environ
    name = environ.get(ALLOCATOR_ENV, "")
    env = preload_environment(name, environ)
    if env is None:
        return
    target = (
        "the C library's allocator (the preloaded one taken out of LD_PRELOAD)"
        if name.strip().lower() in SYSTEM
        else env["LD_PRELOAD"].split(":")[0]
    )
    print(
        f"skelagnostic: restarting on {target} ({ALLOCATOR_ENV})",
        file=sys.stderr,
        flush=True,
    )
    sys.stdout.flush()
    os.execve(sys.executable, [sys.executable, "-m", "skelagnostic.cli", *args], env)
