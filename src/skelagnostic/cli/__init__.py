"""The ``skelagnostic`` command line: a thin verb dispatcher.

Each verb lives in its own module and is imported only when called, so
``skelagnostic --help`` and light verbs stay fast.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

#: verb -> ("module", "function", one-line help)
VERBS: dict[str, tuple[str, str, str]] = {
    "demo": ("skelagnostic.cli.demo", "main", "procedural/BVH motion -> FK -> BVH + PNG"),
    "fit": ("skelagnostic.cli.app", "fit", "train an aligner: model=<name> [data=...] [overrides]"),
    "validate": ("skelagnostic.cli.app", "validate", "evaluate on the validation split"),
    "test": ("skelagnostic.cli.app", "test", "evaluate on the test split"),
    "predict": ("skelagnostic.cli.app", "predict", "aligner outputs -> predictions.pt"),
    "plugins": ("skelagnostic.cli.plugins", "main", "list plugins: name, version, source, status"),
    "render": ("skelagnostic.cli.render", "main", "render a motion to PNG/GIF"),
    "retarget": ("skelagnostic.cli.infer", "retarget",
                 "a trained aligner moves a BVH onto another skeleton"),
    "interpolate": ("skelagnostic.cli.infer", "interpolate",
                    "a trained aligner fills the frames between keyframes of a BVH"),
    "transfer": ("skelagnostic.cli.infer", "transfer",
                 "a trained aligner re-enacts a BVH with another character's clips"),
    "export": ("skelagnostic.cli.export", "main",
               "a trained aligner's networks -> ONNX / TorchScript files + JSON sidecars"),
}


def _usage() -> str:
    lines = ["usage: skelagnostic VERB [ARGS...]", "", "verbs:"]
    width = max(len(v) for v in VERBS)
    for verb, (_, _, text) in VERBS.items():
        lines.append(f"  {verb:<{width}}  {text}")
    lines.append("")
    lines.append("Run 'skelagnostic VERB --help' for the options of one verb.")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``skelagnostic`` console script.

    Args:
        argv: Arguments without the program name (defaults to ``sys.argv[1:]``).

    Returns:
        The process exit code.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in {"-h", "--help", "help"}:
        print(_usage())
        return 0
    verb, rest = args[0], args[1:]
    if verb not in VERBS:
        print(f"skelagnostic: unknown verb {verb!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    module_name, func_name, _ = VERBS[verb]
    func = getattr(importlib.import_module(module_name), func_name)
    return int(func(rest) or 0)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
