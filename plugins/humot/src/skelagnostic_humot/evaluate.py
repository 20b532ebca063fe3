"""HuMoT evaluations (Sec. 4) on 1 s chunks of held-out clips, as JSON and plots.

* :func:`reconstruction` (Table 2): MPJPE (cm) and MPJPE / height of
  encode-decode on the clip's own template, with three baselines that use
  the ground truth: the chunk's mean pose, the neutral template at the chunk
  centre, and the chunk's mean root-relative pose carried along the true root
  trajectory (which leaves only the limb motion to explain).
* :func:`denoising_curve` (Fig. 8): Gaussian noise of standard deviation
  ``sigma`` added to every coordinate; MPJPE of the noisy input and of its
  reconstruction, both against the clean chunk.
* :func:`upsampling_curve` (Fig. 9): a random share of joints is kept (at
  least two), encoded with the subset template and decoded with the full one;
  MPJPE on all joints.

``python -m skelagnostic_humot.evaluate CKPT --group NAME A.bvh ... [--group ...] --out DIR``
writes ``DIR/humot_eval.json``, ``DIR/denoising.png`` and ``DIR/upsampling.png``.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic.core.motion import UNITS, Motion
from skelagnostic_humot.aligner import HumotAligner, infer_units
from skelagnostic_humot.data import Topology, gather_subset, prepare_chunks

__all__ = ["chunks_of", "denoising_curve", "main", "reconstruction", "upsampling_curve"]


def chunks_of(motion: Motion, chunk: int = 30, units: str | None = None) -> torch.Tensor:
    """Non-overlapping ``[C, chunk, J, 3]`` world positions (metres) of a motion at 30 fps."""
    unit = infer_units(motion.skeleton, units or motion.units)
    if motion.fps != 30.0:
        motion = motion.resample(30.0)
    pos = motion.global_positions().float() * UNITS[unit]
    count = pos.shape[0] // chunk
    return pos[: count * chunk].reshape(count, chunk, *pos.shape[1:])


def _mpjpe(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per-chunk MPJPE ``[C]``."""
    return (a - b).norm(dim=-1).mean(dim=(1, 2))


@torch.no_grad()
def _run(model: HumotAligner, pos: torch.Tensor, src_tmpl: torch.Tensor,
         dst_tmpl: torch.Tensor, batch: int = 16, src_mask: torch.Tensor | None = None
         ) -> torch.Tensor:
    outs = []
    for i in range(0, len(pos), batch):
        sl = slice(i, i + batch)
        m = None if src_mask is None else src_mask[sl]
        outs.append(model.net(pos[sl], src_tmpl[sl], dst_tmpl[sl], m))
    return torch.cat(outs)


def reconstruction(model: HumotAligner, chunks: torch.Tensor, topology: Topology,
                   up_axis: str = "y") -> dict[str, float]:
    """Encode-decode MPJPE on the chunks' own templates, with static baselines.

    Returns:
        ``mpjpe_cm``, ``mpjpe_std_cm`` (over chunks), ``mpjpe_over_height``, the
        baselines ``mean_pose_cm`` (the chunk's temporal mean pose), ``template_cm``
        (the template at the chunk centre) and ``mean_pose_on_trajectory_cm`` (the
        temporal mean of the root-relative pose plus the true root position of each
        frame), ``chunks``.
    """
    pos, tmpl = prepare_chunks(chunks, topology, up_axis)
    rec = _run(model, pos, tmpl, tmpl)
    err = _mpjpe(rec, pos)
    mean_pose = pos.mean(dim=1, keepdim=True).expand_as(pos)
    centre = pos[:, :, topology.major].mean(dim=(1, 2), keepdim=True) if bool(
        topology.major.any()) else pos.mean(dim=(1, 2), keepdim=True)
    tmpl_pose = (tmpl - tmpl[:, topology.major].mean(dim=1, keepdim=True))[:, None] + centre
    root = pos[:, :, :1]
    on_trajectory = (pos - root).mean(dim=1, keepdim=True) + root
    height = float((tmpl[..., 2].amax(-1) - tmpl[..., 2].amin(-1)).mean())
    return {
        "mpjpe_cm": 100 * float(err.mean()),
        "mpjpe_std_cm": 100 * float(err.std()) if len(err) > 1 else 0.0,
        "mpjpe_over_height": float(err.mean()) / height,
        "mean_pose_cm": 100 * float(_mpjpe(mean_pose, pos).mean()),
        "template_cm": 100 * float(_mpjpe(tmpl_pose.expand_as(pos), pos).mean()),
        "mean_pose_on_trajectory_cm": 100 * float(_mpjpe(on_trajectory, pos).mean()),
        "chunks": len(pos),
    }


def denoising_curve(model: HumotAligner, chunks: torch.Tensor, topology: Topology,
                    sigmas_cm: Sequence[float] = (0, 1, 2, 4, 6, 8, 10), up_axis: str = "y",
                    seed: int = 0) -> dict[str, list[float]]:
    """Fig. 8: MPJPE (cm) of noisy inputs and of their reconstructions, per noise level."""
    pos, tmpl = prepare_chunks(chunks, topology, up_axis)
    gen = torch.Generator().manual_seed(seed)
    noisy_err, out_err = [], []
    for sigma in sigmas_cm:
        noisy = pos + torch.randn(pos.shape, generator=gen) * sigma / 100
        noisy_err.append(100 * float(_mpjpe(noisy, pos).mean()))
        out_err.append(100 * float(_mpjpe(_run(model, noisy, tmpl, tmpl), pos).mean()))
    return {"sigma_cm": list(map(float, sigmas_cm)), "input_mpjpe_cm": noisy_err,
            "output_mpjpe_cm": out_err}


def upsampling_curve(model: HumotAligner, chunks: torch.Tensor, topology: Topology,
                     fractions: Sequence[float] = (1.0, 0.8, 0.6, 0.5, 0.4, 0.3, 0.2),
                     up_axis: str = "y", seed: int = 0) -> dict[str, list[float]]:
    """Fig. 9: MPJPE (cm) on all joints when only a random share of joints is encoded."""
    pos, tmpl = prepare_chunks(chunks, topology, up_axis)
    gen = torch.Generator().manual_seed(seed)
    num = pos.shape[2]
    errors = []
    for frac in fractions:
        keep_n = max(2, round(frac * num))
        keep = torch.zeros(len(pos), num, dtype=torch.bool)
        for i in range(len(pos)):
            keep[i, torch.randperm(num, generator=gen)[:keep_n]] = True
        sub = gather_subset(keep, topology.skeleton.parents)
        out = _run(model, sub.take(pos, 2), sub.take(tmpl, 1), tmpl, src_mask=sub.mask)
        errors.append(100 * float(_mpjpe(out, pos).mean()))
    return {"fraction": list(map(float, fractions)), "mpjpe_cm": errors}


def evaluate_clips(model: HumotAligner, groups: dict[str, list[Motion]]) -> dict[str, Any]:
    """All three evaluations for each named group of clips (one topology per group)."""
    results: dict[str, Any] = {}
    for name, motions in groups.items():
        chunks = torch.cat([chunks_of(m, model.hparams.chunk) for m in motions])
        sk = motions[0].skeleton
        topo = model.topology(sk)
        results[name] = {
            "joints": sk.num_joints,
            "reconstruction": reconstruction(model, chunks, topo, sk.up_axis),
            "denoising": denoising_curve(model, chunks, topo, up_axis=sk.up_axis),
            "upsampling": upsampling_curve(model, chunks, topo, up_axis=sk.up_axis),
        }
    return results


def plot_results(results: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write ``denoising.png`` and ``upsampling.png`` (one line per group)."""
    from skelagnostic.viz import plot_metric_curves

    out_dir.mkdir(parents=True, exist_ok=True)
    den = {f"{n} (output)": (r["denoising"]["input_mpjpe_cm"], r["denoising"]["output_mpjpe_cm"])
           for n, r in results.items()}
    first = next(iter(results.values()))["denoising"]["input_mpjpe_cm"]
    den["identity (no denoising)"] = (first, first)
    plot_metric_curves(None, den, xlabel="MPJPE of noisy input (cm)",
                       ylabel="MPJPE after HuMoT (cm)", title="Denoising (paper Fig. 8)",
                       out=out_dir / "denoising.png")
    up = {n: (r["upsampling"]["fraction"], r["upsampling"]["mpjpe_cm"])
          for n, r in results.items()}
    plot_metric_curves(None, up, xlabel="share of input joints", ylabel="MPJPE (cm)",
                       title="Joint upsampling (paper Fig. 9)", out=out_dir / "upsampling.png")
    return [out_dir / "denoising.png", out_dir / "upsampling.png"]


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: evaluate a checkpoint on seen and unseen clips (see the module notes)."""
    from skelagnostic.io.bvh import read_bvh

    parser = argparse.ArgumentParser(prog="python -m skelagnostic_humot.evaluate")
    parser.add_argument("checkpoint")
    parser.add_argument("--group", nargs="+", action="append", required=True,
                        metavar=("NAME", "BVH"),
                        help="a name and the BVH clips of one topology (repeatable)")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    model = HumotAligner.load_from_checkpoint(args.checkpoint, map_location="cpu").eval()
    groups = {g[0]: [read_bvh(p) for p in g[1:]] for g in args.group}
    results = evaluate_clips(model, groups)
    out = Path(args.out)
    plot_results(results, out)
    (out / "humot_eval.json").write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps({n: r["reconstruction"] for n, r in results.items()}, indent=2))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
