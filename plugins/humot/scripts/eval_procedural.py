"""Reconstruction MPJPE of a HuMoT checkpoint on held-out procedural humans, with baselines.

The clips come from :func:`skelagnostic.procedural.dataset` with base seed 1000, far from
the seeds of the training clips of ``experiment=humot_quick`` (0 up to the number of
clips). Usage:
    python plugins/humot/scripts/eval_procedural.py CKPT [OUT.json]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluate import chunks_of, reconstruction

from skelagnostic import procedural


def main() -> None:
    """Print (and optionally write) per-topology reconstruction results as JSON."""
    model = HumotAligner.load_from_checkpoint(sys.argv[1], map_location="cpu").eval()
    results = {}
    for kind in ("biped22", "biped31", "biped17"):
        clips = procedural.dataset(kinds=(kind,), gaits=("walk", "run"), clips_per_gait=2,
                                   seconds=6.0, seed=1000)
        chunks = torch.cat([chunks_of(m, model.hparams.chunk) for m, _ in clips])
        sk = clips[0][0].skeleton
        results[kind] = reconstruction(model, chunks, model.topology(sk), sk.up_axis)
    text = json.dumps(results, indent=2)
    print(text)
    if len(sys.argv) > 2:
        Path(sys.argv[2]).write_text(text + "\n")


if __name__ == "__main__":
    main()
