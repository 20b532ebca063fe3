"""``skelagnostic export``: write a trained aligner's networks (ONNX, TorchScript) or weights.

Usage::

    skelagnostic export ckpt_path=PATH format=onnx|torchscript|safetensors [out=DIR]
                        [model=NAME] [threads=N]

Every graph the aligner declares (:meth:`~skelagnostic.aligners.Aligner.export_graphs`)
becomes ``DIR/<graph>.onnx`` (or ``.pt``) plus the JSON sidecar ``DIR/<graph>.json``
(inputs, outputs, dynamic and fixed axes, normalisation statistics, skeleton).
``format=safetensors`` writes the weights and the model config as ``DIR/model.safetensors``,
which ``ckpt=DIR`` (or the file) loads back, and the run's ``model`` and ``data`` config as
``DIR/config.yaml``.
Path options expand ``~`` and ``$VARS``.
The checkpoint is loaded like the inference verbs do
(:func:`skelagnostic.cli.infer.load_from_checkpoint`).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from skelagnostic.core.paths import expand_path
from skelagnostic.errors import SkelagnosticError, error_line, printable

__all__ = ["main"]

_OPTIONS = {
    "ckpt_path": "checkpoint written by `skelagnostic fit` (required; `ckpt=` also works)",
    "format": "onnx, torchscript or safetensors (weights + model config) (required)",
    "out": "output directory; default: <checkpoint name>-<format> next to the checkpoint",
    "model": "registered aligner name; default: model.name of the run's config.yaml",
    "threads": "torch intra-op threads (a positive integer); default: torch's",
}

_USAGE = (
    "usage: skelagnostic export ckpt_path=PATH format=onnx|torchscript|safetensors "
    "[out=DIR] [model=NAME]\n\n"
    "Write the networks of a trained aligner for a game engine or another runtime:\n"
    "one .onnx (or TorchScript .pt) file per network plus a .json sidecar describing\n"
    "its inputs, outputs, dynamic axes, normalisation statistics and skeleton.\n"
    "format=safetensors writes the weights and model config as model.safetensors,\n"
    "loadable back with ckpt=DIR.\n\n"
    "options:\n" + "\n".join(f"  {k:<10} {v}" for k, v in _OPTIONS.items())
)


def main(argv: list[str]) -> int:
    """Run ``skelagnostic export``.

    Args:
        argv: The words after the verb.

    Returns:
        0 on success, 2 on a usage or export error (one line on stderr).
    """
    from skelagnostic.cli.render import wants_help

    if not argv or wants_help(argv):
        print(_USAGE)
        return 0 if argv else 2
    try:
        from skelagnostic.aligners.export import FORMATS, export_aligner
        from skelagnostic.cli.infer import load_from_checkpoint
        from skelagnostic.cli.render import apply_threads, parse_arguments
        from skelagnostic.io.outputs import check_output_dir

        words, options = parse_arguments(argv)
        if words:
            raise SkelagnosticError(
                f"unexpected argument {words[0]!r}; options are key=value, "
                "see 'skelagnostic export --help'"
            )
        if "ckpt" in options and "ckpt_path" in options:
            raise SkelagnosticError("give ckpt_path= or ckpt=, not both")
        if "ckpt" in options:
            options["ckpt_path"] = options.pop("ckpt")
        unknown = sorted(set(options) - set(_OPTIONS))
        if unknown:
            raise SkelagnosticError(
                f"unknown option(s) {', '.join(k + '=' for k in unknown)}; "
                "see 'skelagnostic export --help'"
            )
        apply_threads(options)
        for key in ("ckpt_path", "format"):
            if key not in options:
                raise SkelagnosticError(f"missing option {key}=")
        fmt = options["format"]
        if fmt not in FORMATS:
            raise SkelagnosticError(f"option format={fmt!r}: use one of {', '.join(FORMATS)}")
        ckpt = expand_path(options["ckpt_path"])
        out = (
            expand_path(options["out"])
            if options.get("out")
            else ckpt.parent / f"{ckpt.stem}-{fmt}"
        )
        check_output_dir(out, "out")  # before the checkpoint is loaded
        aligner = load_from_checkpoint(ckpt, options.get("model"))
        name = options.get("model") or _registered_name(aligner)
        written = export_aligner(aligner, fmt, out, name)
        if fmt == "safetensors":
            written.append(_write_config(out, ckpt, aligner, name))
        for path in written:
            print(printable(path))
    except SkelagnosticError as error:
        print(error_line("skelagnostic export", error), file=sys.stderr)
        return 2
    return 0


def _write_config(out: Path, ckpt: Path, aligner: Any, name: str) -> Path:
    """``out/config.yaml`` beside the weights: the run's ``model`` and ``data`` nodes.

    With it, ``evaluate ckpt_path=out/model.safetensors`` reuses the model and data
    config as it does for a run's checkpoint. Without a run (a checkpoint reader's
    ``<scheme>:<path>``), the model node is the aligner's hyperparameters.
    """
    from omegaconf import OmegaConf

    from skelagnostic.cli.runs import CONFIG_FILE, REUSED, find_run_dir
    from skelagnostic.io.outputs import output_path

    run_dir = find_run_dir(ckpt) if ckpt.exists() else None
    if run_dir is not None:
        saved = OmegaConf.load(run_dir / CONFIG_FILE)
        config = OmegaConf.create({k: saved[k] for k in REUSED if k in saved})
    else:
        config = OmegaConf.create({"model": {"name": name, **dict(aligner.hparams)}})
    path = out / CONFIG_FILE
    with output_path(path) as tmp:
        OmegaConf.save(config, tmp)
    return path


def _registered_name(aligner: object) -> str:
    """The registered name of ``aligner``'s class (``""`` when it is not registered)."""
    from skelagnostic.plugins import get_plugin_manager

    for name, spec in get_plugin_manager().aligners.items():
        if spec.module is type(aligner):
            return name
    return ""
