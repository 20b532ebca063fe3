"""Suite ``training`` (HuMoT part): training throughput of the paper-size network on CPU.

The paper's settings (App. A.3-A.5): the 2.36 M-parameter network, batch 32
chunks per topology, 1 s chunks at 30 Hz (``window=30``, ``stride=6``),
stochastic joint subsampling, MSE + 0.5 x bone-length consistency, Adam with
the triangular cyclic learning rate; the full Lightning training step on two
topologies (CMU-31 and LaFAN1-22 clips from ``$SKELAGNOSTIC_TEST_DATA`` or
``../shared/data``; procedural biped31 + biped22 when the clips are absent).

* ``humot_steps_per_s``: training steps (one batch per topology) per second,
  from the median step time (``on_train_batch_start`` -> ``on_train_batch_end``
  plus the data fetch before it);
* ``humot_windows_per_s``: 64 chunks per step / median step time;
* ``humot_data_share``: share of the wall time spent fetching batches (the gap
  between the end of one step and the start of the next).

No baseline column: no implementation of HuMoT is public. For orientation,
docs/reports/humot.md measures 11-13 s per step with one thread on the
project's busy 2-core machine (~0.4 TFLOP per step) and 8.6 s with two
threads on a nearly idle one; the paper trained on an A100.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.steptime import accelerators, suffix, time_fit

#: Timed steps per size (after one warm-up step); a step takes ~10 s on one core.
STEPS = {"smoke": 2, "default": 6, "large": 20}

#: Chunks per step: batch 32 (the paper's) x two topologies.
WINDOWS_PER_STEP = 64


def measure(steps: int, accelerator: str = "cpu") -> dict[str, Any]:
    """Median step time, median data-fetch time and their share over ``steps`` steps."""
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "humot" / "src"))
    import torch
    from skelagnostic_humot import HumotAligner, HumotDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    root = shared_data("human/cmu", "human/lafan1")
    if root is not None:
        human = root / "human"
        sources: list[Any] = [
            BVHSource([human / "cmu" / "131_01.bvh"], units="cmu", name="cmu"),
            BVHSource([human / "lafan1" / "walk4_subject1.bvh"], units="cm", name="lafan1"),
        ]
        data = "CMU-31 (131_01) + LaFAN1-22 (walk4_subject1)"
    else:
        sources = [ProceduralSource(kinds=["biped31", "biped22"], gaits=["walk", "run"],
                                    clips_per_gait=2, seconds=8.0)]
        data = "procedural biped31 + biped22"
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    dm = HumotDataModule(sources, batch_size=32, val_fraction=0.0, cache_dir=cache)
    torch.manual_seed(0)
    model = HumotAligner()
    timing = time_fit(model, dm, steps, accelerator=accelerator)
    return {**timing, "data": data, "threads": torch.get_num_threads(),
            "parameters": sum(p.numel() for p in model.parameters())}


def run(size: str) -> list[Result]:
    """Steps/s, windows/s and the data-loading share of the paper-size training step."""
    results = []
    for device in accelerators():
        out, _ = run_child("benchmarks.suites.training_humot:measure", steps=STEPS[size],
                           accelerator=device)
        step, tag = out["median_step_s"], suffix(device)
        results += [
            Result(f"humot_steps_per_s{tag}", "steps/s", 1.0 / step, higher_is_better=True),
            Result(f"humot_windows_per_s{tag}", "windows/s", WINDOWS_PER_STEP / step,
                   higher_is_better=True),
            Result(f"humot_data_share{tag}", "fraction", out["data_share"]),
        ]
    return results
