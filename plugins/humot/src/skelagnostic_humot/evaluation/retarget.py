"""HuMoT retargeting evaluations (Sec. 4.2) and the ``humot.retarget`` protocol.

* :func:`retargeting_procedural` (the paper's Tables 3-5 need paired data the
  project does not have): the procedural generator plays the same gait with the
  same parameters (seed) on every human topology, so the clip generated on the
  target topology is the ground truth of retargeting the clip generated on the
  source topology. MPJPE of :meth:`HumotAligner.retarget` (positions -> rotations
  by IK, what a user gets) divided by the target's height, next to the name-copy
  and primal-copy baselines. Caveat: the procedural ground truth is itself made by
  driving corresponding joints with the same local rotations, so with the roots
  aligned the name copy is exact between procedural rigs whose names match
  (biped22 <-> biped31; its root path follows the copies' root rule,
  :func:`skelagnostic.baselines.scaled_root`, not the generated one) and only the
  topology with other names (biped17) tests it.
* :func:`cycle_error`: for real clips without paired ground truth,
  source -> other rig -> source, MPJPE / height, for HuMoT and the baselines.
* ``humot.retarget`` (:func:`retarget_protocol`): per held-out human clip, the
  cycle error (source -> a procedural rig of another topology -> source) of
  HuMoT beside the :func:`~skelagnostic.baselines.name_copy`,
  :func:`~skelagnostic.baselines.primal_copy` and
  :func:`~skelagnostic.baselines.direction_copy` baselines; ``extra`` adds
  :func:`retargeting_procedural` (paired procedural ground truth).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from skelagnostic import procedural
from skelagnostic.baselines import direction_copy, name_copy, primal_copy
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import (
    GROUND_TRUTH,
    MODEL,
    SKATE_THRESHOLD,
    Evaluation,
    HeldOut,
    foot_skate_rows,
    skate_feet,
)
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.evaluation.held_out import (
    HELD_OUT_SEED,
    HUMAN_KINDS,
    SEEN_NOTE,
    by_topology,
    protocol_clips,
    topology_status,
)

__all__ = [
    "BASELINES",
    "cycle_error",
    "paired_by_method",
    "retarget_protocol",
    "retargeting_procedural",
]

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
    _check_joints(pred, truth)
    return _position_error(
        pred.global_positions().double(),
        truth.global_positions().double(),
        truth.skeleton.height(),
    )


def _check_joints(pred: Motion, truth: Motion) -> None:
    if pred.skeleton.joint_names != truth.skeleton.joint_names:
        raise SkelagnosticError(
            "retargeting error: prediction and ground truth have different joints"
        )


def _position_error(a: torch.Tensor, b: torch.Tensor, height: float) -> dict[str, float]:
    """:func:`_motion_error` of global positions ``[T, J, 3]`` (the common frames)."""
    frames = min(a.shape[0], b.shape[0])
    a, b = a[:frames], b[:frames]
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
        ``mpjpe`` in the source's units), and each one's ``*_foot_skate`` (cm/s) and
        ``*_foot_skate_ratio`` on the contacts of the source
        (:func:`~skelagnostic.evaluation.foot_skate_rows`), with the source's own as
        ``source_foot_skate`` and ``source_foot_skate_ratio`` (NaN without contacts).
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
    truth_pos, height = truth.global_positions().double(), truth.skeleton.height()
    positions = {}
    for method, pred in preds.items():  # forward kinematics once per output
        _check_joints(pred, truth)
        positions[method] = pred.global_positions().double()
        for key, value in _position_error(positions[method], truth_pos, height).items():
            results[f"{method}_{key}"] = value
    sk = truth.skeleton
    skates = foot_skate_rows(
        positions, truth_pos, skate_feet(sk), truth.fps, sk.up_index, height, 100.0 * UNITS[unit]
    )
    for method, figures in skates.items():
        name = "source" if method == GROUND_TRUTH else method
        results[f"{name}_foot_skate"] = figures.get("foot_skate_cm_s", math.nan)
        results[f"{name}_foot_skate_ratio"] = figures.get("foot_skate_ratio", math.nan)
    return results


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
        "foot skate: on the contacts detected on the source (skelagnostic.analysis); the "
        f"source's own skate is the `{GROUND_TRUTH}` row (a reference, not a baseline) and "
        "extra.source_foot_skate_cm_s",
        SEEN_NOTE,
    ]
    humans, trained = protocol_clips(held, notes, extra, extra_units)
    rows: list[dict[str, Any]] = []
    source_skates: list[float] = []
    for clip in humans:
        via_kind = next(
            k
            for k in HUMAN_KINDS
            if procedural.skeleton(k).topology_key() != clip.skeleton.topology_key()
        )
        cyc = cycle_error(aligner, clip, procedural.skeleton(via_kind), via_units="cm")
        source_skates.append(cyc["source_foot_skate"])
        values = {}
        for method, prefix in ((MODEL, "humot"), *((n, n) for n in BASELINES)):
            values[method] = {
                "cycle_over_height": cyc[f"{prefix}_mpjpe_over_height"],
                "cycle_root_aligned_over_height": cyc[f"{prefix}_root_aligned_over_height"],
                "cycle_foot_skate_cm_s": cyc[f"{prefix}_foot_skate"],
                "cycle_foot_skate_ratio": cyc[f"{prefix}_foot_skate_ratio"],
            }
        values[GROUND_TRUTH] = {
            "cycle_foot_skate_cm_s": cyc["source_foot_skate"],
            "cycle_foot_skate_ratio": cyc["source_foot_skate_ratio"],
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
            "cycle_foot_skate_cm_s": "horizontal speed of the feet (cm/s) on the frames where "
            "the source's feet are planted, lower is better",
            "cycle_foot_skate_ratio": "share of those planted steps faster than "
            f"{SKATE_THRESHOLD:g} source heights/s, lower is better",
        },
        rows,
        extra={
            "procedural_paired_retargeting": paired,
            "procedural_paired_mean": paired_by_method(paired["mean"]),
            "procedural_topologies": kinds,
            "by_topology": by_topology(rows),
            "source_foot_skate_cm_s": sum(source_skates) / max(len(source_skates), 1),
        },
        notes=notes,
    )
