"""The ``skelagnostic`` command line: a thin verb dispatcher.

Each verb lives in its own module and is imported only when called, so
``skelagnostic --help`` and light verbs stay fast.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from skelagnostic._shadow import ShadowedPackageError, check_not_shadowed
from skelagnostic.cli.allocator import ALLOCATOR_ENV, reexec_with_allocator
from skelagnostic.cli.signals import SIGTERM_EXIT_CODE, Terminated, sigterm_raises
from skelagnostic.errors import SkelagnosticError, error_line, printable

#: verb -> ("module", "function", one-line help)
VERBS: dict[str, tuple[str, str, str]] = {
    "demo": (
        "skelagnostic.cli.demo",
        "main",
        "procedural/BVH motion -> FK -> BVH + PNG + GIF (html=: 3D viewer page)",
    ),
    "fit": ("skelagnostic.cli.app", "fit", "train an aligner: model=<name> [data=...] [overrides]"),
    "validate": ("skelagnostic.cli.app", "validate", "evaluate on the validation split"),
    "test": ("skelagnostic.cli.app", "test", "evaluate on the test split"),
    "predict": ("skelagnostic.cli.app", "predict", "aligner outputs -> predictions.pt"),
    "evaluate": (
        "skelagnostic.cli.app",
        "evaluate",
        "a plugin's protocol on held-out clips: model vs baselines -> evaluation.json",
    ),
    "plugins": (
        "skelagnostic.cli.plugins",
        "main",
        "list plugins and what they provide; plugins NAME: an aligner's defaults",
    ),
    "new-plugin": (
        "skelagnostic.cli.new_plugin",
        "main",
        "write a third-party aligner package: new-plugin NAME [--dir DIR]",
    ),
    "cache": ("skelagnostic.cli.cache", "main", "window cache: info (entries, size) or clear"),
    "data": (
        "skelagnostic.cli.data",
        "main",
        "install a dataset: data prepare PRESET --zip FILE --dest DIR, or data get",
    ),
    "render": (
        "skelagnostic.cli.render",
        "main",
        "draw BVH clips: GIF/MP4 animation, PNG contact sheet or HTML 3D viewer",
    ),
    "retarget": (
        "skelagnostic.cli.infer",
        "retarget",
        "a trained aligner moves a BVH onto another skeleton",
    ),
    "interpolate": (
        "skelagnostic.cli.infer",
        "interpolate",
        "a trained aligner fills the frames between keyframes of a BVH",
    ),
    "transfer": (
        "skelagnostic.cli.infer",
        "transfer",
        "a trained aligner re-enacts a BVH with another character's clips",
    ),
    "export": (
        "skelagnostic.cli.export",
        "main",
        "a trained aligner's networks -> ONNX / TorchScript files + JSON sidecars",
    ),
}


def _usage() -> str:
    lines = ["usage: skelagnostic VERB [ARGS...]", "", "verbs:"]
    width = max(len(v) for v in VERBS)
    for verb, (_, _, text) in VERBS.items():
        lines.append(f"  {verb:<{width}}  {text}")
    lines += ["", "environment:"]
    width = max(len(name) for name in ENVIRONMENT)
    lines += [f"  {name:<{width}}  {text}" for name, text in ENVIRONMENT.items()]
    lines.append("")
    lines.append("Run 'skelagnostic VERB --help' for the options of one verb.")
    return "\n".join(lines)


#: Environment variables the command reads -> one-line help (``skelagnostic --help``). The
#: names are those of the modules that read them (a test checks), spelled out here so that
#: the help does not import them.
ENVIRONMENT: dict[str, str] = {
    "SKELAGNOSTIC_DATA": "folder of the corpora presets (data=lafan1: $SKELAGNOSTIC_DATA/lafan1)",
    "SKELAGNOSTIC_CACHE": "window cache folder (default ~/.cache/skelagnostic)",
    "SKELAGNOSTIC_ALLOCATOR": "tcmalloc | jemalloc | system: run on that memory allocator (Linux)",
    "SKELAGNOSTIC_LOAD_PLUGINS": "comma-separated plugins to load (unset: all)",
    "SKELAGNOSTIC_DEBUG": "1: full tracebacks instead of one-line errors",
}


#: Verbs that are one Hydra application (flags, overrides, shell completion).
HYDRA_VERBS = ("fit", "validate", "test", "predict", "evaluate")


def _complete(args: list[str]) -> int:
    """Answer a shell-completion query of Hydra's bash/zsh/fish script.

    The script installed by ``skelagnostic fit --shell-completion install=bash``
    calls ``skelagnostic -sc query=bash`` with the line being typed in
    ``COMP_LINE``. The first word after ``skelagnostic`` is completed with the
    verbs; after a Hydra verb, the query goes to that verb's Hydra app with the
    verb removed from the line (Hydra expects ``<app> <overrides...>``).
    """
    line = os.environ.get("COMP_LINE", "")
    words = line.split(" ")
    if len(words) <= 2:  # still typing the verb
        prefix = words[1] if len(words) == 2 else ""
        print(" ".join(v for v in VERBS if v.startswith(prefix)))
        return 0
    verb = words[1]
    if verb not in HYDRA_VERBS:
        return 0
    point = int(os.environ.get("COMP_POINT", len(line)))
    os.environ["COMP_LINE"] = " ".join([words[0], *words[2:]])
    os.environ["COMP_POINT"] = str(max(0, point - len(verb) - 1))
    from skelagnostic.cli import app

    return app.main(verb, args)


@contextmanager
def _plugin_warnings_on_one_line() -> Iterator[None]:
    """Show each ``PluginLoadWarning`` as ``skelagnostic: warning: ...``.

    Python's default format adds the warning's file, line and source line; a
    skipped plugin is one line naming it and why. Other warnings, and warnings
    recorded rather than shown, are left alone. The plugin module is not
    imported for this (light verbs stay light).
    """
    formatted = warnings.formatwarning

    def format_warning(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        line: str | None = None,
    ) -> str:
        manager = sys.modules.get("skelagnostic.plugins.manager")
        if manager is not None and issubclass(category, manager.PluginLoadWarning):
            return f"skelagnostic: warning: {printable(message)}\n"
        return formatted(message, category, filename, lineno, line)

    warnings.formatwarning = format_warning
    try:
        yield
    finally:
        if warnings.formatwarning is format_warning:
            warnings.formatwarning = formatted


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``skelagnostic`` console script.

    When ``argv`` is ``None`` (a new process) and ``SKELAGNOSTIC_ALLOCATOR`` names a
    memory allocator that is not loaded, the command first restarts itself on it
    (:func:`skelagnostic.cli.allocator.reexec_with_allocator`). Output into a closed pipe
    (``skelagnostic --help | head``) ends the command quietly with exit code 1, as
    Python's documentation recommends (the note on SIGPIPE in :mod:`signal`): the rest
    of the output goes to ``os.devnull`` instead of a ``BrokenPipeError`` traceback.

    Args:
        argv: Arguments without the program name (defaults to ``sys.argv[1:]``).

    Returns:
        The process exit code.
    """
    try:
        code = _main(argv)
        sys.stdout.flush()  # a closed pipe shows here, not in Python's flush at exit
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(AttributeError, OSError, ValueError):
                os.dup2(devnull, stream.fileno())
        return 1
    return code


def _main(argv: Sequence[str] | None) -> int:
    """:func:`main` without the closed-pipe handling."""
    try:
        check_not_shadowed()  # `python -m skelagnostic.cli` beside a checkout named skelagnostic
    except ShadowedPackageError as exc:
        print(f"skelagnostic: error: {exc}", file=sys.stderr)
        return 2
    args = list(sys.argv[1:] if argv is None else argv)
    completing = args[:1] in (["-sc"], ["--shell-completion"])  # answered by this process
    if argv is None and os.environ.get(ALLOCATOR_ENV) and not completing:  # a process start
        try:
            reexec_with_allocator(args)
        except SkelagnosticError as exc:
            print(error_line("skelagnostic", exc), file=sys.stderr)
            return 2
    if not args or args[0] in {"-h", "--help", "help"}:
        print(_usage())
        return 0
    if args[0] in {"-sc", "--shell-completion"}:
        return _complete(args)
    verb, rest = args[0], args[1:]
    if verb not in VERBS:
        print(
            f"skelagnostic: error: unknown verb {verb!r} (verbs: {', '.join(VERBS)}); "
            "see 'skelagnostic --help'",
            file=sys.stderr,
        )
        return 2
    module_name, func_name, _ = VERBS[verb]
    func = getattr(importlib.import_module(module_name), func_name)
    try:
        # SIGTERM: clean-up code runs, then one line (not silence)
        with sigterm_raises(), _plugin_warnings_on_one_line():
            return int(func(rest) or 0)
    except Terminated:
        print(
            f"skelagnostic {verb}: terminated by SIGTERM; files still being written were "
            "discarded (none is left half-written)",
            file=sys.stderr,
        )
        return SIGTERM_EXIT_CODE
    except KeyboardInterrupt:  # Ctrl+C outside training (Lightning reports its own)
        print(f"skelagnostic {verb}: interrupted (Ctrl+C)", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
