r"""Profile of one HuMoT training step at the paper's settings: the top operators.

The step of ``benchmarks/suites/training_humot.py`` (paper-size network, batch
32 chunks of 30 frames per topology, CMU-31 + LaFAN1-22 clips or the
procedural fallback, joint subsampling, both losses, Adam) run outside
Lightning: forward, backward and optimiser step on the first training batch.
After ``--warmup`` steps, ``--steps`` steps are timed (median wall and CPU
time) and one more is recorded by :mod:`torch.profiler`; the operators with
the largest self CPU time are printed as a Markdown table (docs/reports/performance.md,
"HuMoT training step").

Usage::

    python benchmarks/humot_profile.py --threads 1            # the packed network
    python benchmarks/humot_profile.py --threads 1 --padded   # fast_path=false
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.suites.training_humot import paper_setup


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--padded", action="store_true", help="model.fast_path=false")
    parser.add_argument("--warmup", type=int, default=1, help="untimed steps first")
    parser.add_argument("--steps", type=int, default=2, help="timed steps before the profile")
    parser.add_argument("--rows", type=int, default=12, help="operators in the table")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    model, dm, data = paper_setup(fast_path=not args.padded)
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))[0]
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-4)
    topologies = {n: model.topology(dm.skeletons[n]) for n in batch}

    def step() -> None:
        optimizer.zero_grad()
        losses = [
            model.chunk_loss(b["features"], topologies[n], dm.skeletons[n].up_axis)["loss"]
            for n, b in batch.items()
        ]
        torch.stack(losses).mean().backward()
        optimizer.step()

    for _ in range(args.warmup):
        step()
    wall, cpu = [], []
    for _ in range(args.steps):
        w, c = time.perf_counter(), time.process_time()
        step()
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        step()
    events = sorted(prof.key_averages(), key=lambda e: -e.self_cpu_time_total)
    total = sum(e.self_cpu_time_total for e in events)
    print(
        f"data: {data}; network: {'padded' if args.padded else 'packed'}; threads: {args.threads}"
    )
    print(
        f"step: median wall {statistics.median(wall):.2f} s, "
        f"median CPU {statistics.median(cpu):.2f} s over {args.steps} step(s)\n"
    )
    print("| operator | self CPU (s) | share | calls |")
    print("|---|---:|---:|---:|")
    for e in events[: args.rows]:
        print(
            f"| `{e.key}` | {e.self_cpu_time_total / 1e6:.2f} | "
            f"{100 * e.self_cpu_time_total / total:.1f} % | {e.count} |"
        )
    print(f"| total (profiled step) | {total / 1e6:.2f} | 100 % | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
