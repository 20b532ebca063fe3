"""Matching frequencies of VQ-PAE transfer measured over longer windows (issue 27).

Usage (from the repository root)::

    .venv/bin/python benchmarks/vqpae_frequency_window.py RUN_DIR/checkpoints/last.ckpt
                     [--variants rule:1 rule:2 phase:2 head_median:2 ...] [--splits val test]
                     [--json OUT.json]

The run directory's ``split.json`` names the clips: the human (first dataset)
clips of the given splits (never trained on) are transferred onto the dog
(second dataset) training clips, as ``vqpae.transfer`` does. Every variant sets
the per-frame frequencies of both sides (query and database) from the same
embedding, then runs the same frequency-scaled matching:

* ``rule``: the transfer's default,
  :func:`~skelagnostic_vqpae.transfer.matching_frequency` (the head, the
  measured phase rate where they differ by more than 5 %) with the phase rate
  measured over the VQ-PAE window of each character; ``rule:W``: the same with
  the phase rate measured over ``W`` seconds (``rule:1`` is ``rule`` for a
  model with 1 s windows, as the authors' settings are);
* ``phase:W``: the measured phase rate over ``W`` seconds everywhere it is
  positive (the head where the phase stands still or runs backwards; ``phase``:
  over the VQ-PAE window);
* ``head_median:W``: the frequency head's estimate, median over ``W`` seconds
  centred on the frame;
* ``feet``: the touch-down rate where a foot steps (the protocol's bound, not a
  method).

Prints, per variant, the rhythm errors (``rhythm_figures``: whole clip and over
the source's walks) per clip and their means per split, and the per-frame error
of each estimate against the feet's touch-down rate on the held-out clips of
both characters. Clips are read from their files and resampled to the model's
frame rate, as the protocol's clips are.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))

import numpy as np  # noqa: E402
import torch  # noqa: E402
from skelagnostic_vqpae.aligner import VqpaeAligner  # noqa: E402
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip  # noqa: E402
from skelagnostic_vqpae.protocols.rhythm import rhythm_figures  # noqa: E402
from skelagnostic_vqpae.transfer import (  # noqa: E402
    build_database,
    matching_frequency,
    phase_rate,
    transfer,
    with_known_frequencies,
)

from skelagnostic.aligners.checkpoints import load_checkpoint  # noqa: E402
from skelagnostic.analysis import touchdown_frequency  # noqa: E402
from skelagnostic.core.motion import Motion  # noqa: E402
from skelagnostic.io import read_bvh  # noqa: E402

DEFAULT_VARIANTS = ["rule", "rule:2", "rule:4", "phase:2", "phase:4", "head_median:2", "feet"]


def median_filter(values: torch.Tensor, frames: int) -> torch.Tensor:
    """Median of ``values`` over ``frames`` frames centred on each frame (cut at the ends)."""
    x = values.double().numpy()
    half = frames // 2
    out = np.array([np.median(x[max(0, i - half) : i + half + 1]) for i in range(len(x))])
    return torch.from_numpy(out).float()


def frequencies(
    variant: str, emb: ClipEmbedding, motion: Motion, vqpae_window: int
) -> torch.Tensor:
    """Per-frame matching frequencies (Hz) of ``variant`` for one embedded clip."""
    kind, _, seconds = variant.partition(":")
    frames = max(2, round(float(seconds) * emb.fps) + 1) if seconds else vqpae_window
    if kind == "rule":
        return matching_frequency(emb, frames)[0]
    if kind == "phase":
        measured = phase_rate(emb.phase, emb.fps, frames)
        return torch.where(measured > 0, measured.float(), emb.frequency.float())
    if kind == "head_median":
        return median_filter(emb.frequency, frames)
    if kind == "feet":
        feet = touchdown_frequency(motion)
        return torch.where(torch.isnan(feet), matching_frequency(emb, vqpae_window)[0], feet)
    raise SystemExit(f"unknown variant {variant!r}")


def estimate_errors(
    variant: str, embs: list[ClipEmbedding], motions: list[Motion], window: int
) -> dict[str, float]:
    """Per-frame ``|estimate / touch-down rate - 1|`` over the frames a foot's stride covers."""
    ratios = []
    for emb, motion in zip(embs, motions, strict=True):
        feet = touchdown_frequency(motion).double().numpy()
        est = frequencies(variant, emb, motion, window).double().numpy()
        keep = np.isfinite(feet)
        ratios.append(est[keep] / feet[keep])
    r = np.concatenate(ratios) if ratios else np.zeros(0)
    err = np.abs(r - 1)
    return {
        "frames": int(r.size),
        "median_ratio": float(np.median(r)) if r.size else math.nan,
        "median_error_pct": 100 * float(np.median(err)) if r.size else math.nan,
        "within_10pct": float(np.mean(err <= 0.1)) if r.size else math.nan,
        "near_half": float(np.mean((r >= 0.4) & (r <= 0.6))) if r.size else math.nan,
    }


def main(argv: list[str] | None = None) -> dict:
    """Run the comparison and print (and return) the summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--variants", nargs="+", default=DEFAULT_VARIANTS)
    parser.add_argument("--splits", nargs="+", default=["val", "test"])
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    model = load_checkpoint(VqpaeAligner, args.checkpoint).eval()
    split = json.loads((args.checkpoint.parent.parent / "split.json").read_text())["clips"]
    human_name, dog_name = model.dataset_names[:2]
    motions = {p: read_bvh(p) for p in sorted(split)}  # each clip read once

    def character(motion: Motion) -> int | None:
        try:
            return model.dataset_of(motion.skeleton)
        except Exception:  # a clip of neither character
            return None

    owner = {p: character(m) for p, m in motions.items()}
    database = [p for p in motions if owner[p] == 1 and split[p] == "train"]
    held = [p for p in motions if owner[p] in (0, 1) and split[p] in args.splits]
    with torch.no_grad():
        fps = embed_clip(model, motions[database[0]]).fps  # the model's: every clip at it
        used = {p: motions[p] for p in [*database, *held]}
        motions = {p: m if m.fps == fps else m.resample(fps) for p, m in used.items()}
        dogs = [motions[p] for p in database]
        target = build_database(model, dogs, [str(d.name) for d in dogs])
        sources = {p: motions[p] for p in held if owner[p] == 0}
        held_dogs = [motions[p] for p in held if owner[p] == 1]
        source_embs = {p: embed_clip(model, m) for p, m in sources.items()}
        dog_embs = [embed_clip(model, m) for m in held_dogs]
        window = {i: int(c.pae.window) for i, c in enumerate(model.characters)}
        summary: dict = {"checkpoint": str(args.checkpoint), "variants": {}}
        print(
            f"{human_name}: {len(sources)} clips ({'/'.join(args.splits)}); "
            f"{dog_name}: {len(dogs)} training clips in the database",
            flush=True,
        )
        for variant in args.variants:
            start = time.perf_counter()
            db_freq = [
                frequencies(variant, e, m, window[1])
                for e, m in zip(target.embeddings, target.motions, strict=True)
            ]
            db = with_known_frequencies(model, target, db_freq)
            rows = {}
            for path, source in sources.items():
                freq = frequencies(variant, source_embs[path], source, window[0])
                out = transfer(model, source, db, frequency=freq).motion
                fig = rhythm_figures(source, out)
                rows[Path(path).name] = {
                    "split": split[path],
                    "whole": fig["contact_rhythm_error_pct"],
                    "walks": fig["locomotion_rhythm_error_pct"],
                }
            means = {}
            for s in [*args.splits, "all"]:
                chosen = [r for r in rows.values() if s in ("all", r["split"])]
                means[s] = {
                    k: float(np.nanmean([r[k] for r in chosen])) if chosen else math.nan
                    for k in ("whole", "walks")
                }
            estimates = {
                human_name: estimate_errors(
                    variant, list(source_embs.values()), list(sources.values()), window[0]
                ),
                dog_name: estimate_errors(variant, dog_embs, held_dogs, window[1]),
            }
            summary["variants"][variant] = {"clips": rows, "mean": means, "estimates": estimates}
            line = ", ".join(f"{s} {m['whole']:.1f}/{m['walks']:.1f}" for s, m in means.items())
            est = ", ".join(
                f"{c} {e['median_error_pct']:.1f}% ({100 * e['within_10pct']:.0f}% <10%)"
                for c, e in estimates.items()
            )
            print(
                f"{variant:>14}: rhythm whole/walks {line} | estimates {est} "
                f"[{time.perf_counter() - start:.0f} s]",
                flush=True,
            )
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1))
    return summary


if __name__ == "__main__":
    main()
