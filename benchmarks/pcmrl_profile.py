r"""Profile of one PC-MRL training step (stage 1 and stage 2): top operators, FLOPs vs peak.

The step of ``benchmarks/suites/training_pcmrl.py`` (the full Lightning training
step: forward, backward, AdamW) at the paper's settings (``--preset paper``) or
at the 2-CPU-hour presets' model and batch (``--preset cpu2h``), built by
:func:`benchmarks.suites.training_pcmrl.setup`. After ``--warmup`` steps,
``--steps`` steps are timed (median wall and process CPU time), one more step
counts its floating-point operations (:class:`torch.utils.flop_counter.FlopCounterMode`:
matrix products and attention, forward and backward; element-wise work is not
counted) and one more is recorded by :mod:`torch.profiler`; the operators with
the largest self CPU time are printed as a Markdown table (docs/reports/performance.md,
"PC-MRL training step").

The same run times a large single-precision matrix product (``torch.mm`` of
``--peak-size`` square matrices, the median of a few) as the machine's sgemm
peak at the same thread count, and reports the step's achieved GFLOP/s (counted
FLOPs over the median CPU time of a step) as a fraction of it: how far any exact
speed-up of the step can go while it does the same arithmetic.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/pcmrl_profile.py --stage recon --steps 2
    OMP_NUM_THREADS=1 python benchmarks/pcmrl_profile.py --stage interp --preset cpu2h
    OMP_NUM_THREADS=1 python benchmarks/pcmrl_profile.py --stage interp --reference

The results are written as JSON (``--out``, default
``benchmarks/results/pcmrl_profile.json``; one entry per stage and preset, and
``/reference`` for stage 2 with ``--reference``, merged into the file's previous entries).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.harness import REPO_ROOT
from benchmarks.suites.steptime import time_fit
from benchmarks.suites.training_pcmrl import PRESETS, setup

#: Default JSON output.
OUT = REPO_ROOT / "benchmarks" / "results" / "pcmrl_profile.json"


def sgemm_peak(size: int = 2048, repeats: int = 5) -> float:
    """Median GFLOP/s of ``torch.mm`` on two ``size x size`` float32 matrices.

    Args:
        size: Matrix side.
        repeats: Timed products (after one untimed).

    Returns:
        ``2 size^3`` over the median CPU time of one product, in GFLOP/s.
    """
    a, b = torch.randn(size, size), torch.randn(size, size)
    torch.mm(a, b)
    times = []
    for _ in range(repeats):
        start = time.process_time()
        torch.mm(a, b)
        times.append(time.process_time() - start)
    return 2 * size**3 / statistics.median(times) / 1e9


def profile_step(
    stage: str,
    preset: str,
    batch: int | None,
    warmup: int,
    steps: int,
    rows: int,
    **model_options: Any,
) -> dict[str, Any]:
    """Time, count and profile the training steps of one stage.

    Args:
        stage: ``"recon"`` or ``"interp"``.
        preset: One of :data:`~benchmarks.suites.training_pcmrl.PRESETS`.
        batch: Windows per step (``None``: the preset's).
        warmup: Untimed steps first.
        steps: Timed steps.
        rows: Operators kept in the table.
        **model_options: More constructor options of the aligner.

    Returns:
        The step's figures and its top operators (see :func:`main`).
    """
    import lightning as L
    from torch.profiler import ProfilerActivity, profile
    from torch.utils.flop_counter import FlopCounterMode

    model, dm, data = setup(stage, batch, preset, **model_options)
    wall: list[float] = []
    cpu: list[float] = []
    counted: dict[str, Any] = {}
    timed_end = warmup + steps

    class Probe(L.Callback):
        """Times the steps after the warm-up, then counts FLOPs of one and profiles one."""

        mode: Any = None
        start = (0.0, 0.0)

        def on_train_batch_start(self, trainer: Any, *args: Any) -> None:
            step = trainer.global_step
            if step == timed_end:
                self.mode = FlopCounterMode(display=False)
            elif step == timed_end + 1:
                self.mode = profile(activities=[ProfilerActivity.CPU], with_flops=True)
            if self.mode is not None:
                self.mode.__enter__()
            self.start = (time.perf_counter(), time.process_time())

        def on_train_batch_end(self, trainer: Any, *args: Any) -> None:
            w, c = time.perf_counter() - self.start[0], time.process_time() - self.start[1]
            step = trainer.global_step - 1  # the optimiser step has counted this batch
            if warmup <= step < timed_end:
                wall.append(w)
                cpu.append(c)
            if self.mode is not None:
                self.mode.__exit__(None, None, None)
                key = "flops" if step == timed_end else "profile"
                counted[key] = self.mode
                self.mode = None

    # the Lightning run of the training suite; its own medians would include the two
    # instrumented steps, so the probe's are used
    time_fit(model, dm, steps + 2, warmup=warmup, callbacks=[Probe()])
    flops = counted["flops"].get_total_flops()
    by_op = {str(k): int(v) for k, v in counted["flops"].get_flop_counts()["Global"].items()}
    events = sorted(counted["profile"].key_averages(), key=lambda e: -e.self_cpu_time_total)
    total = sum(e.self_cpu_time_total for e in events)
    windows = int(dm.batch_size)
    median_cpu = statistics.median(cpu)
    return {
        "stage": stage,
        "preset": preset,
        "data": data,
        "model_options": {k: v for k, v in model_options.items()},
        "windows_per_step": windows,
        "parameters": sum(p.numel() for p in model.parameters()),
        "threads": torch.get_num_threads(),
        "steps": steps,
        "median_step_wall_s": statistics.median(wall),
        "median_step_cpu_s": median_cpu,
        "windows_per_cpu_s": windows / median_cpu,
        "flops_per_step": flops,
        "flops_by_operator": dict(sorted(by_op.items(), key=lambda kv: -kv[1])),
        "achieved_gflops_per_cpu_s": flops / median_cpu / 1e9,
        "profiled_step_self_cpu_s": total / 1e6,
        "top_operators": [
            {
                "operator": e.key,
                "self_cpu_s": e.self_cpu_time_total / 1e6,
                "share": e.self_cpu_time_total / total,
                "calls": e.count,
            }
            for e in events[:rows]
        ],
    }


def table(result: dict[str, Any]) -> str:
    """The Markdown report of one :func:`profile_step` result."""
    lines = [
        f"stage: {result['stage']}; preset: {result['preset']}; data: {result['data']}; "
        f"options: {result['model_options'] or 'defaults'}; threads: {result['threads']}",
        f"step ({result['windows_per_step']} windows): median wall "
        f"{result['median_step_wall_s']:.2f} s, median CPU {result['median_step_cpu_s']:.2f} s "
        f"over {result['steps']} step(s); {result['windows_per_cpu_s']:.2f} windows/CPU-s",
        f"FLOPs per step: {result['flops_per_step'] / 1e9:.1f} GFLOP; achieved "
        f"{result['achieved_gflops_per_cpu_s']:.1f} GFLOP/CPU-s = "
        f"{100 * result['fraction_of_peak']:.0f} % of the sgemm peak "
        f"({result['sgemm_peak_gflops']:.1f} GFLOP/s)",
        "",
        "| operator | self CPU (s) | share | calls |",
        "|---|---:|---:|---:|",
    ]
    lines += [
        f"| `{op['operator']}` | {op['self_cpu_s']:.2f} | {100 * op['share']:.1f} % | "
        f"{op['calls']} |"
        for op in result["top_operators"]
    ]
    lines.append(f"| total (profiled step) | {result['profiled_step_self_cpu_s']:.2f} | 100 % | |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Profile the requested stages and presets, print the tables, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stage", choices=("recon", "interp", "both"), default="both")
    parser.add_argument("--preset", choices=(*PRESETS, "both"), default="paper")
    parser.add_argument("--batch", type=int, default=None, help="windows per step")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--warmup", type=int, default=1, help="untimed steps first")
    parser.add_argument("--steps", type=int, default=2, help="timed steps before the profile")
    parser.add_argument("--rows", type=int, default=12, help="operators in the table")
    parser.add_argument("--peak-size", type=int, default=2048, help="side of the sgemm timing")
    parser.add_argument("--out", type=Path, default=OUT, help="JSON file (merged)")
    parser.add_argument(
        "--reference",
        action="store_true",
        help="stage 2: model.fast_path=false (the network that encodes every frame)",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    stages = ("recon", "interp") if args.stage == "both" else (args.stage,)
    presets = PRESETS if args.preset == "both" else (args.preset,)
    peak = sgemm_peak(args.peak_size)
    print(f"sgemm peak ({args.peak_size}^2 torch.mm, {args.threads} thread(s)): {peak:.1f} GFLOP/s")
    previous = json.loads(args.out.read_text()) if args.out.exists() else {}
    for stage in stages:
        options = {"fast_path": False} if args.reference and stage == "interp" else {}
        for preset in presets:
            result = profile_step(
                stage, preset, args.batch, args.warmup, args.steps, args.rows, **options
            )
            result["sgemm_peak_gflops"] = peak
            result["fraction_of_peak"] = result["achieved_gflops_per_cpu_s"] / peak
            result["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
            print("\n" + table(result))
            previous[f"{stage}/{preset}" + ("/reference" if options else "")] = result
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(previous, indent=2) + "\n")
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
