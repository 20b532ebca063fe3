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
docs/methods/humot.md measures 11-13 s per step with one thread on the
project's busy 2-core machine (~0.4 TFLOP per step) and 8.6 s with two
threads on a nearly idle one; the paper trained on an A100.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, Result, run_child

#: Timed steps per size (after one warm-up step); a step takes ~10 s on one core.
STEPS = {"smoke": 2, "default": 6, "large": 20}

#: Chunks per step: batch 32 (the paper's) x two topologies.
WINDOWS_PER_STEP = 64


def _data_root() -> Path | None:
    env = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    root = Path(env) if env else REPO_ROOT.parent / "shared" / "data"
    ok = (root / "human" / "cmu").is_dir() and (root / "human" / "lafan1").is_dir()
    return root if ok else None


def measure(steps: int) -> dict[str, Any]:
    """Median step time, median data-fetch time and their share over ``steps`` steps."""
    sys.path.insert(0, str(REPO_ROOT / "plugins" / "humot" / "src"))
    import lightning as L
    import torch
    from skelagnostic_humot import HumotAligner, HumotDataModule

    from skelagnostic.data import BVHSource, ProceduralSource

    root = _data_root()
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
    compute: list[float] = []
    fetch: list[float] = []

    class Timer(L.Callback):
        end: float | None = None

        def on_train_batch_start(self, *args: Any) -> None:
            self.start = time.perf_counter()
            if self.end is not None:
                fetch.append(self.start - self.end)

        def on_train_batch_end(self, *args: Any) -> None:
            self.end = time.perf_counter()
            compute.append(self.end - self.start)

    torch.manual_seed(0)
    model = HumotAligner()
    with tempfile.TemporaryDirectory() as run_dir:  # the aligner writes its renders here
        trainer = L.Trainer(max_steps=steps + 1, accelerator="cpu", devices=1, logger=False,
                            enable_checkpointing=False, enable_progress_bar=False,
                            enable_model_summary=False, limit_val_batches=0,
                            num_sanity_val_steps=0, callbacks=[Timer()],
                            default_root_dir=run_dir)
        trainer.fit(model, datamodule=dm)
    # the first step is a warm-up; fetch[i] precedes compute[i + 1]
    steps_s = [c + f for c, f in zip(compute[1:], fetch, strict=True)]
    return {"median_step_s": statistics.median(steps_s),
            "data_share": sum(fetch) / (sum(fetch) + sum(compute[1:])),
            "data": data, "threads": torch.get_num_threads(),
            "parameters": sum(p.numel() for p in model.parameters())}


def run(size: str) -> list[Result]:
    """Steps/s, windows/s and the data-loading share of the paper-size training step."""
    out, _ = run_child("benchmarks.suites.training_humot:measure", steps=STEPS[size])
    step = out["median_step_s"]
    return [
        Result("humot_steps_per_s", "steps/s", 1.0 / step, higher_is_better=True),
        Result("humot_windows_per_s", "windows/s", WINDOWS_PER_STEP / step,
               higher_is_better=True),
        Result("humot_data_share", "fraction", out["data_share"]),
    ]
