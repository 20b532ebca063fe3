"""Matching periods of VQ-PAE transfer: frequency head vs measured phase rate (issue 26, item 3).

Usage (from the repository root)::

    .venv/bin/python benchmarks/vqpae_period_rule.py CHECKPOINT [--seeds 100 101 102]
                     [--fps 30] [--seconds 8] [--tolerances 0.02 0.05 0.1 0.2]

Embeds procedural clips of every gait of the checkpoint's biped22 and quadruped
characters (seeds not used in training: the generator's default data uses 0-19)
and compares, per frame, three estimates of the stride frequency with the
generator's true one: the frequency head, the measured phase rate
(:func:`skelagnostic_vqpae.transfer.phase_rate` over the VQ-PAE window) and the
rule of :func:`skelagnostic_vqpae.transfer.matching_frequency` at each tolerance.
Prints a JSON summary: mean and 95th percentile of ``|f / f_true - 1|`` in %,
separately for the periodic gaits and for idling.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))

import numpy as np  # noqa: E402
import torch  # noqa: E402
from skelagnostic_vqpae.aligner import VqpaeAligner  # noqa: E402
from skelagnostic_vqpae.embed import embed_clip  # noqa: E402
from skelagnostic_vqpae.transfer import matching_frequency, phase_rate  # noqa: E402

from skelagnostic import procedural  # noqa: E402


def main(argv: list[str] | None = None) -> dict[str, dict[str, dict[str, float]]]:
    """Run the comparison and print (and return) the summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102])
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--tolerances", type=float, nargs="+", default=[0.02, 0.05, 0.1, 0.2])
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    model = VqpaeAligner.load_from_checkpoint(args.checkpoint, map_location="cpu")
    errors: dict[str, dict[str, list[np.ndarray]]] = {}
    for kind in ("biped22", "quadruped"):
        for gait in procedural.GAITS["biped" if kind.startswith("biped") else kind]:
            for seed in args.seeds:
                clip, info = procedural.generate(
                    kind, gait, seconds=args.seconds, fps=args.fps, seed=seed
                )
                emb = embed_clip(model, clip)
                window = int(model.characters[model.dataset_of(clip.skeleton)].pae.window)
                truth = float(info["frequency"])
                estimates = {
                    "head": emb.frequency.double().numpy(),
                    "phase_rate": phase_rate(emb.phase, emb.fps, window).numpy(),
                }
                for tol in args.tolerances:
                    used, _ = matching_frequency(emb, window, tol)
                    estimates[f"rule_{tol:g}"] = used.double().numpy()
                group = errors.setdefault("idle" if gait == "idle" else "periodic", {})
                for name, values in estimates.items():
                    group.setdefault(name, []).append(np.abs(values / truth - 1))
    summary = {
        group: {
            name: {
                "mean_pct": round(100 * float(np.concatenate(v).mean()), 2),
                "p95_pct": round(100 * float(np.percentile(np.concatenate(v), 95)), 2),
            }
            for name, v in estimates.items()
        }
        for group, estimates in errors.items()
    }
    print(
        json.dumps({"checkpoint": str(args.checkpoint), "seeds": args.seeds, **summary}, indent=1)
    )
    return summary


if __name__ == "__main__":
    main()
