r"""PC-MRL stage 2: the keyframe fast path against the reference network, step by step.

Both networks (``model.fast_path=true``, the default, and ``false``) are built by
the training suite's setup, seeded as it seeds them, and train on the same
windows and keyframes (checked per step: keyframe positions and a checksum of the
windows; the script stops if they differ), at the paper's settings
(:func:`benchmarks.suites.training_pcmrl.setup`, ``--preset paper``) or the
2-CPU-hour preset's. For every training step the script reports the keyframes
per window, the floating-point operations of both networks
(:class:`torch.utils.flop_counter.FlopCounterMode`: matrix products and
attention, forward and backward) and the process CPU time of the full Lightning
step (forward, backward, AdamW). The FLOP ratio is what the fast path saves on
that batch; the CPU-time ratio is what it delivers. Counting and timing are
separate runs, so the counter's dispatch overhead does not enter the times.

The fast path saves work in proportion to the frames that are not keyframes,
so a ratio measured on two steps depends on how many keyframes those steps
drew (5-36 per 128-frame window by default): the medians here are over
``--steps`` steps of the same batches on both sides.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/pcmrl_fastpath.py --steps 8 --json out.json
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

from benchmarks.suites.steptime import time_fit
from benchmarks.suites.training_pcmrl import PRESETS, setup


def run(preset: str, batch: int | None, steps: int, fast_path: bool, count: bool) -> list[dict]:
    """Per-step keyframes and CPU seconds (``count=False``) or FLOPs (``count=True``).

    Args:
        preset: One of :data:`~benchmarks.suites.training_pcmrl.PRESETS`.
        batch: Windows per step (``None``: the preset's).
        steps: Training steps after one warm-up step.
        fast_path: The aligner's ``fast_path``.
        count: Count FLOPs instead of timing.

    Returns:
        One dict per step after the warm-up: ``keys`` (mean keyframes per window),
        ``batch`` (the keyframe positions and a checksum of the windows' rotations,
        to check that two runs drew the same batches) and ``cpu_s`` or ``flops``.
    """
    import lightning as L
    from torch.utils.flop_counter import FlopCounterMode

    model, dm, _ = setup("interp", batch, preset, fast_path=fast_path)
    L.seed_everything(0, verbose=False)
    rows: list[dict[str, Any]] = []

    class Probe(L.Callback):
        """Keyframes and CPU time (or FLOPs) of every step."""

        mode: Any = None
        start = 0.0

        def on_train_batch_start(self, trainer: Any, module: Any, batch: Any, *args: Any) -> None:
            rows.append(
                {
                    "keys": float(batch["keys"].sum(-1).float().mean()),
                    # which windows and keyframes: both runs of a comparison must draw the same
                    "batch": (
                        batch["keys"].nonzero().tolist(),
                        float(batch["global_rotations"].double().sum()),
                    ),
                }
            )
            if count:
                self.mode = FlopCounterMode(display=False)
                self.mode.__enter__()
            self.start = time.process_time()

        def on_train_batch_end(self, *args: Any) -> None:
            rows[-1]["cpu_s"] = time.process_time() - self.start
            if count:
                self.mode.__exit__(None, None, None)
                rows[-1]["flops"] = int(self.mode.get_total_flops())

    time_fit(model, dm, steps, warmup=1, callbacks=[Probe()])
    return rows[1:]


def main(argv: list[str] | None = None) -> int:
    """Run both networks, print the per-step table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=PRESETS, default="paper")
    parser.add_argument("--batch", type=int, default=None, help="windows per step")
    parser.add_argument("--steps", type=int, default=8, help="steps after one warm-up step")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    side: dict[str, list[dict]] = {}
    for name, fast in (("fast", True), ("reference", False)):
        timed = run(args.preset, args.batch, args.steps, fast, count=False)
        counted = run(args.preset, args.batch, args.steps, fast, count=True)
        if [r["batch"] for r in timed] != [r["batch"] for r in counted]:
            raise RuntimeError("the timed and the counted runs drew different batches")
        side[name] = [
            {"keys": t["keys"], "batch": t["batch"], "cpu_s": t["cpu_s"], "flops": c["flops"]}
            for t, c in zip(timed, counted, strict=True)
        ]
    if [r["batch"] for r in side["fast"]] != [r["batch"] for r in side["reference"]]:
        raise RuntimeError("the two networks drew different batches")
    steps = []
    print(
        "| step | keyframes / window | GFLOP fast | GFLOP reference | FLOP ratio "
        "| CPU s fast | CPU s reference | CPU ratio |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for i, (f, r) in enumerate(zip(side["fast"], side["reference"], strict=True)):
        row = {
            "step": i + 1,
            "keys": f["keys"],
            "flops_fast": f["flops"],
            "flops_reference": r["flops"],
            "flop_ratio": r["flops"] / f["flops"],
            "cpu_s_fast": f["cpu_s"],
            "cpu_s_reference": r["cpu_s"],
            "cpu_ratio": r["cpu_s"] / f["cpu_s"],
        }
        steps.append(row)
        print(
            f"| {row['step']} | {row['keys']:.1f} | {f['flops'] / 1e9:.0f} | "
            f"{r['flops'] / 1e9:.0f} | {row['flop_ratio']:.2f} | {f['cpu_s']:.2f} | "
            f"{r['cpu_s']:.2f} | {row['cpu_ratio']:.2f} |"
        )
    summary = {
        "median_flop_ratio": statistics.median(s["flop_ratio"] for s in steps),
        "median_cpu_ratio": statistics.median(s["cpu_ratio"] for s in steps),
        "total_flop_ratio": sum(s["flops_reference"] for s in steps)
        / sum(s["flops_fast"] for s in steps),
        "total_cpu_ratio": sum(s["cpu_s_reference"] for s in steps)
        / sum(s["cpu_s_fast"] for s in steps),
    }
    print("\n" + ", ".join(f"{k} {v:.2f}" for k, v in summary.items()))
    if args.json is not None:
        out = {
            "preset": args.preset,
            "threads": args.threads,
            "steps": steps,
            **summary,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
