"""HuMoT reconstruction evaluations (Sec. 4) on 1 s chunks, and ``humot.reconstruction``.

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
* ``humot.reconstruction`` (the default protocol, :func:`reconstruction_protocol`):
  per held-out human clip, :func:`reconstruction` beside the mean-pose baselines
  of :mod:`skelagnostic.baselines`; the denoising and joint-upsampling curves
  over all chunks go into ``extra`` and two plots.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import torch

from skelagnostic.analysis import contacts_of_positions
from skelagnostic.baselines import mean_pose, mean_pose_on_trajectory
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.evaluation import (
    FOOT_SKATE_METRICS,
    GROUND_TRUTH,
    MODEL,
    Evaluation,
    EvaluationError,
    HeldOut,
    foot_skate_rows,
    skate_feet,
)
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import Topology, gather_subset, prepare_chunks
from skelagnostic_humot.evaluation.held_out import (
    SEEN_NOTE,
    by_topology,
    protocol_clips,
    topology_status,
)

__all__ = [
    "DENOISING_FROM_CM",
    "chunk_contacts",
    "chunks_of",
    "denoising_curve",
    "denoising_figures",
    "mean_denoising_curve",
    "plot_results",
    "reconstruction",
    "reconstruction_protocol",
    "run_network",
    "upsampling_curve",
]

#: Index of the up axis of the model frame (:func:`~skelagnostic_humot.template.to_model_frame`).
MODEL_UP = 2
#: The note on the foot-skate columns of ``humot.reconstruction``.
SKATE_NOTE = (
    f"foot skate: the feet's horizontal speed inside each 1 s chunk on the frames where the "
    f"clip's own feet are planted (contacts detected on the ground truth, "
    f"skelagnostic.analysis); `{GROUND_TRUTH}` is the clip's own skate, a reference, not a "
    "baseline"
)
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


def chunk_contacts(
    chunks: torch.Tensor, skeleton: Skeleton, feet: Sequence[int] | None, units: str | None = None
) -> torch.Tensor | None:
    """``[C, F, len(feet)]`` foot contacts of :func:`chunks_of`'s chunks, on the clip as a whole.

    The rule of :func:`~skelagnostic.analysis.foot_contacts` on the chunks' frames taken
    as one sequence (the clip at 30 fps, its floor over all of them), then cut again:
    no second forward kinematics.

    Args:
        chunks: ``[C, F, J, 3]`` world positions (metres) of one clip (or of clips of one
            skeleton, one after the other).
        skeleton: Their skeleton (its height and up axis).
        feet: The foot joints; ``None``: no contacts.
        units: The skeleton's length unit (default: guessed, as :func:`chunks_of`).
    """
    if feet is None or not len(chunks):
        return None
    metres = skeleton.height() * UNITS[infer_units(skeleton, units)]
    flat = chunks.reshape(-1, *chunks.shape[2:])[:, list(feet)]
    contacts = contacts_of_positions(flat, 30.0, skeleton.up_index, metres)
    return contacts.reshape(*chunks.shape[:2], len(feet))


def _mpjpe(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per-chunk MPJPE ``[C]``."""
    return (a - b).norm(dim=-1).mean(dim=(1, 2))


@torch.no_grad()
def run_network(
    model: HumotAligner,
    pos: torch.Tensor,
    src_tmpl: torch.Tensor,
    dst_tmpl: torch.Tensor,
    batch: int = 16,
    src_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Autoencode ``[C, F, J, 3]`` chunks ``batch`` at a time: ``model.net`` without gradients.

    Args:
        model: The aligner whose network runs.
        pos: Source positions, as :func:`~skelagnostic_humot.data.prepare_chunks` gives them.
        src_tmpl: Source templates, one per chunk.
        dst_tmpl: Target templates, one per chunk.
        batch: Chunks per network call.
        src_mask: Valid source joints per chunk (joint subsets), or ``None``.

    Returns:
        The decoded positions on the target templates.
    """
    outs = []
    for i in range(0, len(pos), batch):
        sl = slice(i, i + batch)
        m = None if src_mask is None else src_mask[sl]
        outs.append(model.net(pos[sl], src_tmpl[sl], dst_tmpl[sl], m))
    return torch.cat(outs)


def reconstruction(
    model: HumotAligner,
    chunks: torch.Tensor,
    topology: Topology,
    up_axis: str = "y",
    feet: Sequence[int] | None = None,
    contacts: torch.Tensor | None = None,
) -> dict[str, Any]:
    """Encode-decode MPJPE on the chunks' own templates, with static baselines.

    Args:
        model: The model.
        chunks: ``[C, F, J, 3]`` world positions (metres), :func:`chunks_of`.
        topology: The chunks' topology.
        up_axis: Up axis of ``chunks``.
        feet: Foot joints for the foot skate (:func:`~skelagnostic.evaluation.skate_feet`).
        contacts: ``[C, F, len(feet)]`` contacts of the chunks' feet
            (:func:`chunk_contacts`); without them or ``feet``, no ``foot_skate`` figures.

    Returns:
        ``mpjpe_cm``, ``mpjpe_std_cm`` (over chunks), ``mpjpe_over_height``, the
        baselines ``mean_pose_cm`` (the chunk's temporal mean pose), ``template_cm``
        (the template at the chunk centre) and ``mean_pose_on_trajectory_cm`` (the
        temporal mean of the root-relative pose plus the true root position of each
        frame), ``chunks``; and ``foot_skate``: ``method -> {foot_skate_cm_s,
        foot_skate_ratio}`` for ``model``, ``mean_pose``, ``template``,
        ``mean_pose_on_trajectory`` and ``ground_truth``, on ``contacts``
        (:func:`~skelagnostic.evaluation.foot_skate_rows`; inside each chunk, at 30 fps).
    """
    pos, tmpl = prepare_chunks(chunks, topology, up_axis)
    rec = run_network(model, pos, tmpl, tmpl)
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
    guesses = {
        MODEL: rec,
        "mean_pose": static,
        "template": tmpl_pose.expand_as(pos),
        "mean_pose_on_trajectory": on_trajectory,
    }
    skates = {}
    if feet is not None and contacts is not None:
        skates = foot_skate_rows(guesses, pos, feet, 30.0, MODEL_UP, height, contacts=contacts)
    return {
        "mpjpe_cm": 100 * float(err.mean()),
        "mpjpe_std_cm": 100 * float(err.std()) if len(err) > 1 else 0.0,
        "mpjpe_over_height": float(err.mean()) / height,
        "mean_pose_cm": 100 * float(_mpjpe(static, pos).mean()),
        "template_cm": 100 * float(_mpjpe(tmpl_pose.expand_as(pos), pos).mean()),
        "mean_pose_on_trajectory_cm": 100 * float(_mpjpe(on_trajectory, pos).mean()),
        "chunks": len(pos),
        "foot_skate": skates,
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
        out_err.append(100 * float(_mpjpe(run_network(model, noisy, tmpl, tmpl), pos).mean()))
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
        out = run_network(model, sub.take(pos, 2), sub.take(tmpl, 1), tmpl, src_mask=sub.mask)
        errors.append(100 * float(_mpjpe(out, pos).mean()))
    removed = [num - max(2, round(f * num)) for f in fractions]
    return {"fraction": list(map(float, fractions)), "removed_joints": removed, "mpjpe_cm": errors}


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
        SEEN_NOTE,
        SKATE_NOTE,
    ]
    humans, trained = protocol_clips(held, notes, extra, extra_units)
    rows: list[dict[str, Any]] = []
    outputs: dict[str, Callable[[], Motion]] = {}
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
        feet = skate_feet(sk)
        contacts = chunk_contacts(chunks, sk, feet, clip.units)
        rec = reconstruction(aligner, chunks, aligner.topology(sk), sk.up_axis, feet, contacts)
        values = {
            MODEL: {"mpjpe_cm": rec["mpjpe_cm"], "mpjpe_over_height": rec["mpjpe_over_height"]},
            "mean_pose": {"mpjpe_cm": rec["mean_pose_cm"]},
            "template": {"mpjpe_cm": rec["template_cm"]},
            "mean_pose_on_trajectory": {"mpjpe_cm": rec["mean_pose_on_trajectory_cm"]},
        }
        for method, skate in rec["foot_skate"].items():
            values[method] = values.get(method, {}) | skate
        rows.append(
            {"clip": str(clip.name), "chunks": rec["chunks"], "topology": status, "values": values}
        )
        outputs[str(clip.name)] = partial(aligner.denoise, clip)  # the whole clip, through IK
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
    extra: dict[str, Any] = {"curves": curves, "by_topology": by_topology(rows)}
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
            **FOOT_SKATE_METRICS,
        },
        rows,
        extra=extra,
        plots=plots,
        notes=notes,
        outputs=outputs,
    )
