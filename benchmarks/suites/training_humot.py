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
* ``humot_windows_per_cpu_s``: 64 chunks / median process CPU time of a step
  (all threads): other jobs on a shared machine stretch wall time, not this;
  with one thread it is the windows/s of an idle core;
* ``humot_data_share``: share of the wall time spent fetching batches (the gap
  between the end of one step and the start of the next), of the packed network.

Baseline (sizes ``default`` and ``large``): the same steps of the padded
network (``model.fast_path=false``: every block computes on the batch's widest
joint subset, padding included), same weights, data and seed, timed in the
same run after the packed one; its figures are the "before" of issue 28. At
``smoke`` size only the packed network runs (the CI smoke test stays short),
so the figures have no baseline. No implementation of HuMoT is public; the
paper trained on an A100.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.harness import REPO_ROOT, Result, run_child, shared_data
from benchmarks.suites.steptime import accelerators, suffix, time_fit

#: Timed steps per size (after one warm-up step), for each network.
STEPS = {"smoke": 2, "default": 6, "large": 20}

#: Chunks per step: batch 32 (the paper's) x two topologies.
WINDOWS_PER_STEP = 64


def paper_setup(fast_path: bool = True) -> tuple[Any, Any, str]:
    """The paper-size aligner (seed 0) and the data module of the benchmark's two topologies.

    Args:
        fast_path: ``model.fast_path`` (``False``: the padded network).

    Returns:
        ``(HumotAligner, HumotDataModule, description of the data)``.
    """
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
        sources = [
            ProceduralSource(
                kinds=["biped31", "biped22"], gaits=["walk", "run"], clips_per_gait=2, seconds=8.0
            )
        ]
        data = "procedural biped31 + biped22"
    cache = Path(tempfile.gettempdir()) / "skelagnostic-bench-cache"
    dm = HumotDataModule(sources, batch_size=32, val_fraction=0.0, cache_dir=cache)
    torch.manual_seed(0)
    return HumotAligner(fast_path=fast_path), dm, data


def measure(steps: int, accelerator: str = "cpu", fast_path: bool = True) -> dict[str, Any]:
    """Median step time, median data-fetch time and their share over ``steps`` steps."""
    import lightning as L
    import torch

    model, dm, data = paper_setup(fast_path)
    L.seed_everything(0, verbose=False)  # the same subsets and batches for both networks
    timing = time_fit(model, dm, steps, accelerator=accelerator)
    return {
        **timing,
        "data": data,
        "threads": torch.get_num_threads(),
        "parameters": sum(p.numel() for p in model.parameters()),
    }


def run(size: str) -> list[Result]:
    """Steps/s, windows/s and the data-loading share, against the padded network."""
    results = []
    baseline = "padded network (fast_path=false), same run"
    for device in accelerators():
        out, _ = run_child(
            "benchmarks.suites.training_humot:measure", steps=STEPS[size], accelerator=device
        )
        before: dict[str, Any] | None = None
        if size != "smoke":
            before, _ = run_child(
                "benchmarks.suites.training_humot:measure",
                steps=STEPS[size],
                accelerator=device,
                fast_path=False,
            )
        step, tag = out["median_step_s"], suffix(device)
        old = None if before is None else before["median_step_s"]
        name = None if before is None else baseline
        results += [
            Result(
                f"humot_steps_per_s{tag}",
                "steps/s",
                1.0 / step,
                name,
                None if old is None else 1.0 / old,
                higher_is_better=True,
            ),
            Result(
                f"humot_windows_per_s{tag}",
                "windows/s",
                WINDOWS_PER_STEP / step,
                name,
                None if old is None else WINDOWS_PER_STEP / old,
                higher_is_better=True,
            ),
            Result(
                f"humot_windows_per_cpu_s{tag}",
                "windows/CPU-s",
                WINDOWS_PER_STEP / out["median_step_cpu_s"],
                name,
                None if before is None else WINDOWS_PER_STEP / before["median_step_cpu_s"],
                higher_is_better=True,
            ),
            Result(f"humot_data_share{tag}", "fraction", out["data_share"]),
        ]
    return results
