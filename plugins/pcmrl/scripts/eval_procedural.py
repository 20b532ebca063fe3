"""Table 2 protocol on held-out procedural clips (biped22 walk + run, seeds 100-101) -> biped31.

Usage::

    python plugins/pcmrl/scripts/eval_procedural.py RUN/checkpoints/last.ckpt OUT.json
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def main(ckpt: str, out: str) -> None:
    """Evaluate ``ckpt`` and the name-copy baseline; print the table, write JSON."""
    from skelagnostic_pcmrl.evaluate import evaluate_clips, format_table
    from skelagnostic_pcmrl.recon import PcmrlReconstruction

    from skelagnostic import procedural
    from skelagnostic.aligners.checkpoints import load_checkpoint

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = load_checkpoint(PcmrlReconstruction, ckpt, option="ckpt").eval()
    clips = [procedural.generate("biped22", gait, seconds=4.0, seed=100 + i)[0]
             for i, gait in enumerate(["walk", "run"])]
    result = evaluate_clips(clips, procedural.skeleton("biped31"), model)
    result["checkpoint"] = ckpt
    print(format_table(result))
    Path(out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
