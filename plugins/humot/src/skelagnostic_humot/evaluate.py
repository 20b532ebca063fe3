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
  MPJPE on all joints, against the share kept and the number removed.
* :func:`retargeting_procedural` (Sec. 4.2; the paper's Tables 3-5 need
  paired data the project does not have): the procedural generator plays the
  same gait with the same parameters (seed) on every human topology, so the
  clip generated on the target topology is the ground truth of retargeting the
  clip generated on the source topology. MPJPE of :meth:`HumotAligner.retarget`
  (positions -> rotations by IK, what a user gets) divided by the target's
  height, next to :func:`name_copy_retarget`.
* :func:`name_copy_retarget`: the baseline, a naive retargeter that copies the
  local rotation of the source joint with the closest name (after removing
  side words and namespaces) onto each target joint and scales the root
  trajectory by the leg-length ratio (HuMoT's rule, App. A.6). Caveat: the
  procedural ground truth is itself made by driving corresponding joints with
  the same local rotations, so this baseline is exact between procedural rigs
  whose names match (biped22 <-> biped31) and only the topology with other
  names (biped17) tests it.
* :func:`cycle_error`: for real clips without paired ground truth,
  source -> other rig -> source, MPJPE / height, for HuMoT and the baseline.

``python -m skelagnostic_humot.evaluate CKPT --group NAME[:UNITS] A.bvh ... [--group ...]
[--cycle-via B.bvh ...] [--procedural] --out DIR`` writes ``DIR/humot_eval.json``,
``DIR/denoising.png`` and ``DIR/upsampling.png`` (see :func:`main`).
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic import procedural
from skelagnostic.aligners.checkpoints import load_checkpoint
from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import UNITS, Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic_humot.aligner import HumotAligner, infer_units, leg_length
from skelagnostic_humot.data import Topology, gather_subset, prepare_chunks

__all__ = [
    "chunks_of",
    "cycle_error",
    "denoising_curve",
    "evaluate_clips",
    "evaluate_procedural",
    "main",
    "name_copy_retarget",
    "name_match",
    "reconstruction",
    "retargeting_procedural",
    "upsampling_curve",
]

#: Procedural human topologies (22, 31 and 17 joints).
HUMAN_KINDS: tuple[str, ...] = ("biped22", "biped31", "biped17")

#: Base seed of held-out procedural clips: training uses seeds 0 up to the clip count.
HELD_OUT_SEED = 1000


def chunks_of(motion: Motion, chunk: int = 30, units: str | None = None) -> torch.Tensor:
    """Non-overlapping ``[C, chunk, J, 3]`` world positions (metres) of a motion at 30 fps."""
    motion = motion.to_metres(units)
    if motion.fps != 30.0:
        motion = motion.resample(30.0)
    pos = motion.global_positions().float()
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
    removed = [num - max(2, round(f * num)) for f in fractions]
    return {"fraction": list(map(float, fractions)), "removed_joints": removed,
            "mpjpe_cm": errors}


# ------------------------------------------------------------------ retargeting
_SIDE = re.compile(r"(left|right)")


def _normalise_name(name: str) -> str:
    """Lower case, without namespaces (``mixamorig:``) and with ``left/right`` -> ``l/r``."""
    base = name.rsplit(":", 1)[-1].rsplit("|", 1)[-1].lower()
    base = _SIDE.sub(lambda m: m.group(1)[0], base)
    return re.sub(r"[^a-z0-9]", "", base)


def name_match(source: Skeleton, target: Skeleton, cutoff: float = 0.6) -> list[int | None]:
    """For each target joint, the source joint with the most similar name (or ``None``).

    Names are compared after :func:`_normalise_name` with :class:`difflib.SequenceMatcher`
    (ratio >= ``cutoff``); a match must be on the same side (its normalised name starts
    with the same ``l``/``r`` letter or neither does). The roots always match.
    """
    src = [_normalise_name(n) for n in source.joint_names]

    def side(n: str) -> str:
        return n[0] if len(n) > 1 and n[0] in "lr" and not n.startswith(("low", "leg")) else ""

    out: list[int | None] = []
    for j, name in enumerate(target.joint_names):
        if j == 0:
            out.append(0)
            continue
        t = _normalise_name(name)
        best, best_ratio = None, cutoff
        for i, s in enumerate(src):
            if i == 0 or side(s) != side(t):
                continue
            ratio = difflib.SequenceMatcher(None, s, t).ratio()
            if ratio > best_ratio or (ratio == best_ratio and best is None):
                best, best_ratio = i, ratio
        out.append(best)
    return out


def _leg_metres(skeleton: Skeleton, unit: float) -> float:
    """Hip-knee-ankle leg length of ``skeleton``'s rest pose, in metres (0 without legs)."""
    template = Topology.of(skeleton).templates(skeleton.bone_lengths().float() * unit)
    return leg_length(template, skeleton)


def name_copy_retarget(motion: Motion, target: Skeleton, source_units: str | None = None,
                       target_units: str | None = None) -> Motion:
    """Baseline retargeting: copy local rotations by joint name, scale the root trajectory.

    Each target joint takes the local rotation of the source joint
    :func:`name_match` pairs it with (identity without a match); the root
    positions are scaled by the target/source leg-length ratio (in metres; the
    height ratio for skeletons without legs), as HuMoT scales its trajectory,
    and converted to the target's units. The result is at 30 fps like
    :meth:`HumotAligner.retarget`.
    """
    src_unit = UNITS[infer_units(motion.skeleton, source_units or motion.units)]
    dst_unit = UNITS[infer_units(target, target_units)]
    if motion.fps != 30.0:
        motion = motion.resample(30.0)
    match = name_match(motion.skeleton, target)
    rot = Q.identity(motion.num_frames, target.num_joints, dtype=motion.rotations.dtype)
    for j, i in enumerate(match):
        if i is not None:
            rot[:, j] = motion.rotations[:, i]
    src_leg, dst_leg = _leg_metres(motion.skeleton, src_unit), _leg_metres(target, dst_unit)
    if src_leg > 0 and dst_leg > 0:
        ratio = dst_leg / src_leg
    else:
        ratio = (target.height() * dst_unit) / max(motion.skeleton.height() * src_unit, 1e-9)
    root = motion.root_positions * (src_unit * ratio / dst_unit)
    return Motion(target, rot, root.to(rot.dtype), 30.0)


def _motion_error(pred: Motion, truth: Motion) -> dict[str, float]:
    """MPJPE (truth's units) and MPJPE / height, globally and with the roots aligned."""
    if pred.skeleton.joint_names != truth.skeleton.joint_names:
        raise SkelagnosticError("retargeting error: prediction and ground truth have different "
                                "joints")
    frames = min(pred.num_frames, truth.num_frames)
    a = pred.global_positions()[:frames].double()
    b = truth.global_positions()[:frames].double()
    height = truth.skeleton.height()
    err = float((a - b).norm(dim=-1).mean())
    local = float(((a - a[:, :1]) - (b - b[:, :1])).norm(dim=-1).mean())
    return {"mpjpe": err, "mpjpe_over_height": err / height,
            "root_aligned_mpjpe": local, "root_aligned_over_height": local / height}


def retargeting_procedural(model: HumotAligner, kinds: Sequence[str] = HUMAN_KINDS,
                           gaits: Sequence[str] = ("walk", "run"), clips_per_gait: int = 2,
                           seconds: float = 6.0, seed: int = HELD_OUT_SEED
                           ) -> dict[str, dict[str, float]]:
    """Retargeting error between procedural topologies against generated ground truth.

    For every ordered pair ``A -> B`` of ``kinds`` and every (gait, clip) the
    clip generated on ``A`` is retargeted onto the skeleton of the clip
    generated with the same gait and seed (so the same body size, frequency,
    amplitudes, phase and turn rate) on ``B``, which is the ground truth.

    Returns:
        ``"A->B" -> {humot_*, name_copy_*}`` with the keys of the error (``mpjpe``
        in cm, ``mpjpe_over_height``, ``root_aligned_mpjpe``,
        ``root_aligned_over_height``), averaged over clips, plus ``clips``;
        and ``"mean"``, the average over pairs.
    """
    clips = {k: procedural.dataset(kinds=(k,), gaits=tuple(gaits),
                                   clips_per_gait=clips_per_gait, seconds=seconds, seed=seed)
             for k in kinds}
    out: dict[str, dict[str, float]] = {}
    for a in kinds:
        for b in kinds:
            if a == b:
                continue
            sums: dict[str, float] = {}
            for (src, _), (truth, _) in zip(clips[a], clips[b], strict=True):
                for method, pred in (
                    ("humot", model.retarget(src, truth.skeleton, "cm", "cm")),
                    ("name_copy", name_copy_retarget(src, truth.skeleton, "cm", "cm")),
                ):
                    for key, value in _motion_error(pred, truth).items():
                        sums[f"{method}_{key}"] = sums.get(f"{method}_{key}", 0.0) + value
            count = len(clips[a])
            out[f"{a}->{b}"] = {k: v / count for k, v in sums.items()} | {"clips": count}
    keys = [k for k in next(iter(out.values())) if k != "clips"]
    out["mean"] = {k: sum(r[k] for r in out.values()) / len(out) for k in keys}
    return out


def cycle_error(model: HumotAligner, motion: Motion, via: Skeleton,
                units: str | None = None, via_units: str | None = None) -> dict[str, float]:
    """Source -> ``via`` -> source retargeting error, for HuMoT and the name-copy baseline.

    Real clips have no paired ground truth on another rig; the cycle back to
    the source rig has. The reference is the source clip at 30 fps.

    Returns:
        ``humot_*`` and ``name_copy_*`` errors (see :func:`retargeting_procedural`;
        ``mpjpe`` in the source's units).
    """
    unit = infer_units(motion.skeleton, units or motion.units)
    truth = motion.resample(30.0) if motion.fps != 30.0 else motion
    results: dict[str, float] = {}
    humot = model.retarget(model.retarget(motion, via, unit, via_units), motion.skeleton,
                           via_units, unit)
    copy = name_copy_retarget(name_copy_retarget(motion, via, unit, via_units),
                              motion.skeleton, via_units, unit)
    for method, pred in (("humot", humot), ("name_copy", copy)):
        for key, value in _motion_error(pred, truth).items():
            results[f"{method}_{key}"] = value
    return results


def evaluate_clips(model: HumotAligner, groups: dict[str, list[Motion]],
                   cycle_via: Sequence[Skeleton] = (), units: dict[str, str] | None = None
                   ) -> dict[str, Any]:
    """Reconstruction and both curves for each named group of clips (one topology per group).

    Args:
        model: The model.
        groups: ``name -> clips`` of one skeleton topology.
        cycle_via: Also measure :func:`cycle_error` of every clip through the first of
            these skeletons whose topology differs from the group's.
        units: ``name -> length unit`` of a group's files (default: guessed).

    Raises:
        SkelagnosticError: A group is empty or mixes topologies.
    """
    results: dict[str, Any] = {}
    for name, motions in groups.items():
        if not motions:
            raise SkelagnosticError(f"--group {name}: no clips")
        sk = motions[0].skeleton
        for m in motions[1:]:
            if m.skeleton.topology_key() != sk.topology_key():
                raise SkelagnosticError(f"--group {name}: clip {m.name!r} has another topology "
                                        f"than {motions[0].name!r}; one topology per group")
        unit = (units or {}).get(name)
        chunks = torch.cat([chunks_of(m, model.hparams.chunk, unit) for m in motions])
        topo = model.topology(sk)
        results[name] = {
            "joints": sk.num_joints,
            "clips": [m.name for m in motions],
            "reconstruction": reconstruction(model, chunks, topo, sk.up_axis),
            "denoising": denoising_curve(model, chunks, topo, up_axis=sk.up_axis),
            "upsampling": upsampling_curve(model, chunks, topo, up_axis=sk.up_axis),
        }
        via = next((v for v in cycle_via if v.topology_key() != sk.topology_key()), None)
        if via is not None:
            cycles = [cycle_error(model, m, via, unit) for m in motions]
            results[name]["cycle"] = {k: sum(c[k] for c in cycles) / len(cycles)
                                      for k in cycles[0]}
            results[name]["cycle"]["via"] = via.name or f"{via.num_joints} joints"
    return results


def evaluate_procedural(model: HumotAligner, kinds: Sequence[str] = HUMAN_KINDS,
                        clips_per_gait: int = 2, seconds: float = 6.0,
                        seed: int = HELD_OUT_SEED) -> dict[str, Any]:
    """Held-out procedural clips (walk and run, seeds from ``seed``): every evaluation.

    Returns:
        ``{"kinds": <evaluate_clips result per kind>, "retargeting":
        <retargeting_procedural result>}``.
    """
    groups = {k: [m for m, _ in procedural.dataset(kinds=(k,), gaits=("walk", "run"),
                                                     clips_per_gait=clips_per_gait,
                                                     seconds=seconds, seed=seed)]
              for k in kinds}
    return {"kinds": evaluate_clips(model, groups, units=dict.fromkeys(kinds, "cm")),
            "retargeting": retargeting_procedural(model, kinds, clips_per_gait=clips_per_gait,
                                                  seconds=seconds, seed=seed)}


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
    plot_metric_curves(None, up, xlabel="proportion of input joints", ylabel="MPJPE (cm)",
                       title="Joint upsampling (paper Fig. 9)", out=out_dir / "upsampling.png")
    return [out_dir / "denoising.png", out_dir / "upsampling.png"]


def _group_arg(values: list[str]) -> tuple[str, str | None, list[str]]:
    name, _, unit = values[0].partition(":")
    return name, unit or None, values[1:]


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: evaluate a checkpoint on real and/or procedural clips.

    ``--group NAME[:UNITS] A.bvh ...`` (repeatable) names the clips of one
    topology (``UNITS``: e.g. ``cmu``, ``cm``; default: guessed from the height);
    ``--cycle-via B.bvh`` (repeatable) adds :func:`cycle_error` through the first
    of these skeletons whose topology differs from the group's;
    ``--procedural`` adds :func:`evaluate_procedural`. Writes
    ``OUT/humot_eval.json`` and the curves ``OUT/denoising.png``,
    ``OUT/upsampling.png`` (and ``OUT/procedural_*.png``).
    """
    from skelagnostic.io.bvh import read_bvh

    parser = argparse.ArgumentParser(prog="python -m skelagnostic_humot.evaluate")
    parser.add_argument("checkpoint")
    parser.add_argument("--group", nargs="+", action="append", default=[],
                        metavar=("NAME[:UNITS]", "BVH"),
                        help="a name and the BVH clips of one topology (repeatable)")
    parser.add_argument("--cycle-via", metavar="BVH", action="append", default=[],
                        help="also retarget each clip to this BVH's skeleton and back "
                             "(repeatable: the first one of another topology is used)")
    parser.add_argument("--procedural", action="store_true",
                        help="also evaluate held-out procedural humans (seeds from 1000)")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    if not args.group and not args.procedural:
        parser.error("give at least one --group or --procedural")
    for g in args.group:
        if len(g) < 2:
            parser.error(f"--group {g[0]}: give a name and at least one BVH file")
    model = load_checkpoint(HumotAligner, args.checkpoint, option="checkpoint").eval()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"checkpoint": str(args.checkpoint)}
    if args.group:
        parsed = [_group_arg(g) for g in args.group]
        groups = {n: [read_bvh(p) for p in paths] for n, _, paths in parsed}
        units = {n: u for n, u, _ in parsed if u}
        via = [read_bvh(p).skeleton for p in args.cycle_via]
        results["groups"] = evaluate_clips(model, groups, via, units)
        plot_results(results["groups"], out)
    if args.procedural:
        results["procedural"] = evaluate_procedural(model)
        plot_results(results["procedural"]["kinds"], out / "procedural")
    (out / "humot_eval.json").write_text(json.dumps(results, indent=2) + "\n")
    summary = {n: r["reconstruction"] for n, r in results.get("groups", {}).items()}
    if "procedural" in results:
        summary["procedural_retargeting_mean"] = results["procedural"]["retargeting"]["mean"]
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
