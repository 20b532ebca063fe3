"""Suite ``training`` (VQ-PAE part): training throughput at the authors' settings.

Two datasets (LaFAN1 human + MANN dog from ``$SKELAGNOSTIC_TEST_DATA`` or
``../shared/data``; procedural biped + quadruped when the clips are absent),
batch 32 per dataset, 1 s windows at 60 fps (T = 61), K = 32, the full Lightning
training step (data loading, both VQ-PAEs, codebook re-initialisation, AdamW,
scheduler) on CPU:

* ``vqpae_windows_per_s_pose``: with the average-pose MLPs trained alongside
  (``pose_mlp="joint"``, as the authors' trainer does);
* ``vqpae_windows_per_s_nopose``: without them (``pose_mlp="none"``);
* ``vqpae_windows_per_s_pose_phase_rate`` / ``_nopose_phase_rate``: the same with
  the phase-rate loss (``lambda_phase_rate=1``, not in the paper), which also
  encodes every window's partner.

The first two run with ``lambda_phase_rate=0``, the authors' objective.

plus ``vqpae_data_share_pose`` / ``_nopose``, the share of the step time spent
fetching batches. Windows/s = 64 windows per step / median step time (compute
and the data fetch before it, :mod:`benchmarks.suites.steptime`). There is no baseline
column: the authors' trainer cannot be run here, and the harness only compares
against baselines measured in the same run. For orientation, issue 10 reports
the authors' trainer on this class of 2-core machine at a median 5.0 it/s
(320 windows/s) with its pose decoder and 16 it/s (1024 windows/s) without.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.steptime import accelerators, suffix, time_fit

STEPS = {"smoke": 15, "default": 60, "large": 200}


def measure(pose_mlp: str, steps: int, accelerator: str = "cpu",
            lambda_phase_rate: float = 0.0) -> dict[str, Any]:
    """Median training-step time (seconds) of ``steps`` steps after 5 warm-up steps."""
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "vqpae" / "src"))
    from skelagnostic_vqpae.aligner import PREVIOUS_DEFAULTS, VqpaeAligner
    from skelagnostic_vqpae.data import MultiSource, VqpaeDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    root = shared_data("dog/mann")
    if root is not None:
        human = BVHSource([root / "human" / "lafan1" / "Lafan1_example.bvh",
                           root / "human" / "lafan1" / "walk4_subject1.bvh"], units="cm",
                          name="human")
        dog = BVHSource([root / "dog" / "mann"], units="cm", name="dog")
        source: Any = MultiSource([human, dog])
        data = "LaFAN1 (2 clips) + MANN dog (8 clips)"
    else:
        source = ProceduralSource(kinds=["biped22", "quadruped"], seconds=20.0)
        data = "procedural biped22 + quadruped"
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    # partner windows only where the loss uses them (the presets without it set 0 too)
    dm = VqpaeDataModule(source, fps=60, stride=1, batch_size=32, cache_dir=cache,
                         pair_seconds=0.1 if lambda_phase_rate > 0 else 0.0)
    # the settings of the recorded throughput (docs/reports/vqpae.md, section 12)
    model = VqpaeAligner(**{**PREVIOUS_DEFAULTS, "num_codes": 32, "pose_mlp": pose_mlp,
                            "lambda_phase_rate": lambda_phase_rate})
    timing = time_fit(model, dm, steps, warmup=5, accelerator=accelerator)
    return {**timing, "data": data, "threads": __import__("torch").get_num_threads()}


def run(size: str) -> list[Result]:
    """Windows/s with and without the pose MLPs (on the CPU, and a GPU when present)."""
    steps = STEPS[size]
    results = []
    for device in accelerators():
        for mode, label, rate in (("joint", "pose", 0.0), ("none", "nopose", 0.0),
                                  ("joint", "pose_phase_rate", 1.0),
                                  ("none", "nopose_phase_rate", 1.0)):
            out, _ = run_child("benchmarks.suites.training_vqpae:measure", pose_mlp=mode,
                               steps=steps, accelerator=device, lambda_phase_rate=rate)
            tag = f"{label}{suffix(device)}"
            results.append(Result(
                f"vqpae_windows_per_s_{tag}", "windows/s", 64.0 / out["median_step_s"],
                higher_is_better=True))
            results.append(Result(f"vqpae_data_share_{tag}", "fraction", out["data_share"]))
    return results
