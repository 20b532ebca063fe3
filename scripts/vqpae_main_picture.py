"""Write the main job's picture shown in the README (docs/assets/vqpae_main_job.png).

Takes the run directory of `skelagnostic fit model=vqpae experiment=vqpae_main`,
computes its end-of-fit summary again from `checkpoints/last.ckpt` (the run's
config.yaml and split.json give the same clips:
summary_of_run below) into `<run>/summary_again/`, and
copies its `vqpae_transfer.png` (held-out human clip, the dog's VQ-PAE transfer
and the two baselines at one scale, the feet's strides over time) to OUT, in a
64-colour palette to keep the README light.

Usage: python scripts/vqpae_main_picture.py RUN_DIR [OUT.png] [--mode full|quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from PIL import Image
from skelagnostic_vqpae.protocols.summary import SUMMARY_PLANS, fit_summary

from skelagnostic.errors import SkelagnosticError

ROOT = Path(__file__).resolve().parents[1]


def summary_of_run(
    run_dir: str | Path,
    out_dir: str | Path | None = None,
    mode: str = "full",
    checkpoint: str = "last",
) -> list[Path]:
    """The end-of-fit summary of a finished VQ-PAE run, computed again from its checkpoint.

    The run's saved ``config.yaml`` (model and data) and ``split.json`` rebuild its
    data module with the same clips in each split; ``checkpoints/<checkpoint>.ckpt``
    (``last``: the weights the fit's own summary saw) gives the aligner. The files
    are those of the fit summary (``vqpae_metrics.json``, ``summary.md``,
    ``vqpae_transfer.png``, ...), written into ``out_dir``.

    Args:
        run_dir: The run directory of a ``skelagnostic fit model=vqpae ...``.
        out_dir: Where the files go (default: ``<run_dir>/summary_again``).
        mode: ``"full"`` or ``"quick"`` (:data:`SUMMARY_PLANS`).
        checkpoint: ``"last"`` or ``"best"``.

    Returns:
        The written paths.

    Raises:
        SkelagnosticError: Not a run directory, a checkpoint missing or of another
            model, or an unknown mode.
    """
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from skelagnostic.aligners.checkpoints import load_checkpoint, read_checkpoint
    from skelagnostic.callbacks import FitSummary
    from skelagnostic.cli.app import build_datamodule, compose
    from skelagnostic.cli.runs import CONFIG_FILE, checkpoint_of, read_split, reuse_run_config
    from skelagnostic.plugins import get_plugin_manager

    if mode not in SUMMARY_PLANS:
        raise SkelagnosticError(f"mode: one of {', '.join(SUMMARY_PLANS)}, got {mode!r}")
    run = Path(run_dir)
    if not (run / CONFIG_FILE).is_file():
        raise SkelagnosticError(f"run_dir: {str(run)!r} holds no {CONFIG_FILE} (not a run)")
    out = Path(out_dir) if out_dir is not None else run / "summary_again"
    saved = OmegaConf.load(run / CONFIG_FILE)
    pm = get_plugin_manager()
    spec = pm.aligner(saved.model.name)
    cfg = compose([f"model={saved.model.name}", f"run_dir={out}"], plugin_manager=pm)
    reuse_run_config(cfg, saved, [])
    datamodule = build_datamodule(cfg, pm)
    datamodule.recorded_splits = read_split(run)
    datamodule.setup("fit")
    ckpt = checkpoint_of(run, checkpoint)
    aligners = pm.aligner_classes()
    state = read_checkpoint(ckpt, spec.module, option="run_dir", aligners=aligners)
    aligner = load_checkpoint(spec.module, ckpt, option="run_dir", aligners=aligners).eval()
    trainer = SimpleNamespace(
        datamodule=datamodule,
        global_step=int(state.get("global_step", 0)),
        current_epoch=int(state.get("epoch", 0)),
        callback_metrics={},
    )
    with torch.no_grad():
        content = fit_summary(aligner, trainer, mode=mode)  # type: ignore[arg-type]
    reason = f"computed again from {ckpt.name} of {run.name}, summary={mode}"
    content["metrics"] = {"summary": {"mode": mode, "reason": reason}, **content["metrics"]}
    out.mkdir(parents=True, exist_ok=True)
    return FitSummary(name=saved.model.name).write(trainer, content, out)  # type: ignore[arg-type]


def main() -> None:
    """Compute the summary again and copy the picture."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the run directory of the main job")
    parser.add_argument(
        "out", nargs="?", type=Path, default=ROOT / "docs/assets/vqpae_main_job.png"
    )
    parser.add_argument("--mode", default="full", choices=["full", "quick"])
    args = parser.parse_args()
    written = summary_of_run(args.run, mode=args.mode)
    picture = next(p for p in written if p.name == "vqpae_transfer.png")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with Image.open(picture) as image:  # a 64-colour palette: a third of the size, same look
        image.convert("RGB").quantize(colors=64).save(args.out, optimize=True)
    print(f"{args.out} ({args.out.stat().st_size // 1024} KB); the summary: {picture.parent}")


if __name__ == "__main__":
    main()
