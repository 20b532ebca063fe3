"""Write the main job's picture shown in the README (docs/assets/vqpae_main_job.png).

Takes the run directory of `skelagnostic fit model=vqpae experiment=vqpae_main`,
computes its end-of-fit summary again from `checkpoints/last.ckpt` (the run's
config.yaml and split.json give the same clips:
skelagnostic_vqpae.fit_outputs.summary_of_run) into `<run>/summary_again/`, and
copies its `vqpae_transfer.png` (held-out human clip, the dog's VQ-PAE transfer
and the two baselines at one scale, the feet's strides over time) to OUT, in a
64-colour palette to keep the README light.

Usage: python scripts/vqpae_main_picture.py RUN_DIR [OUT.png] [--mode full|quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image
from skelagnostic_vqpae.fit_outputs import summary_of_run

ROOT = Path(__file__).resolve().parents[1]


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
