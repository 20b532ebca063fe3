"""PC-MRL Table 1 protocol: L2P / L2Q / NPSS at keyframe gaps 5, 15, 30 (Sec. 4.3).

Every held-out clip is cut into windows of 128 frames (every ``stride`` frames);
in each window a key is placed every ``gap`` frames plus on the last frame (the
keys of the authors' ``eval_inpainter.py``), and each method fills the other
frames:

* ``LERP``: the baseline of the paper, linear interpolation of the root position
  and spherical linear interpolation (SLERP) of every joint's local rotation
  between the surrounding keys, then forward kinematics
  (:func:`skelagnostic.baselines.lerp_slerp`);
* ``PC-MRL``: :meth:`PcmrlInterpAligner.interpolate
  <skelagnostic_pcmrl.interp.aligner.PcmrlInterpAligner.interpolate>`.

Two sets of metrics are computed on the same predictions:

* ``l2p``, ``l2q``, ``npss``: **Table 1 as the authors compute it**
  (:func:`authors_table1`, equal to their ``eval_inpainter.py`` within 1e-6 on
  the fixture of ``tests/fixtures/pcmrl``): the keys of the prediction are
  replaced by the ground truth, positions (metres) are centred on the mean
  position of the keyframes, L2P is the mean over all frames of the window of
  ``sqrt(sum over joints and xyz of the squared error)``, L2Q the same on global
  quaternions, NPSS (squared-magnitude spectrum) on the concatenation of
  positions and quaternions, power-weighted over all windows. Joints that move
  no bone (:func:`~skelagnostic_pcmrl.points.effective_joints`) get the identity
  rotation in both motions and are left out of the centre, as the authors' zero-
  length joints; the target's quaternions are made sign-continuous in time (as
  the authors' data loader does) and the prediction's put on the target's
  hemisphere, frame by frame.
* ``lafan1_l2p``, ``lafan1_l2q``, ``lafan1_npss``: the LaFAN1 benchmark's
  definitions (:mod:`skelagnostic.metrics`): L2P on global positions (training
  units), horizontally centred on the window's mean root position and
  z-normalised per channel with statistics of the training windows (or, when
  none are given, of the evaluated windows; the JSON says which); L2Q on global
  quaternions; both averaged over the generated (non-key) frames. NPSS on global
  quaternions over the whole window with the squared-magnitude spectrum.

``skelagnostic evaluate`` runs it on a run's held-out clips as protocol
``pcmrl.interpolation`` (:func:`skelagnostic_pcmrl.evaluation.interpolation_protocol`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from skelagnostic.analysis import contacts_of_positions
from skelagnostic.core import quaternion as Q
from skelagnostic.core.motion import Motion
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import GROUND_TRUTH, foot_skate_figures, skate_feet
from skelagnostic.io.markdown import markdown_cell
from skelagnostic.metrics.functional import feature_npss, l2p, l2q, npss
from skelagnostic_pcmrl.interp.clips import gap_keys
from skelagnostic_pcmrl.points import effective_joints

__all__ = [
    "GAPS",
    "METRIC_SETS",
    "authors_table1",
    "evaluate",
    "format_table",
    "keyframe_centre",
    "position_stats",
    "windows",
]

#: Keyframe gaps of Table 1.
GAPS = (5, 15, 30)

Interpolator = Callable[[Motion, Sequence[int]], Motion]


def windows(motions: Sequence[Motion], window: int, stride: int) -> list[Motion]:
    """Windows of ``window`` frames every ``stride`` frames (shorter clips are skipped)."""
    out = []
    for motion in motions:
        for start in range(0, motion.num_frames - window + 1, stride):
            out.append(motion[start : start + window])
    return out


def _batch_keys(keys: torch.Tensor, batch: int, frames: int) -> torch.Tensor:
    """``[B, T]`` boolean key mask from a ``[T]`` or ``[B, T]`` one."""
    keys = torch.as_tensor(keys, dtype=torch.bool)
    if keys.shape[-1] != frames or keys.dim() not in (1, 2):
        raise SkelagnosticError(
            f"keys must be a [T] or [B, T] mask with T={frames}, got shape {list(keys.shape)}"
        )
    if not bool(keys.any(dim=-1).all()):
        raise SkelagnosticError("keys: every window needs at least one keyframe")
    return keys.expand(batch, frames)


def keyframe_centre(
    positions: torch.Tensor, keys: torch.Tensor, joints: Sequence[int] | None = None
) -> torch.Tensor:
    """``[B, 3]`` mean position over the keyframes and ``joints`` of ``[B, T, J, 3]``.

    The centre of the authors' evaluation (``p_mean`` of their ``eval_inpainter.py``,
    over their non-zero-length joints).

    Args:
        positions: Global joint positions ``[B, T, J, 3]``.
        keys: ``[T]`` or ``[B, T]`` boolean key mask.
        joints: Joints to average (``None``: all).
    """
    batch, frames = positions.shape[:2]
    mask = _batch_keys(keys, batch, frames).to(positions.device)
    sel = positions if joints is None else positions[:, :, list(joints)]
    weight = mask.to(positions.dtype)[:, :, None, None]
    return (sel * weight).sum(dim=(1, 2)) / (weight.sum(dim=(1, 2)) * sel.shape[2])


def authors_table1(
    pred_positions: torch.Tensor,
    pred_rotations: torch.Tensor,
    target_positions: torch.Tensor,
    target_rotations: torch.Tensor,
    keys: torch.Tensor,
    joints: Sequence[int] | None = None,
) -> dict[str, float]:
    r"""L2P, L2Q and NPSS of a batch of windows as the authors' ``eval_inpainter.py``.

    The keyframes of the prediction are replaced by the target; both are centred on
    :func:`keyframe_centre` of the target; then, over all ``B * T`` frames,

    $\mathrm{L2P} = \operatorname{mean}_{b,t} \lVert \hat p_{b,t} - p_{b,t} \rVert_2$
    (all ``J*3`` values of the frame), L2Q the same on the ``J*4`` quaternion values
    (no sign handling: pass them as they should be compared), and NPSS the
    power-weighted EMD of the squared-magnitude spectra of the ``J*7`` channels of
    positions and quaternions, weighted over all windows and channels.

    Args:
        pred_positions: ``[B, T, J, 3]`` predicted global positions (metres).
        pred_rotations: ``[B, T, J, 4]`` predicted global quaternions.
        target_positions: ``[B, T, J, 3]`` ground truth.
        target_rotations: ``[B, T, J, 4]`` ground truth.
        keys: ``[T]`` or ``[B, T]`` boolean key mask.
        joints: Joints of the centre (the authors': non-zero-length ones; ``None``: all).

    Returns:
        ``{"l2p", "l2q", "npss"}``.

    Raises:
        SkelagnosticError: Mismatched shapes or a window without keys.
    """
    shapes = [
        list(t.shape) for t in (pred_positions, pred_rotations, target_positions, target_rotations)
    ]
    if (
        pred_positions.dim() != 4
        or shapes[0] != shapes[2]
        or shapes[1] != shapes[3]
        or shapes[0][:3] != shapes[1][:3]
        or shapes[0][-1] != 3
        or shapes[1][-1] != 4
    ):
        raise SkelagnosticError(
            "authors_table1: expected positions [B, T, J, 3] and rotations "
            f"[B, T, J, 4] of the same B, T, J; got {shapes}"
        )
    batch, frames = shapes[0][:2]
    mask = _batch_keys(keys, batch, frames).to(pred_positions.device)[:, :, None, None]
    pos = torch.where(mask, target_positions, pred_positions)
    rot = torch.where(mask, target_rotations, pred_rotations)
    centre = keyframe_centre(target_positions, mask[:, :, 0, 0], joints)[:, None, None]
    pos, tpos = pos - centre, target_positions - centre
    l2p_value = (pos - tpos).flatten(2).norm(dim=-1).mean()
    l2q_value = (rot - target_rotations).flatten(2).norm(dim=-1).mean()
    npss_value = feature_npss(
        torch.cat([pos, rot], dim=-1).flatten(2),
        torch.cat([tpos, target_rotations], dim=-1).flatten(2),
        "abs",
    )
    return {"l2p": float(l2p_value), "l2q": float(l2q_value), "npss": float(npss_value)}


def _authors_inputs(
    motion: Motion, joints: Sequence[int], reference: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Positions (metres) and global rotations of a window as the authors compare them.

    Joints outside ``joints`` get the identity rotation; the rotations are made
    sign-continuous in time, or, given ``reference`` rotations, put on their
    hemisphere frame by frame.
    """
    metric = motion.to_metres().double()
    rot = metric.global_rotations().clone()
    keep = set(joints)
    others = [j for j in range(rot.shape[1]) if j not in keep]
    rot[:, others] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=rot.dtype)
    if reference is None:
        rot = Q.continuity(rot, dim=-3)
    else:
        rot = torch.where((rot * reference).sum(-1, keepdim=True) < 0, -rot, rot)
    return metric.global_positions(), rot


def _centred_positions(motion: Motion) -> torch.Tensor:
    """``[T, J, 3]`` global positions minus the window's mean horizontal root position."""
    pos = motion.global_positions()
    up = motion.skeleton.up_index
    centre = motion.root_positions.mean(dim=0).clone()
    centre[up] = 0.0
    return pos - centre


def position_stats(motions: Sequence[Motion]) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-channel mean and std (``[J*3]``, floored at 1e-3) of centred global positions."""
    if not motions:
        raise SkelagnosticError("position_stats: no windows to compute statistics from")
    flat = torch.cat([_centred_positions(m.double()).flatten(1) for m in motions])
    return flat.mean(dim=0), flat.std(dim=0).clamp_min(1e-3)


#: Metric sets of :func:`evaluate`: ``authors`` (Table 1 as their code) and ``lafan1``.
METRIC_SETS = ("authors", "lafan1")


def evaluate(
    methods: dict[str, Interpolator],
    motions: Sequence[Motion],
    window: int = 128,
    stride: int = 64,
    gaps: Sequence[int] = GAPS,
    stats: tuple[torch.Tensor, torch.Tensor] | None = None,
    metrics: Sequence[str] = METRIC_SETS,
) -> dict[str, Any]:
    """Run the Table 1 protocol.

    Args:
        methods: Name -> ``interpolate(motion, keyframes)`` callable.
        motions: Held-out clips (all on one skeleton hierarchy), in the training units.
        window: Window length (128 in the paper).
        stride: Frames between window starts.
        gaps: Keyframe gaps.
        stats: LaFAN1 L2P normalisation ``(mean, std)`` from training windows
            (:func:`position_stats`); ``None`` uses the evaluated windows.
        metrics: Metric sets (:data:`METRIC_SETS`): ``"authors"`` gives ``l2p``,
            ``l2q``, ``npss`` (:func:`authors_table1`), ``"lafan1"`` gives
            ``lafan1_l2p``, ``lafan1_l2q``, ``lafan1_npss``.

    Returns:
        ``{"protocol": {...}, "results": {method: {gap: {metric: value}}}}``; every
        method also has ``foot_skate_cm_s`` and ``foot_skate_ratio`` on the contacts of
        the target windows (:func:`~skelagnostic.evaluation.foot_skate_figures`), and
        the target's own skate is the method ``ground_truth`` (when the skeleton has legs).

    Raises:
        SkelagnosticError: No clip is long enough for one window, or an unknown metric set.
    """
    unknown = sorted(set(metrics) - set(METRIC_SETS))
    if unknown or not metrics:
        raise SkelagnosticError(
            f"evaluate: metrics must be among {METRIC_SETS}, got {list(metrics)}"
        )
    wins = windows(motions, window, stride)
    if not wins:
        raise SkelagnosticError(f"evaluate: no clip has {window} frames")
    stats_source = "training windows"
    if "lafan1" in metrics and stats is None:
        stats, stats_source = position_stats(wins), "evaluated windows"
    joints = effective_joints(wins[0].skeleton)
    target_pos = torch.stack([_centred_positions(w.double()) for w in wins])
    target_rot = torch.stack([w.double().global_rotations() for w in wins])
    authors_target = [_authors_inputs(w, joints) for w in wins]
    a_pos = torch.stack([p for p, _ in authors_target])
    a_rot = torch.stack([r for _, r in authors_target])
    skate = _skate_setup(wins, target_pos)
    results: dict[str, dict[str, dict[str, float]]] = {}
    for name, method in methods.items():
        results[name] = {}
        for gap in gaps:
            key_mask = gap_keys(window, gap)
            keys = key_mask.nonzero().squeeze(1).tolist()
            preds = [method(w, keys).double() for w in wins]
            row: dict[str, float] = {}
            pred_pos = torch.stack(
                [_centred_positions_like(p, w) for p, w in zip(preds, wins, strict=True)]
            )
            if skate is not None:
                row |= foot_skate_figures(pred_pos, *skate)
            if "authors" in metrics:
                pairs = [_authors_inputs(p, joints, r) for p, r in zip(preds, a_rot, strict=True)]
                row |= authors_table1(
                    torch.stack([p for p, _ in pairs]),
                    torch.stack([r for _, r in pairs]),
                    a_pos,
                    a_rot,
                    key_mask,
                    joints,
                )
            if "lafan1" in metrics:
                mean, std = stats
                pred_rot = torch.stack([p.global_rotations() for p in preds])
                mask = (~key_mask).expand(len(wins), -1)
                row |= {
                    "lafan1_l2p": float(l2p(pred_pos, target_pos, mean, std, mask=mask)),
                    "lafan1_l2q": float(l2q(pred_rot, target_rot, mask=mask)),
                    "lafan1_npss": float(npss(pred_rot, target_rot, "abs")),
                }
            results[name][str(gap)] = row
    if skate is not None:  # the ground truth's own skate: a reference row, last
        results[GROUND_TRUTH] = {str(g): foot_skate_figures(target_pos, *skate) for g in gaps}
    return {
        "protocol": {
            "window": window,
            "stride": stride,
            "gaps": list(gaps),
            "windows": len(wins),
            "clips": [m.name for m in motions if m.num_frames >= window],
            "metrics": list(metrics),
            "authors": "keys pasted from the target; positions in metres centred on the "
            "keyframes' mean position; L2P/L2Q over all frames; NPSS on positions "
            "and quaternions, power=abs",
            "lafan1_l2p_stats": stats_source,
            "lafan1_l2p_l2q_frames": "non-key frames",
            "lafan1_npss": "global quaternions, whole window, power=abs",
            "fps": wins[0].fps,
        },
        "results": results,
    }


def _skate_setup(wins: Sequence[Motion], target_pos: torch.Tensor) -> tuple[Any, ...] | None:
    """The arguments of :func:`~skelagnostic.evaluation.foot_skate_figures` after positions.

    Contacts are detected once on the target windows (``[W, T, J, 3]``); ``None`` for a
    skeleton without legs.
    """
    sk, fps = wins[0].skeleton, wins[0].fps
    feet = skate_feet(sk)
    if feet is None:
        return None
    height = sk.height()
    contacts = contacts_of_positions(target_pos[..., feet, :], fps, sk.up_index, height)
    to_cm = 100.0 * UNITS[infer_units(sk, wins[0].units)]
    return contacts, feet, fps, sk.up_index, height, to_cm


def _centred_positions_like(pred: Motion, target: Motion) -> torch.Tensor:
    """``pred``'s global positions centred with ``target``'s horizontal root mean."""
    pos = pred.global_positions()
    up = target.skeleton.up_index
    centre = target.double().root_positions.mean(dim=0).clone()
    centre[up] = 0.0
    return pos - centre


def format_table(report: dict[str, Any]) -> str:
    """A Markdown table in the layout of the paper's Table 1 (the authors' metrics if present)."""
    gaps = report["protocol"]["gaps"]
    prefix = "" if "authors" in report["protocol"].get("metrics", ["authors"]) else "lafan1_"
    head = "| Method | " + " | ".join(f"{m} {g}" for m in ("L2P", "L2Q", "NPSS") for g in gaps)
    lines = [head + " |", "|---" * (1 + 3 * len(gaps)) + "|"]
    for name, per_gap in report["results"].items():
        if prefix + "l2p" not in per_gap[str(gaps[0])]:  # a reference row (the truth's skate)
            continue
        cells = [f"{per_gap[str(g)][prefix + m]:.4f}" for m in ("l2p", "l2q", "npss") for g in gaps]
        lines.append(f"| {markdown_cell(name)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
