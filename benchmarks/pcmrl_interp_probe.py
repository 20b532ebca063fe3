r"""How fast does PC-MRL's stage-2 model learn beyond LERP? A training probe.

A diagnostic for stage 2 (docs/reports/pcmrl.md, "Learning beyond LERP"):
trains :class:`~skelagnostic_pcmrl.interp.aligner.PcmrlInterpAligner` on the
``--train`` clips for ``--minutes`` (one thread, the training step of ``fit``
without Lightning), and every ``--every`` steps prints, on the fixed windows of
the held-out ``--test`` clips (128 frames, a key every 15 and every 30 frames),
the mean joint position error of the non-key frames, next to the LERP/SLERP
baseline's (the untrained residual model) and their ratio. It also prints the
ratio of the training loss to the baseline's on the same fresh training
batches (moving averages): below 1 means the model learns beyond LERP on its
own training distribution. The last line and ``--json`` hold the final figures.

Model and data options are passed as ``key=value`` (YAML values), e.g.::

    python benchmarks/pcmrl_interp_probe.py \
        --train ../shared/data/human/lafan1/walk4_subject1.bvh \
        --test ../shared/data/human/lafan1/obstacles1_subject5.bvh --units cm --minutes 7 \
        --model interm_tokens=lerp canonical_heading=true lr=3e-3 \
        --data key_mode=regular min_gap=5 max_gap=30
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import torch
import yaml
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plugins" / "pcmrl" / "src"))

#: The CPU configuration of experiment=pcmrl_interp_cpu / pcmrl_interp_cmu.
CPU_MODEL = {"dim": 64, "heads": 4, "layers": 2, "lr": 1e-3, "warmup_steps": 100, "residual": True}
CPU_DATA = {
    "window": 128,
    "batch_size": 8,
    "samples_per_epoch": 512,
    "val_fraction": 0.0,
    "mirror": True,
}
PROBE_GAPS = (15, 30)


def _options(pairs: list[str], flag: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise SystemExit(f"{flag}: expected key=value, got {pair!r}")
        parsed = yaml.safe_load(value)
        if isinstance(parsed, str):  # YAML 1.1 reads 3e-3 (no dot) as a string
            try:
                parsed = float(parsed)
            except ValueError:
                pass
        out[key] = parsed
    return out


def _position_error(model: Any, batch: dict[str, torch.Tensor]) -> tuple[float, int]:
    """Summed mean-joint position error over the non-key frames, and their count."""
    feats, _, pos = model.predict_batch(batch)
    err = (pos - feats["positions"]).norm(dim=-1).mean(-1)
    inner = ~batch["keys"]
    return float((err * inner).sum()), int(inner.sum())


def main(argv: list[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
    from skelagnostic_pcmrl.interp.data import FixedWindows, PcmrlInterpDataModule

    from skelagnostic.data.sources import BVHSource

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--train", nargs="+", required=True, help="training BVH files/dirs")
    parser.add_argument("--test", nargs="+", required=True, help="held-out BVH files/dirs")
    parser.add_argument("--units", default=None, help="units of the BVH files (cm, cmu, m)")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--every", type=int, default=300, help="probe every N steps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", nargs="*", default=[], help="model options key=value")
    parser.add_argument("--data", nargs="*", default=[], help="data options key=value")
    parser.add_argument("--json", default=None, help="write the trajectory here")
    parser.add_argument(
        "--ema",
        type=float,
        default=None,
        help="also probe an EMA of the weights with this decay (e.g. 0.999)",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)

    model_opts = {**CPU_MODEL, **_options(args.model, "--model")}
    data_opts = {**CPU_DATA, "fps": args.fps, "seed": args.seed, **_options(args.data, "--data")}
    train = PcmrlInterpDataModule(
        sources=[BVHSource(paths=args.train, units=args.units)], **data_opts
    )
    train.setup("fit")
    test = PcmrlInterpDataModule(
        sources=[BVHSource(paths=args.test, units=args.units)],
        fps=args.fps,
        window=data_opts["window"],
        val_fraction=0.0,
    )
    test.setup("fit")
    assert train.skeleton is not None and train.train_set is not None
    common = {"skeleton": train.skeleton.to_dict(), "fps": args.fps, "window": data_opts["window"]}
    model = PcmrlInterpAligner(**model_opts, **common)
    baseline_opts = {**model_opts, "residual": True, "interm_tokens": "zero"}
    baseline = PcmrlInterpAligner(**baseline_opts, **common).eval()  # zero residual = LERP
    averaged = None
    if args.ema is not None:
        if not 0.0 < args.ema < 1.0:
            raise SystemExit(f"--ema: the decay must lie in (0, 1), got {args.ema}")
        averaged = AveragedModel(
            model, multi_avg_fn=get_ema_multi_avg_fn(args.ema), use_buffers=True
        )
    optimisers = model.configure_optimizers()
    opt, sched = optimisers["optimizer"], optimisers["lr_scheduler"]["scheduler"]
    probe = {
        gap: list(
            torch.utils.data.DataLoader(
                FixedWindows(test.clips["train"], data_opts["window"], 64, gap), batch_size=32
            )
        )
        for gap in PROBE_GAPS
    }
    if not any(probe.values()):
        raise SystemExit(f"--test: no clip has {data_opts['window']} frames at {args.fps} fps")

    def evaluate(net: Any) -> dict[str, dict[str, float]]:
        net.eval()
        out = {}
        with torch.no_grad():
            for gap, batches in probe.items():
                err = base = count = 0.0
                for batch in batches:
                    e, n = _position_error(net, batch)
                    b, _ = _position_error(baseline, batch)
                    err, base, count = err + e, base + b, count + n
                out[str(gap)] = {
                    "model_m": err / count,
                    "lerp_m": base / count,
                    "ratio": err / base,
                }
        net.train()
        return out

    def evaluate_all() -> dict[str, Any]:
        figures: dict[str, Any] = {"probe": evaluate(model)}
        if averaged is not None:
            figures["probe_ema"] = evaluate(averaged.module)
        return figures

    trajectory = []
    start, step, epoch = time.perf_counter(), 0, 0
    loss_avg = base_avg = None
    batches = iter(train.train_dataloader())
    while time.perf_counter() - start < args.minutes * 60:
        try:
            batch = next(batches)
        except StopIteration:
            epoch += 1
            train.train_set.epoch = epoch
            batches = iter(train.train_dataloader())
            batch = next(batches)
        loss, _ = model._losses(batch)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if averaged is not None:
            averaged.update_parameters(model)
        step += 1
        with torch.no_grad():
            base_loss = baseline._losses(batch)[0].item()
        loss_avg = loss.item() if loss_avg is None else 0.98 * loss_avg + 0.02 * loss.item()
        base_avg = base_loss if base_avg is None else 0.98 * base_avg + 0.02 * base_loss
        if step % args.every == 0:
            figures = evaluate_all()
            trajectory.append(
                {
                    "step": step,
                    "seconds": time.perf_counter() - start,
                    "train_ratio": loss_avg / base_avg,
                    **figures,
                }
            )
            cells = " | ".join(
                f"gap {g}: {f['model_m'] * 100:.2f} cm vs LERP "
                f"{f['lerp_m'] * 100:.2f} cm ({f['ratio']:.3f})"
                for g, f in figures["probe"].items()
            )
            if averaged is not None:
                cells += " | EMA " + " ".join(
                    f"gap {g}: {f['ratio']:.3f}" for g, f in figures["probe_ema"].items()
                )
            print(
                f"step {step} ({time.perf_counter() - start:.0f} s) train loss / LERP "
                f"{loss_avg / base_avg:.3f} | {cells}",
                flush=True,
            )
    final = evaluate_all()
    trajectory.append({"step": step, "seconds": time.perf_counter() - start, **final})
    for key, figures in final.items():
        print(
            "final",
            "EMA" if key == "probe_ema" else "model",
            "step",
            step,
            " ".join(f"gap {g}: {f['ratio']:.4f}" for g, f in figures.items()),
        )
    if args.json:
        Path(args.json).write_text(
            json.dumps({"model": model_opts, "data": data_opts, "trajectory": trajectory}, indent=2)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
