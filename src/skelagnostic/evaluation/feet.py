"""Foot skate of a protocol's outputs: every method on the ground truth's planted frames.

Shared by the protocols of every method (and the reconstruction rows): the contacts are
detected once per clip on positions the protocol already computed, and the ground
truth's own skate is a reference row (:data:`GROUND_TRUTH`), not a baseline.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch

from skelagnostic.analysis import contact_joints, contacts_of_positions
from skelagnostic.core.motion import Motion
from skelagnostic.core.units import UNITS, infer_units
from skelagnostic.errors import SkelagnosticError
from skelagnostic.metrics.functional import foot_skate, foot_skate_ratio

__all__ = [
    "FOOT_SKATE_METRICS",
    "GROUND_TRUTH",
    "SKATE_THRESHOLD",
    "foot_skate_figures",
    "foot_skate_rows",
    "own_foot_skate",
    "skate_feet",
]

#: The method name of the ground truth's own figures (its foot skate): a reference row
#: beside the model and the baselines, not a baseline (``references:`` of a result entry).
GROUND_TRUTH = "ground_truth"
#: Speed above which a planted step skates (``foot_skate_ratio``), in skeleton heights per
#: second (8.5 cm/s for a 1.7 m human).
SKATE_THRESHOLD = 0.05
#: Metrics of :func:`foot_skate_figures` and :func:`foot_skate_rows`.
FOOT_SKATE_METRICS = {
    "foot_skate_cm_s": "mean horizontal speed of the feet on the frames where the ground "
    "truth's feet are planted, cm/s, lower is better",
    "foot_skate_ratio": f"share of those planted steps faster than {SKATE_THRESHOLD:g} skeleton "
    "heights/s, lower is better",
}


def skate_feet(skeleton: Any) -> list[int] | None:
    """The foot joints foot skate is read on (:func:`~skelagnostic.analysis.contact_joints`).

    Returns:
        The joints, or ``None`` for a skeleton without legs (no foot-skate columns).
    """
    try:
        return contact_joints(skeleton)
    except SkelagnosticError:
        return None


def foot_skate_figures(
    positions: torch.Tensor,
    contacts: torch.Tensor,
    feet: Sequence[int],
    fps: float,
    up_index: int,
    height: float,
    to_cm: float = 100.0,
) -> dict[str, float]:
    """:data:`FOOT_SKATE_METRICS` of one motion's positions on given contacts.

    Args:
        positions: ``[..., T, J, 3]`` global joint positions (any constant shift per
            sequence is harmless: only frame-to-frame steps count).
        contacts: ``[..., T, F]`` bool contacts of the ``F`` feet.
        feet: The foot joints.
        fps: Frame rate.
        up_index: Index of the up axis.
        height: The skeleton's height, in the positions' units.
        to_cm: Centimetres per unit of the positions.

    Returns:
        ``foot_skate_cm_s`` and ``foot_skate_ratio``; empty when no foot is planted at
        two consecutive frames (no value rather than NaN).
    """
    cm = positions[..., list(feet), :].double() * to_cm
    skate = float(foot_skate(cm, contacts, fps, up_axis=up_index))
    if not math.isfinite(skate):
        return {}
    threshold = SKATE_THRESHOLD * height * to_cm
    ratio = float(foot_skate_ratio(cm, contacts, fps, threshold, up_axis=up_index))
    return {"foot_skate_cm_s": skate, "foot_skate_ratio": ratio}


def foot_skate_rows(
    positions: Mapping[str, torch.Tensor],
    truth: torch.Tensor,
    feet: Sequence[int] | None,
    fps: float,
    up_index: int,
    height: float,
    to_cm: float = 100.0,
    contacts: torch.Tensor | None = None,
) -> dict[str, dict[str, float]]:
    """Foot skate of every method's positions on the contacts of the ground truth.

    The contacts are detected once, on ``truth``
    (:func:`~skelagnostic.analysis.contacts_of_positions`; or given), so the model and every
    baseline are scored on the same planted frames; the truth's own skate is the
    :data:`GROUND_TRUTH` entry, what the data itself has (a reference, not a baseline).
    Positions already computed by the protocol are reused: no forward kinematics here.

    Args:
        positions: ``method -> [..., T, J, 3]`` positions, on the truth's skeleton
            (joints in the same order; frames beyond the truth's are ignored).
        truth: ``[..., T, J, 3]`` ground-truth positions.
        feet: The foot joints (:func:`skate_feet`); ``None``: no figures.
        fps: Frame rate.
        up_index: Index of the up axis.
        height: The skeleton's height, in the positions' units.
        to_cm: Centimetres per unit of the positions.
        contacts: ``[..., T, F]`` contacts of the truth when the caller detected them
            (e.g. on whole clips before cutting them into chunks).

    Returns:
        ``method -> {foot_skate_cm_s, foot_skate_ratio}``, then :data:`GROUND_TRUTH`;
        empty without feet.
    """
    if feet is None:
        return {}
    frames = min(truth.shape[-3], *(p.shape[-3] for p in positions.values()))
    truth = truth[..., :frames, :, :]
    if contacts is None:
        contacts = contacts_of_positions(truth[..., list(feet), :], fps, up_index, height)
    contacts = contacts[..., :frames, :]
    args = (contacts, feet, fps, up_index, height, to_cm)
    out = {m: foot_skate_figures(p[..., :frames, :, :], *args) for m, p in positions.items()}
    return out | {GROUND_TRUTH: foot_skate_figures(truth, *args)}


def own_foot_skate(motion: Motion, positions: torch.Tensor | None = None) -> dict[str, float]:
    """:data:`FOOT_SKATE_METRICS` of a motion on its own contacts (no ground truth).

    For outputs on a character without ground truth (a transfer onto another rig):
    the contacts are detected on the motion itself
    (:func:`~skelagnostic.analysis.contacts_of_positions`), so a foot the method
    drags fast enough is not planted and does not count; compare methods with it, and
    prefer :func:`foot_skate_rows` where a ground truth exists.

    Args:
        motion: The motion (any units: centimetres per unit from
            :func:`~skelagnostic.core.units.infer_units`).
        positions: Its global positions ``[T, J, 3]`` when already computed.

    Returns:
        ``foot_skate_cm_s`` and ``foot_skate_ratio``; empty without legs or contacts.
    """
    sk = motion.skeleton
    feet = skate_feet(sk)
    if feet is None or motion.num_frames < 2:
        return {}
    pos = motion.global_positions() if positions is None else positions
    height = sk.height()
    contacts = contacts_of_positions(pos[:, feet], motion.fps, sk.up_index, height)
    to_cm = 100.0 * UNITS[infer_units(sk, motion.units)]
    return foot_skate_figures(pos, contacts, feet, motion.fps, sk.up_index, height, to_cm)
