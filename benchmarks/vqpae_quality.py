"""VQ-PAE quality checks on held-out clips (issue 10; not a timed test).

Usage (from the repository root)::

    .venv/bin/python benchmarks/vqpae_quality.py procedural [--steps 1500]
    .venv/bin/python benchmarks/vqpae_quality.py human_dog [--steps 3000] [--no-reinit]

``procedural``: trains on procedural biped22 + quadruped clips (every gait, 30 fps,
1 s windows), then embeds held-out clips (new seeds) whose gait frequency is
known and reports, per clip, the median predicted frequency against the truth
(pass: within 5 %) and the R^2 of a line fitted to the unwrapped phase over
time (pass: >= 0.98).

``human_dog``: trains on LaFAN1 + MANN dog from ``$SKELAGNOSTIC_TEST_DATA`` (else
``../shared/data``), K = 32, 60 fps, batch 32 per dataset, and reports codebook
usage and manifold overlap (paper Table 2) of the per-frame embeddings of every
clip; run it with ``--no-reinit`` for the ablation. Prints a JSON summary.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))

import lightning as L  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from skelagnostic_vqpae.aligner import VQPAEAligner  # noqa: E402
from skelagnostic_vqpae.data import MultiSource, VQPAEDataModule  # noqa: E402
from skelagnostic_vqpae.embed import embed_clip  # noqa: E402

from skelagnostic import procedural  # noqa: E402
from skelagnostic.data import BVHSource, ProceduralSource  # noqa: E402
from skelagnostic.metrics.functional import manifold_overlap  # noqa: E402


def _train(dm: VQPAEDataModule, model: VQPAEAligner, steps: int) -> float:
    start = time.perf_counter()
    trainer = L.Trainer(max_steps=steps, accelerator="cpu", devices=1, logger=False,
                        enable_checkpointing=False, enable_progress_bar=False,
                        enable_model_summary=False, limit_val_batches=0,
                        num_sanity_val_steps=0)
    trainer.fit(model, datamodule=dm)
    return time.perf_counter() - start


def phase_linearity(phase: torch.Tensor) -> float:
    """R^2 of a least-squares line through the unwrapped phase (cycles) over frames."""
    return _phase_line(phase)[0]


def _phase_line(phase: torch.Tensor) -> tuple[float, float]:
    """``(R^2, slope in cycles per frame)`` of a line through the unwrapped phase."""
    unwrapped = np.unwrap(phase.double().numpy() * 2 * math.pi) / (2 * math.pi)
    t = np.arange(len(unwrapped), dtype=np.float64)
    slope, intercept = np.polyfit(t, unwrapped, 1)
    residual = unwrapped - (slope * t + intercept)
    return float(1 - residual.var() / max(unwrapped.var(), 1e-12)), float(slope)


def check_procedural(steps: int, lr: float, fps: float, options: dict[str, Any]
                     ) -> dict[str, object]:
    """Frequency and phase linearity on held-out procedural gaits."""
    L.seed_everything(0, verbose=False)
    cache = Path(tempfile.gettempdir()) / "skelagnostic-quality-cache"
    source = ProceduralSource(kinds=["biped22", "quadruped"], clips_per_gait=4, seconds=8.0)
    dm = VQPAEDataModule(source, fps=fps, stride=1, batch_size=32, cache_dir=cache)
    model = VQPAEAligner(num_codes=16, lr=lr, restart_period=10_000, pose_mlp="none",
                         **options)
    seconds = _train(dm, model, steps)
    half = int(fps) // 2
    clips = []
    for kind, gaits in (("biped22", ("walk", "run")), ("quadruped", ("walk", "trot", "gallop"))):
        for gait in gaits:
            motion, info = procedural.generate(kind, gait, seconds=6.0, fps=fps, seed=1000)
            emb = embed_clip(model, motion)
            inner = slice(half, len(emb) - half)  # frames whose window lies inside the clip
            freq = float(emb.frequency[inner].median())
            truth = float(info["frequency"])
            r2, slope = _phase_line(emb.phase[inner])
            clips.append({"clip": f"{kind}/{gait}", "true_hz": round(truth, 4),
                          "predicted_hz": round(freq, 4),
                          "rel_error": round(abs(freq - truth) / truth, 4),
                          "phase_r2": round(r2, 4),
                          # how fast the pivot phase actually advances (Hz)
                          "phase_hz": round(abs(slope) * fps, 4),
                          "pass_frequency": abs(freq - truth) <= 0.05 * truth,
                          "pass_phase": r2 >= 0.98})
    return {"setting": "procedural", "steps": steps, "lr": lr, "fps": fps, **options,
            "train_seconds": round(seconds, 1), "clips": clips}


def check_human_dog(steps: int, reinit: bool, lr: float, num_codes: int,
                    options: dict[str, Any]) -> dict[str, object]:
    """Codebook usage and manifold overlap of the per-frame embeddings (Table 2)."""
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    root = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    human = BVHSource([root / "human" / "lafan1"], units="cm", name="human")
    dog = BVHSource([root / "dog" / "mann"], units="cm", name="dog")
    L.seed_everything(0, verbose=False)
    cache = Path(tempfile.gettempdir()) / "skelagnostic-quality-cache"
    dm = VQPAEDataModule(MultiSource([human, dog]), fps=60, stride=1, batch_size=32,
                         cache_dir=cache, val_fraction=0.0)
    model = VQPAEAligner(num_codes=num_codes, reinit=reinit, lr=lr, pose_mlp="none",
                         restart_period=10_000, **options)
    seconds = _train(dm, model, steps)
    codes = []
    for src in (human, dog):
        codes.append(torch.cat([embed_clip(model, src.load(c)).code for c in src.clips()]))
    overlap = manifold_overlap(codes, num_codes)
    return {"setting": "human_dog", "reinit": reinit, "num_codes": num_codes, "steps": steps,
            "lr": lr, **options, "train_seconds": round(seconds, 1), **overlap,
            "codes_used": [int(c.unique().numel()) for c in codes]}


def main() -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("setting", choices=["procedural", "human_dog"])
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--num-codes", type=int, default=32)
    parser.add_argument("--no-reinit", action="store_true")
    parser.add_argument("--fps", type=float, default=30.0, help="procedural frame rate")
    parser.add_argument("--padding-mode", default="replicate",
                        help="model.padding_mode (zeros: the authors' convolutions)")
    parser.add_argument("--no-center", action="store_true",
                        help="model.center_windows=false (reconstruct the window means too)")
    parser.add_argument("--kernel-size", type=int, default=23)
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = {"padding_mode": args.padding_mode, "center_windows": not args.no_center,
               "kernel_size": args.kernel_size}
    if args.setting == "procedural":
        out = check_procedural(args.steps or 1500, args.lr, args.fps, options)
    else:
        out = check_human_dog(args.steps or 3000, not args.no_reinit, args.lr, args.num_codes,
                              options)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
