"""HuMoT evaluations (Sec. 4) on 1 s chunks of held-out clips, and its two protocols.

Protocols (``skelagnostic evaluate model=humot ckpt_path=... [protocol=...]``):

* ``humot.reconstruction`` (the default, :func:`reconstruction_protocol`): per
  held-out human clip, :func:`reconstruction` (Table 2: encode-decode MPJPE on
  the clip's own template) beside the mean-pose baselines of
  :mod:`skelagnostic.baselines`; the denoising (Fig. 8) and joint-upsampling
  (Fig. 9) curves over all chunks go into ``extra`` and two plots.
* ``humot.retarget`` (:func:`retarget_protocol`): per held-out human clip, the
  cycle error (source -> a procedural rig of another topology -> source) of
  HuMoT beside the :func:`~skelagnostic.baselines.name_copy`,
  :func:`~skelagnostic.baselines.primal_copy` and
  :func:`~skelagnostic.baselines.direction_copy` baselines; ``extra`` adds
  :func:`retargeting_procedural` (paired procedural ground truth).

Functions:

* :func:`reconstruction` (Table 2): MPJPE (cm) and MPJPE / height of
  encode-decode on the clip's own template, with three baselines that use
  the ground truth: the chunk's mean pose, the neutral template at the chunk
  centre, and the chunk's mean root-relative pose carried along the true root
  trajectory (which leaves only the limb motion to explain).
* :func:`denoising_curve` (Fig. 8): Gaussian noise of standard deviation
  ``sigma`` added to every coordinate; MPJPE of the noisy input and of its
  reconstruction, both against the clean chunk. :func:`denoising_figures`
  turns a curve into the two numbers a target can be set on (issue #45): the
  share of the levels from 4 cm of noise up where the output error stays below
  the noisy input's, and the output error's growth over the noise range
  divided by the input's, for the model and for the identity (output = noisy
  input: 0 and 1).
* :func:`upsampling_curve` (Fig. 9): a random share of joints is kept (at
  least two), encoded with the subset template and decoded with the full one;
  MPJPE on all joints, against the share kept and the number removed.
* :func:`retargeting_procedural` (Sec. 4.2; the paper's Tables 3-5 need
  paired data the project does not have): the procedural generator plays the
  same gait with the same parameters (seed) on every human topology, so the
  clip generated on the target topology is the ground truth of retargeting the
  clip generated on the source topology. MPJPE of :meth:`HumotAligner.retarget`
  (positions -> rotations by IK, what a user gets) divided by the target's
  height, next to the name-copy and primal-copy baselines. Caveat: the
  procedural ground truth is itself made by driving corresponding joints with
  the same local rotations, so with the roots aligned the name copy is exact
  between procedural rigs whose names match (biped22 <-> biped31; its root path
  follows the copies' root rule, :func:`skelagnostic.baselines.scaled_root`,
  not the generated one) and only the topology with other names (biped17)
  tests it.
* :func:`cycle_error`: for real clips without paired ground truth,
  source -> other rig -> source, MPJPE / height, for HuMoT and the baselines.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic import procedural
from skelagnostic.baselines import (
    direction_copy,
    mean_pose,
    mean_pose_on_trajectory,
    name_copy,
    primal_copy,
)
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import MODEL, Evaluation, EvaluationError, HeldOut, mean_rows
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import Topology, gather_subset, prepare_chunks

__all__ = [
    "BASELINES",
    "chunks_of",
    "cycle_error",
    "denoising_curve",
    "denoising_figures",
    "evaluate_clips",
    "evaluate_procedural",
    "extra_clips",
    "mean_denoising_curve",
    "paired_by_method",
    "reconstruction",
    "reconstruction_protocol",
    "retarget_protocol",
    "retargeting_procedural",
    "topology_status",
    "trained_hierarchies",
    "upsampling_curve",
]

#: Procedural human topologies (22, 31 and 17 joints).
HUMAN_KINDS: tuple[str, ...] = ("biped22", "biped31", "biped17")

#: Base seed of held-out procedural clips: training uses seeds 0 up to the clip count.
HELD_OUT_SEED = 1000

#: Noise level (sigma, cm) from which a denoised output must stay below its noisy input.
DENOISING_FROM_CM = 4.0


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
def _run(
    model: HumotAligner,
    pos: torch.Tensor,
    src_tmpl: torch.Tensor,
    dst_tmpl: torch.Tensor,
    batch: int = 16,
    src_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    outs = []
    for i in range(0, len(pos), batch):
        sl = slice(i, i + batch)
        m = None if src_mask is None else src_mask[sl]
        outs.append(model.net(pos[sl], src_tmpl[sl], dst_tmpl[sl], m))
    return torch.cat(outs)


def reconstruction(
    model: HumotAligner, chunks: torch.Tensor, topology: Topology, up_axis: str = "y"
) -> dict[str, float]:
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
    static = mean_pose(pos)
    centre = (
        pos[:, :, topology.major].mean(dim=(1, 2), keepdim=True)
        if bool(topology.major.any())
        else pos.mean(dim=(1, 2), keepdim=True)
    )
    tmpl_pose = (tmpl - tmpl[:, topology.major].mean(dim=1, keepdim=True))[:, None] + centre
    on_trajectory = mean_pose_on_trajectory(pos)
    height = float((tmpl[..., 2].amax(-1) - tmpl[..., 2].amin(-1)).mean())
    return {
        "mpjpe_cm": 100 * float(err.mean()),
        "mpjpe_std_cm": 100 * float(err.std()) if len(err) > 1 else 0.0,
        "mpjpe_over_height": float(err.mean()) / height,
        "mean_pose_cm": 100 * float(_mpjpe(static, pos).mean()),
        "template_cm": 100 * float(_mpjpe(tmpl_pose.expand_as(pos), pos).mean()),
        "mean_pose_on_trajectory_cm": 100 * float(_mpjpe(on_trajectory, pos).mean()),
        "chunks": len(pos),
    }


def denoising_curve(
    model: HumotAligner,
    chunks: torch.Tensor,
    topology: Topology,
    sigmas_cm: Sequence[float] = (0, 1, 2, 4, 6, 8, 10),
    up_axis: str = "y",
    seed: int = 0,
) -> dict[str, list[float]]:
    """Fig. 8: MPJPE (cm) of noisy inputs and of their reconstructions, per noise level."""
    pos, tmpl = prepare_chunks(chunks, topology, up_axis)
    gen = torch.Generator().manual_seed(seed)
    noisy_err, out_err = [], []
    for sigma in sigmas_cm:
        noisy = pos + torch.randn(pos.shape, generator=gen) * sigma / 100
        noisy_err.append(100 * float(_mpjpe(noisy, pos).mean()))
        out_err.append(100 * float(_mpjpe(_run(model, noisy, tmpl, tmpl), pos).mean()))
    return {
        "sigma_cm": list(map(float, sigmas_cm)),
        "input_mpjpe_cm": noisy_err,
        "output_mpjpe_cm": out_err,
    }


def denoising_figures(
    curve: Mapping[str, Sequence[float]], from_sigma_cm: float = DENOISING_FROM_CM
) -> dict[str, dict[str, float]]:
    """Whether a Fig. 8 curve shows denoising, as ``method -> figure -> number``.

    Two figures, for the model (``output_mpjpe_cm``) and for the identity, which
    returns the noisy input (its error is ``input_mpjpe_cm``):

    * ``below_noise_from_<from_sigma_cm>cm`` (``below_noise_from_4cm`` by default):
      the share of the noise levels ``sigma_cm >= from_sigma_cm`` where the output
      error is strictly below the noisy input's; 1.0 when it is at every level, 0.0
      for the identity.
    * ``growth_over_noise``: the output error's growth from the lowest to the
      highest noise level, divided by the input error's growth over the same
      levels; 1.0 for the identity, about 0 for an output that ignores its input.
      Issue #45's target is < 1/3.

    Denoising needs both: an output that ignores its input does not grow, but its
    error stays at the reconstruction error, above small noise.

    Args:
        curve: A :func:`denoising_curve` (``sigma_cm``, ``input_mpjpe_cm``,
            ``output_mpjpe_cm``; any order of the levels).
        from_sigma_cm: The lowest noise level (sigma, cm) of the first figure.

    Returns:
        ``{"model": {...}, "identity": {...}}``.

    Raises:
        EvaluationError: The columns differ in length, no level reaches
            ``from_sigma_cm``, or the input error does not grow over the levels.

    Example:
        >>> curve = {"sigma_cm": [0, 4, 8], "input_mpjpe_cm": [0, 6, 12],
        ...          "output_mpjpe_cm": [5, 5.5, 7]}
        >>> denoising_figures(curve)["model"]
        {'below_noise_from_4cm': 1.0, 'growth_over_noise': 0.16666666666666666}
    """
    sigma, noisy, out = (
        [float(v) for v in curve[k]] for k in ("sigma_cm", "input_mpjpe_cm", "output_mpjpe_cm")
    )
    if not len(sigma) == len(noisy) == len(out):
        raise EvaluationError("denoising curve: sigma, input and output columns differ in length")
    order = sorted(range(len(sigma)), key=sigma.__getitem__)
    from_levels = [i for i in order if sigma[i] >= from_sigma_cm]
    if not from_levels:
        raise EvaluationError(f"denoising curve: no noise level reaches {from_sigma_cm:g} cm")
    lo, hi = order[0], order[-1]
    noise_growth = noisy[hi] - noisy[lo]
    if not noise_growth > 0:
        raise EvaluationError("denoising curve: the input error does not grow over the levels")
    below = f"below_noise_from_{from_sigma_cm:g}cm"
    figures = {}
    for method, err in ((MODEL, out), ("identity", noisy)):
        figures[method] = {
            below: sum(err[i] < noisy[i] for i in from_levels) / len(from_levels),
            "growth_over_noise": (err[hi] - err[lo]) / noise_growth,
        }
    return figures


def mean_denoising_curve(curves: Sequence[Mapping[str, Sequence[float]]]) -> dict[str, list[float]]:
    """The mean of :func:`denoising_curve` curves over the same noise levels (Fig. 8's average).

    Raises:
        EvaluationError: No curve, or curves of other noise levels.
    """
    if not curves:
        raise EvaluationError("mean_denoising_curve: no curve")
    sigma = [float(v) for v in curves[0]["sigma_cm"]]
    if any([float(v) for v in c["sigma_cm"]] != sigma for c in curves):
        raise EvaluationError("mean_denoising_curve: the curves have other noise levels")
    mean = {"sigma_cm": sigma}
    for key in ("input_mpjpe_cm", "output_mpjpe_cm"):
        mean[key] = [sum(float(c[key][i]) for c in curves) / len(curves) for i in range(len(sigma))]
    return mean


def upsampling_curve(
    model: HumotAligner,
    chunks: torch.Tensor,
    topology: Topology,
    fractions: Sequence[float] = (1.0, 0.8, 0.6, 0.5, 0.4, 0.3, 0.2),
    up_axis: str = "y",
    seed: int = 0,
) -> dict[str, list[float]]:
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
    return {"fraction": list(map(float, fractions)), "removed_joints": removed, "mpjpe_cm": errors}


# ------------------------------------------------------------------ retargeting
#: Retargeting baselines of :mod:`skelagnostic.baselines`: ``name -> f(motion, target,
#: source_units, target_units)``; the source is resampled to HuMoT's 30 fps first.
BASELINES: dict[str, Callable[..., Motion]] = {
    "name_copy": name_copy,
    "primal_copy": primal_copy,
    "direction_copy": direction_copy,
}


def _at_30fps(motion: Motion) -> Motion:
    return motion if motion.fps == 30.0 else motion.resample(30.0)


def _motion_error(pred: Motion, truth: Motion) -> dict[str, float]:
    """MPJPE (truth's units) and MPJPE / height, globally and with the roots aligned."""
    if pred.skeleton.joint_names != truth.skeleton.joint_names:
        raise SkelagnosticError(
            "retargeting error: prediction and ground truth have different joints"
        )
    frames = min(pred.num_frames, truth.num_frames)
    a = pred.global_positions()[:frames].double()
    b = truth.global_positions()[:frames].double()
    height = truth.skeleton.height()
    err = float((a - b).norm(dim=-1).mean())
    local = float(((a - a[:, :1]) - (b - b[:, :1])).norm(dim=-1).mean())
    return {
        "mpjpe": err,
        "mpjpe_over_height": err / height,
        "root_aligned_mpjpe": local,
        "root_aligned_over_height": local / height,
    }


def retargeting_procedural(
    model: HumotAligner,
    kinds: Sequence[str] = HUMAN_KINDS,
    gaits: Sequence[str] = ("walk", "run"),
    clips_per_gait: int = 2,
    seconds: float = 6.0,
    seed: int = HELD_OUT_SEED,
) -> dict[str, dict[str, float]]:
    """Retargeting error between procedural topologies against generated ground truth (cm).

    For every ordered pair ``A -> B`` of ``kinds`` and every (gait, clip) the
    clip generated on ``A`` is retargeted onto the skeleton of the clip
    generated with the same gait and seed (so the same body size, frequency,
    amplitudes, phase and turn rate) on ``B``, which is the ground truth.

    Returns:
        ``"A->B" -> {humot_*, <baseline>_*}`` (one per :data:`BASELINES`) with the keys
        of the error (``mpjpe`` in cm, ``mpjpe_over_height``, ``root_aligned_mpjpe``,
        ``root_aligned_over_height``), averaged over clips, plus ``clips``;
        and ``"mean"``, the average over pairs.
    """
    clips = {
        k: procedural.dataset(
            kinds=(k,),
            gaits=tuple(gaits),
            clips_per_gait=clips_per_gait,
            seconds=seconds,
            seed=seed,
        )
        for k in kinds
    }
    out: dict[str, dict[str, float]] = {}
    for a in kinds:
        for b in kinds:
            if a == b:
                continue
            sums: dict[str, float] = {}
            for (src, _), (truth, _) in zip(clips[a], clips[b], strict=True):
                preds = {"humot": model.retarget(src, truth.skeleton, "cm", "cm")}
                preds |= {
                    n: f(_at_30fps(src), truth.skeleton, "cm", "cm") for n, f in BASELINES.items()
                }
                for method, pred in preds.items():
                    for key, value in _motion_error(pred, truth).items():
                        sums[f"{method}_{key}"] = sums.get(f"{method}_{key}", 0.0) + value
            count = len(clips[a])
            out[f"{a}->{b}"] = {k: v / count for k, v in sums.items()} | {"clips": count}
    keys = [k for k in next(iter(out.values())) if k != "clips"]
    out["mean"] = {k: sum(r[k] for r in out.values()) / len(out) for k in keys}
    return out


def cycle_error(
    model: HumotAligner,
    motion: Motion,
    via: Skeleton,
    units: str | None = None,
    via_units: str | None = None,
) -> dict[str, float]:
    """Source -> ``via`` -> source retargeting error, for HuMoT and the :data:`BASELINES`.

    Real clips have no paired ground truth on another rig; the cycle back to
    the source rig has. The reference is the source clip at 30 fps.

    Returns:
        ``humot_*`` and ``<baseline>_*`` errors (one per :data:`BASELINES`; see
        :func:`retargeting_procedural`;
        ``mpjpe`` in the source's units).
    """
    unit = infer_units(motion.skeleton, units or motion.units)
    truth = motion.resample(30.0) if motion.fps != 30.0 else motion
    results: dict[str, float] = {}
    humot = model.retarget(
        model.retarget(motion, via, unit, via_units), motion.skeleton, via_units, unit
    )
    preds = {"humot": humot}
    for name, f in BASELINES.items():
        there = f(_at_30fps(motion), via, unit, via_units)
        preds[name] = f(there, motion.skeleton, there.units, unit)
    for method, pred in preds.items():
        for key, value in _motion_error(pred, truth).items():
            results[f"{method}_{key}"] = value
    return results


def evaluate_clips(
    model: HumotAligner,
    groups: dict[str, list[Motion]],
    cycle_via: Sequence[Skeleton] = (),
    units: dict[str, str] | None = None,
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
            raise SkelagnosticError(f"group {name!r}: no clips")
        sk = motions[0].skeleton
        for m in motions[1:]:
            if m.skeleton.topology_key() != sk.topology_key():
                raise SkelagnosticError(
                    f"group {name!r}: clip {m.name!r} has another topology "
                    f"than {motions[0].name!r}; one topology per group"
                )
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
            results[name]["cycle"] = {k: sum(c[k] for c in cycles) / len(cycles) for k in cycles[0]}
            results[name]["cycle"]["via"] = via.name or f"{via.num_joints} joints"
    return results


def evaluate_procedural(
    model: HumotAligner,
    kinds: Sequence[str] = HUMAN_KINDS,
    clips_per_gait: int = 2,
    seconds: float = 6.0,
    seed: int = HELD_OUT_SEED,
) -> dict[str, Any]:
    """Held-out procedural clips (walk and run, seeds from ``seed``): every evaluation.

    Returns:
        ``{"kinds": <evaluate_clips result per kind>, "retargeting":
        <retargeting_procedural result>}``.
    """
    groups = {
        k: [
            m
            for m, _ in procedural.dataset(
                kinds=(k,),
                gaits=("walk", "run"),
                clips_per_gait=clips_per_gait,
                seconds=seconds,
                seed=seed,
            )
        ]
        for k in kinds
    }
    return {
        "kinds": evaluate_clips(model, groups, units=dict.fromkeys(kinds, "cm")),
        "retargeting": retargeting_procedural(
            model, kinds, clips_per_gait=clips_per_gait, seconds=seconds, seed=seed
        ),
    }


def plot_results(results: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write ``denoising.png`` and ``upsampling.png`` (one line per group)."""
    from skelagnostic.viz import plot_metric_curves

    out_dir.mkdir(parents=True, exist_ok=True)
    den = {
        f"{n} (output)": (r["denoising"]["input_mpjpe_cm"], r["denoising"]["output_mpjpe_cm"])
        for n, r in results.items()
    }
    first = next(iter(results.values()))["denoising"]["input_mpjpe_cm"]
    den["identity (no denoising)"] = (first, first)
    plot_metric_curves(
        None,
        den,
        xlabel="MPJPE of noisy input (cm)",
        ylabel="MPJPE after HuMoT (cm)",
        title="Denoising (paper Fig. 8)",
        out=out_dir / "denoising.png",
    )
    up = {n: (r["upsampling"]["fraction"], r["upsampling"]["mpjpe_cm"]) for n, r in results.items()}
    plot_metric_curves(
        None,
        up,
        xlabel="proportion of input joints",
        ylabel="MPJPE (cm)",
        title="Joint upsampling (paper Fig. 9)",
        out=out_dir / "upsampling.png",
    )
    return [out_dir / "denoising.png", out_dir / "upsampling.png"]


# ------------------------------------------------------------------ protocols
def trained_hierarchies(held: HeldOut) -> set[tuple[int, ...]] | None:
    """The joint hierarchies (parent lists) of the run's training skeletons.

    HuMoT never sees joint names, only the hierarchy and the template geometry,
    so a topology counts as seen when a training skeleton has its hierarchy
    (CMU-31 with 3dsMax names and the procedural ``biped31`` share one).

    Returns:
        The parent tuples, or ``None`` when ``held`` carries no set-up data module.
    """
    skeletons = getattr(held.datamodule, "skeletons", None)
    if not skeletons:
        return None
    return {tuple(sk.parents) for sk in skeletons.values()}


def topology_status(skeleton: Skeleton, trained: set[tuple[int, ...]] | None) -> str:
    """``"seen"``, ``"unseen"`` (see :func:`trained_hierarchies`) or ``"unknown"``."""
    if trained is None:
        return "unknown"
    return "seen" if tuple(skeleton.parents) in trained else "unseen"


def _clip_path(clip_id: str) -> Path | None:
    """The file of a clip id (``path`` or ``part:path`` of a multi-source), if it is one."""
    path = Path(clip_id)
    if path.is_file():
        return path.resolve()
    return _clip_path(clip_id.split(":", 1)[1]) if ":" in clip_id else None


def extra_clips(
    paths: str | Sequence[str], units: str | None = None, held: HeldOut | None = None
) -> list[Motion]:
    """BVH clips outside the run's data (``+protocol_options.extra=[DIR_OR_FILE, ...]``).

    Held-out clips of a topology the run never trained on come from here: a
    run's test split only holds clips of its own datasets.

    Args:
        paths: BVH files or directories (searched recursively for ``*.bvh``).
        units: Length unit of the files (``cm``, ``cmu``, ...); ``None``: the file's,
            else guessed from the skeleton's height.
        held: The run's held-out clips; clips its data module trained on are refused.

    Returns:
        The clips in metres, named by their path, in path order.

    Raises:
        EvaluationError: A path does not exist, holds no BVH file, or names a
            training clip of the run.
    """
    from skelagnostic.io.bvh import read_bvh

    if isinstance(paths, (str, Path)):
        paths = [paths]
    assigned = (getattr(held.datamodule, "assigned_splits", None) or {}) if held else {}
    trained = {_clip_path(i) for i, split in assigned.items() if split == "train"} - {None}
    clips = []
    for entry in paths:
        root = Path(entry).expanduser()
        if not root.exists():
            raise EvaluationError(f"protocol_options.extra: {root} does not exist")
        files = sorted(root.rglob("*.bvh")) if root.is_dir() else [root]
        if not files:
            raise EvaluationError(f"protocol_options.extra: no .bvh file below {root}")
        for file in files:
            if file.resolve() in trained:
                raise EvaluationError(
                    f"protocol_options.extra: {file} is a training clip of the run; "
                    "evaluate on clips it never saw"
                )
            motion = read_bvh(file).to_metres(units)
            motion.name = str(file)
            clips.append(motion)
    return clips


def _humans(held: HeldOut, notes: list[str], extra: Sequence[Motion] = ()) -> list[Motion]:
    """The held-out clips HuMoT models (bipeds); the others are named in ``notes``."""
    clips = [*held.clips, *extra]
    humans = [c for c in clips if c.skeleton.morphology == "biped"]
    others = [str(c.name) for c in clips if c.skeleton.morphology != "biped"]
    if others:
        notes.append(f"skipped {len(others)} non-human clip(s): {', '.join(others)}")
    return humans


def _protocol_clips(
    held: HeldOut, notes: list[str], extra: str | Sequence[str] | None, units: str | None
) -> tuple[list[Motion], set[tuple[int, ...]] | None]:
    """The human clips a protocol measures (held out, then ``extra``); the trained hierarchies."""
    more = extra_clips(extra, units, held) if extra else []
    if more:
        notes.append(f"{len(more)} clip(s) from protocol_options.extra, outside the run's data")
    return _humans(held, notes, more), trained_hierarchies(held)


def _by_topology(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """Mean figures of the rows of each topology status (``seen`` / ``unseen`` / ...)."""
    statuses = dict.fromkeys(r["topology"] for r in rows)
    return {s: mean_rows([r for r in rows if r["topology"] == s]) for s in statuses}


_SEEN_NOTE = (
    "topology: 'seen' when a training skeleton of the run has the clip's joint hierarchy "
    "(HuMoT never sees joint names), 'unseen' otherwise; extra['by_topology'] holds the "
    "means of each"
)


def reconstruction_protocol(
    aligner: HumotAligner,
    held: HeldOut,
    out_dir: Path,
    extra: str | Sequence[str] | None = None,
    extra_units: str | None = None,
) -> Evaluation:
    """``humot.reconstruction``: Table 2 per held-out clip, plus the curves of Fig. 8 and 9.

    Args:
        aligner: The model.
        held: The run's held-out clips.
        out_dir: Where the plots go.
        extra: More BVH files or directories to evaluate (clips outside the run's data,
            e.g. of a topology it never trained on; see :func:`extra_clips`).
        extra_units: Length unit of the ``extra`` files.

    Every row names its clip's ``topology`` status (:func:`topology_status`);
    ``extra["by_topology"]`` has the means of the seen and the unseen clips.
    """
    notes = [
        "baselines use the ground truth: mean_pose is the chunk's temporal mean pose, "
        "template the neutral template at the chunk centre, mean_pose_on_trajectory "
        "the chunk's mean root-relative pose along the true root path; the identity "
        "baseline of denoising is the curves' input_mpjpe_cm",
        _SEEN_NOTE,
    ]
    humans, trained = _protocol_clips(held, notes, extra, extra_units)
    rows: list[dict[str, Any]] = []
    groups: dict[tuple[Any, ...], tuple[str, list[torch.Tensor], Skeleton]] = {}
    for clip in humans:
        chunks = chunks_of(clip, aligner.hparams.chunk)
        if not len(chunks):
            notes.append(
                f"skipped {clip.name}: shorter than one {aligner.hparams.chunk}-frame "
                "chunk at 30 fps"
            )
            continue
        sk = clip.skeleton
        status = topology_status(sk, trained)
        rec = reconstruction(aligner, chunks, aligner.topology(sk), sk.up_axis)
        rows.append(
            {
                "clip": str(clip.name),
                "chunks": rec["chunks"],
                "topology": status,
                "values": {
                    MODEL: {
                        "mpjpe_cm": rec["mpjpe_cm"],
                        "mpjpe_over_height": rec["mpjpe_over_height"],
                    },
                    "mean_pose": {"mpjpe_cm": rec["mean_pose_cm"]},
                    "template": {"mpjpe_cm": rec["template_cm"]},
                    "mean_pose_on_trajectory": {"mpjpe_cm": rec["mean_pose_on_trajectory_cm"]},
                },
            }
        )
        name = sk.name or f"{sk.num_joints} joints"
        name = name if status == "unknown" else f"{name} ({status})"
        groups.setdefault((sk.topology_key(), status), (name, [], sk))[1].append(chunks)
    curves = {}
    for name, chunk_list, sk in groups.values():
        chunks, topo = torch.cat(chunk_list), aligner.topology(sk)
        curves[name] = {
            "denoising": denoising_curve(aligner, chunks, topo, up_axis=sk.up_axis),
            "upsampling": upsampling_curve(aligner, chunks, topo, up_axis=sk.up_axis),
        }
    plots = [p.name for p in plot_results(curves, out_dir)] if curves else []
    extra: dict[str, Any] = {"curves": curves, "by_topology": _by_topology(rows)}
    if curves:
        den = [c["denoising"] for c in curves.values()]
        extra["denoising"] = denoising_figures(mean_denoising_curve(den))
        extra["denoising_by_group"] = {
            name: denoising_figures(c["denoising"]) for name, c in curves.items()
        }
        notes.append(
            "extra['denoising']: the denoising curve averaged over the topology groups (as "
            "the paper's Fig. 8), as the share of noise levels from 4 cm (sigma) where the "
            "output error is below the noisy input's (below_noise_from_4cm) and the output "
            "error's growth over the noise range / the input's (growth_over_noise); "
            "'identity' returns the noisy input; extra['denoising_by_group'] per group"
        )
    return Evaluation(
        {
            "mpjpe_cm": "MPJPE of 1 s chunks decoded on their own template, cm, lower is better",
            "mpjpe_over_height": "MPJPE / skeleton height, lower is better",
        },
        rows,
        extra=extra,
        plots=plots,
        notes=notes,
    )


def paired_by_method(mean: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """The mean of :func:`retargeting_procedural` as ``method -> metric -> value``.

    Args:
        mean: Its ``"mean"`` entry, keys ``<method>_<metric>`` (``humot_mpjpe``, ...).

    Returns:
        ``{"model": {...}, "name_copy": {...}, ...}`` with the metrics ``mpjpe`` (cm),
        ``mpjpe_over_height``, ``root_aligned_mpjpe``, ``root_aligned_over_height``.
    """
    methods = {MODEL: "humot"} | {name: name for name in BASELINES}
    return {
        method: {k[len(prefix) + 1 :]: v for k, v in mean.items() if k.startswith(f"{prefix}_")}
        for method, prefix in methods.items()
    }


def retarget_protocol(
    aligner: HumotAligner,
    held: HeldOut,
    out_dir: Path,
    extra: str | Sequence[str] | None = None,
    extra_units: str | None = None,
    paired_clips: int = 1,
    paired_seconds: float = 4.0,
) -> Evaluation:
    """``humot.retarget``: cycle error of held-out clips via another rig, beside the baselines.

    Args:
        aligner: The model.
        held: The run's held-out clips.
        out_dir: Unused (no plots).
        extra: More BVH files or directories (see :func:`extra_clips`).
        extra_units: Length unit of the ``extra`` files.
        paired_clips: Held-out procedural clips per gait (walk, run) and topology of
            the paired retargeting in ``extra["procedural_paired_retargeting"]``.
        paired_seconds: Their duration.

    Rows carry the clip's ``topology`` status; ``extra["procedural_topologies"]``
    gives the status of each procedural kind of the paired retargeting.
    """
    notes = [
        "cycle: source -> a procedural human rig of another topology -> source, compared "
        "with the source at 30 fps; baselines: name_copy, primal_copy and direction_copy "
        "(skelagnostic.baselines)",
        _SEEN_NOTE,
    ]
    humans, trained = _protocol_clips(held, notes, extra, extra_units)
    rows: list[dict[str, Any]] = []
    for clip in humans:
        via_kind = next(
            k
            for k in HUMAN_KINDS
            if procedural.skeleton(k).topology_key() != clip.skeleton.topology_key()
        )
        cyc = cycle_error(aligner, clip, procedural.skeleton(via_kind), via_units="cm")
        values = {}
        for method, prefix in ((MODEL, "humot"), *((n, n) for n in BASELINES)):
            values[method] = {
                "cycle_over_height": cyc[f"{prefix}_mpjpe_over_height"],
                "cycle_root_aligned_over_height": cyc[f"{prefix}_root_aligned_over_height"],
            }
        rows.append(
            {
                "clip": str(clip.name),
                "via": via_kind,
                "topology": topology_status(clip.skeleton, trained),
                "values": values,
            }
        )
    paired = retargeting_procedural(aligner, clips_per_gait=paired_clips, seconds=paired_seconds)
    kinds = {k: topology_status(procedural.skeleton(k), trained) for k in HUMAN_KINDS}
    return Evaluation(
        {
            "cycle_over_height": "MPJPE after the cycle / source height, lower is better",
            "cycle_root_aligned_over_height": "the same with the roots aligned, lower is better",
        },
        rows,
        extra={
            "procedural_paired_retargeting": paired,
            "procedural_paired_mean": paired_by_method(paired["mean"]),
            "procedural_topologies": kinds,
            "by_topology": _by_topology(rows),
        },
        notes=notes,
    )
