"""VQ-PAE quality checks on held-out clips (issue 10; not a timed test).

Usage (from the repository root)::

    .venv/bin/python benchmarks/vqpae_quality.py procedural [--steps 1500]
    .venv/bin/python benchmarks/vqpae_quality.py human_dog [--steps 20000] [--no-reinit]
                     [--eval-every 1000] [--num-codes 32]
    .venv/bin/python benchmarks/vqpae_quality.py sweep --codes 8 16 32 64 128 [--steps 5000]

``procedural``: trains on procedural biped22 + quadruped clips (every gait, 30 fps,
1 s windows, the model's default phase-rate loss), then embeds held-out clips
(seeds 1000-1002, one per gait each) whose gait frequency is known and reports,
per clip, the median predicted frequency against the truth (pass: within 5 %)
and the R^2 of a line fitted to the unwrapped phase over time (pass: >= 0.98).
``--lambda-phase-rate 0`` trains with the paper's objective.

``human_dog``: trains on LaFAN1 + MANN dog from ``$SKELAGNOSTIC_TEST_DATA`` (else
``../shared/data``), K = 32, 60 fps, batch 32 per dataset, with the objective of
``experiment=vqpae_human_dog`` (no phase-rate loss unless ``--lambda-phase-rate``), and
reports codebook usage and manifold overlap (paper Table 2) of the per-frame
embeddings of every clip; run it with ``--no-reinit`` for the ablation. Prints a
JSON summary. ``sweep`` trains like ``human_dog`` once per codebook size.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))

import lightning as L  # noqa: E402
import torch  # noqa: E402
from skelagnostic_vqpae.aligner import (  # noqa: E402
    AUTHORS_OPTIMIZER,
    PREVIOUS_DEFAULTS,
    VqpaeAligner,
)
from skelagnostic_vqpae.data import MultiSource, VqpaeDataModule  # noqa: E402
from skelagnostic_vqpae.embed import embed_clip  # noqa: E402
from skelagnostic_vqpae.losses import pivot_mpjpe  # noqa: E402
from skelagnostic_vqpae.protocols.tables import code_overlap, phase_line  # noqa: E402

from skelagnostic import procedural  # noqa: E402
from skelagnostic.aligners import quiet_trainer  # noqa: E402
from skelagnostic.data import BVHSource, ProceduralSource  # noqa: E402


def _aligner(lr: float, restart_period: int, **options: Any) -> VqpaeAligner:
    """The aligner with the settings of the measured runs (docs/reports/vqpae.md).

    They predate the authors' defaults of ``model=vqpae``: ``PREVIOUS_DEFAULTS``
    (``experiment=vqpae_plus`` with the paper's frequency head and the cosine
    schedule, its first cycle ``restart_period`` epochs), AdamW at ``lr``, then ``options``.
    """
    optimizer = {**AUTHORS_OPTIMIZER, "lr": lr}
    scheduler = {**PREVIOUS_DEFAULTS["scheduler"], "period": restart_period}
    return VqpaeAligner(
        **{**PREVIOUS_DEFAULTS, "optimizer": optimizer, "scheduler": scheduler, **options}
    )


def _train(
    dm: VqpaeDataModule,
    model: VqpaeAligner,
    steps: int,
    callbacks: list[L.Callback] | None = None,
    save: Path | None = None,
) -> float:
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = quiet_trainer(
            max_steps=steps,
            accelerator="cpu",
            devices=1,
            limit_val_batches=0,
            num_sanity_val_steps=0,
            callbacks=callbacks,
            default_root_dir=run_dir,
        )
        trainer.fit(model, datamodule=dm)
        seconds = time.perf_counter() - start
        if save is not None:  # a Lightning checkpoint: skelagnostic transfer ckpt=...
            save.parent.mkdir(parents=True, exist_ok=True)
            trainer.save_checkpoint(save)
    return seconds


def phase_linearity(phase: torch.Tensor) -> float:
    """R^2 of a least-squares line through the unwrapped phase (cycles) over frames."""
    return phase_line(phase)[0]


def check_procedural(
    steps: int,
    lr: float,
    fps: float,
    options: dict[str, Any],
    window_seconds: float = 1.0,
    pair_seconds: float = 0.1,
    eval_seeds: tuple[int, ...] = (1000, 1001, 1002),
    clips_per_gait: int = 4,
) -> dict[str, object]:
    """Frequency and phase linearity on held-out procedural gaits."""
    L.seed_everything(0, verbose=False)
    cache = Path(tempfile.gettempdir()) / "skelagnostic-quality-cache"
    source = ProceduralSource(
        kinds=["biped22", "quadruped"], clips_per_gait=clips_per_gait, seconds=8.0
    )
    dm = VqpaeDataModule(
        source,
        fps=fps,
        stride=1,
        batch_size=32,
        cache_dir=cache,
        window_seconds=window_seconds,
        pair_seconds=pair_seconds,
    )
    model = _aligner(num_codes=16, lr=lr, restart_period=10_000, pose_mlp="none", **options)
    seconds = _train(dm, model, steps)
    half = round(fps * window_seconds) // 2
    clips = []
    gaits = [
        (kind, gait, seed)
        for seed in eval_seeds
        for kind, names in (("biped22", ("walk", "run")), ("quadruped", ("walk", "trot", "gallop")))
        for gait in names
    ]
    for kind, gait, seed in gaits:
        motion, info = procedural.generate(kind, gait, seconds=6.0, fps=fps, seed=seed)
        emb = embed_clip(model, motion)
        inner = slice(half, len(emb) - half)  # frames whose window lies inside the clip
        freq = float(emb.frequency[inner].median())
        truth = float(info["frequency"])
        r2, slope = phase_line(emb.phase[inner])
        clips.append(
            {
                "clip": f"{kind}/{gait}",
                "seed": seed,
                "true_hz": round(truth, 4),
                "predicted_hz": round(freq, 4),
                "rel_error": round(abs(freq - truth) / truth, 4),
                "phase_r2": round(r2, 4),
                # how fast the pivot phase actually advances (Hz)
                "phase_hz": round(abs(slope) * fps, 4),
                "pass_frequency": abs(freq - truth) <= 0.05 * truth,
                "pass_phase": r2 >= 0.98,
            }
        )
    passed = sum(c["pass_frequency"] for c in clips)
    return {
        "setting": "procedural",
        "steps": steps,
        "lr": lr,
        "fps": fps,
        "window_seconds": window_seconds,
        "pair_seconds": pair_seconds,
        "clips_per_gait": clips_per_gait,
        **options,
        "train_seconds": round(seconds, 1),
        "frequency_within_5pct": f"{passed}/{len(clips)}",
        "max_rel_error": max(c["rel_error"] for c in clips),
        "min_phase_r2": min(c["phase_r2"] for c in clips),
        "clips": clips,
    }


def _human_dog_sources(human_files: list[str] | None = None) -> tuple[BVHSource, BVHSource]:
    """LaFAN1 (``human_files`` of ``human/lafan1``, default every file) and the MANN dog."""
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    root = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    lafan = root / "human" / "lafan1"
    human = [lafan] if human_files is None else [lafan / name for name in human_files]
    return (
        BVHSource(human, units="cm", name="human"),
        BVHSource([root / "dog" / "mann"], units="cm", name="dog"),
    )


def _human_dog_module(human_files: list[str] | None = None) -> VqpaeDataModule:
    cache = Path(tempfile.gettempdir()) / "skelagnostic-quality-cache"
    return VqpaeDataModule(
        MultiSource(list(_human_dog_sources(human_files))),
        fps=60,
        stride=1,
        batch_size=32,
        cache_dir=cache,
        val_fraction=0.0,
    )


def overlap_of_clips(
    model: VqpaeAligner, num_codes: int, human_files: list[str] | None = None
) -> dict[str, Any]:
    """Usage and overlap (Table 2) of the per-frame codes of every human and dog clip."""
    codes = {}
    with torch.no_grad():
        for src in _human_dog_sources(human_files):
            codes[src.name] = torch.cat([embed_clip(model, src.load(c)).code for c in src.clips()])
    return code_overlap(codes, num_codes)


class OverlapCurve(L.Callback):
    """Print :func:`overlap_of_clips` as a JSON line every ``every`` steps."""

    def __init__(self, every: int, num_codes: int, human_files: list[str] | None = None) -> None:
        self.every, self.num_codes, self.start = every, num_codes, time.perf_counter()
        self.human_files = human_files
        self.points: list[dict[str, Any]] = []

    def on_train_batch_end(self, trainer: L.Trainer, module: Any, *args: Any) -> None:
        if trainer.global_step % self.every:
            return
        module.eval()
        point = {
            "step": trainer.global_step,
            "seconds": round(time.perf_counter() - self.start, 1),
            **overlap_of_clips(module, self.num_codes, self.human_files),
        }
        module.train()
        self.points.append(point)
        print(json.dumps(point), flush=True)


def check_human_dog(
    steps: int,
    reinit: bool,
    lr: float,
    num_codes: int,
    options: dict[str, Any],
    eval_every: int | None = None,
    save: Path | None = None,
    human_files: list[str] | None = None,
) -> dict[str, object]:
    """Codebook usage and manifold overlap of the per-frame embeddings (Table 2)."""
    L.seed_everything(0, verbose=False)
    dm = _human_dog_module(human_files)
    options = {"lambda_phase_rate": 0.0, **options}  # experiment=vqpae_human_dog's objective
    model = _aligner(
        num_codes=num_codes, reinit=reinit, lr=lr, pose_mlp="none", restart_period=10_000, **options
    )
    curve = [OverlapCurve(eval_every, num_codes, human_files)] if eval_every else []
    seconds = _train(dm, model, steps, curve, save)
    model.eval()
    return {
        "setting": "human_dog",
        "reinit": reinit,
        "num_codes": num_codes,
        "steps": steps,
        "lr": lr,
        **options,
        "train_seconds": round(seconds, 1),
        **overlap_of_clips(model, num_codes, human_files),
        "human_files": human_files,
        "curve": curve[0].points if curve else [],
    }


def pose_mpjpe_cm(model: VqpaeAligner, dm: VqpaeDataModule) -> dict[str, float]:
    """Per-frame pose MPJPE (cm) of the average-pose MLPs over every training window."""
    sums = dict.fromkeys(model.dataset_names, 0.0)
    counts = dict.fromkeys(model.dataset_names, 0)
    with torch.no_grad():
        for name, dataset in dm.datasets["train"].items():
            k = model.dataset_names.index(name)
            for start in range(0, len(dataset), 256):  # the windows gather batches in one go
                b = dataset.gather(range(start, min(start + 256, len(dataset))))
                _, params = model.forward_dataset(k, b["features"])
                err = pivot_mpjpe(model.characters[k], params, b["poses"])
                sums[name] += float(err) * len(b["features"])
                counts[name] += len(b["features"])
    return {name: round(100.0 * sums[name] / max(counts[name], 1), 3) for name in sums}


def check_sweep(
    codes: list[int],
    steps: int,
    lr: float,
    options: dict[str, Any],
    human_files: list[str] | None = None,
) -> dict[str, object]:
    """Tables 1-2 shape: overlap and pose MPJPE for every codebook size in ``codes``."""
    rows = []
    options = {"lambda_phase_rate": 0.0, **options}  # experiment=vqpae_human_dog's objective
    for num_codes in codes:
        L.seed_everything(0, verbose=False)
        dm = _human_dog_module(human_files)
        model = _aligner(
            num_codes=num_codes, lr=lr, pose_mlp="detached", restart_period=10_000, **options
        )
        seconds = _train(dm, model, steps)
        model.eval()
        row = {
            "num_codes": num_codes,
            "train_seconds": round(seconds, 1),
            **overlap_of_clips(model, num_codes, human_files),
            "pose_mpjpe_cm": pose_mpjpe_cm(model, dm),
        }
        print(json.dumps(row), flush=True)
        rows.append(row)
    return {
        "setting": "sweep",
        "steps": steps,
        "lr": lr,
        **options,
        "human_files": human_files,
        "rows": rows,
    }


def main() -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("setting", choices=["procedural", "human_dog", "sweep"])
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument(
        "--lr",
        type=float,
        default=None,
        help="learning rate (procedural: 1e-3, human_dog and sweep: 1e-4)",
    )
    parser.add_argument(
        "--eval-every",
        type=int,
        default=None,
        help="human_dog: also report the overlap every N steps",
    )
    parser.add_argument(
        "--codes", type=int, nargs="+", default=[8, 16, 32, 64, 128], help="sweep: codebook sizes"
    )
    parser.add_argument("--num-codes", type=int, default=32)
    parser.add_argument("--no-reinit", action="store_true")
    parser.add_argument(
        "--save",
        type=Path,
        default=None,
        help="human_dog: write the trained model as a Lightning checkpoint",
    )
    parser.add_argument("--fps", type=float, default=30.0, help="procedural frame rate")
    parser.add_argument(
        "--window-seconds",
        type=float,
        default=1.0,
        help="procedural: window length (the paper: 1 s)",
    )
    parser.add_argument(
        "--padding-mode",
        default="replicate",
        help="model.padding_mode (zeros: the authors' convolutions)",
    )
    parser.add_argument(
        "--no-center",
        action="store_true",
        help="model.center_windows=false (reconstruct the window means too)",
    )
    parser.add_argument("--kernel-size", type=int, default=23)
    parser.add_argument(
        "--freq-layers",
        type=int,
        default=5,
        help="model.freq_layers (5 in the paper, 7 in the authors' code)",
    )
    parser.add_argument(
        "--frequency-head",
        default="mlp",
        choices=["mlp", "centroid_residual"],
        help="model.frequency_head (mlp: the paper's head)",
    )
    parser.add_argument(
        "--lambda-phase-rate",
        type=float,
        default=None,
        help="model.lambda_phase_rate (0: the paper, frequency trained by "
        "the reconstruction only; default: the model's 1 for "
        "procedural, 0 for human_dog and sweep like "
        "experiment=vqpae_human_dog)",
    )
    parser.add_argument(
        "--eval-seeds",
        type=int,
        nargs="+",
        default=[1000, 1001, 1002],
        help="procedural: seeds of the held-out clips (one clip per gait each)",
    )
    parser.add_argument(
        "--clips-per-gait",
        type=int,
        default=4,
        help="procedural: training clips per gait (8 s each)",
    )
    parser.add_argument(
        "--pair-seconds",
        type=float,
        default=0.1,
        help="procedural: data.pair_seconds (partner window offset)",
    )
    parser.add_argument(
        "--phase-rate-grad",
        default="network",
        choices=["network", "timing", "head"],
        help="model.phase_rate_grad (what the phase-rate loss trains)",
    )
    parser.add_argument(
        "--human-files",
        nargs="+",
        default=None,
        help="human_dog and sweep: LaFAN1 file names to train on "
        "(default: every file of human/lafan1)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = {
        "padding_mode": args.padding_mode,
        "center_windows": not args.no_center,
        "kernel_size": args.kernel_size,
        "freq_layers": args.freq_layers,
        "frequency_head": args.frequency_head,
        "phase_rate_grad": args.phase_rate_grad,
    }
    if args.lambda_phase_rate is not None:
        options["lambda_phase_rate"] = args.lambda_phase_rate
    if args.setting == "procedural":
        out = check_procedural(
            args.steps or 1500,
            args.lr or 1e-3,
            args.fps,
            options,
            args.window_seconds,
            args.pair_seconds,
            tuple(args.eval_seeds),
            args.clips_per_gait,
        )
    elif args.setting == "human_dog":
        out = check_human_dog(
            args.steps or 20000,
            not args.no_reinit,
            args.lr or 1e-4,
            args.num_codes,
            options,
            args.eval_every,
            args.save,
            args.human_files,
        )
    else:
        out = check_sweep(
            args.codes, args.steps or 5000, args.lr or 1e-4, options, args.human_files
        )
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
