"""Reconstruction rows: per-clip pose error of a model beside the static baselines."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from skelagnostic.baselines import mean_pose, mean_pose_on_trajectory
from skelagnostic.core.motion import Motion
from skelagnostic.evaluation.feet import (
    FOOT_SKATE_METRICS,
    GROUND_TRUTH,
    foot_skate_rows,
    skate_feet,
)
from skelagnostic.evaluation.protocol import MODEL, track

#: Metrics of :func:`reconstruction_rows`.
RECONSTRUCTION_METRICS = {
    "mpjpe_cm": "MPJPE of global joint positions, cm, lower is better",
    "mpjpe_over_height": "MPJPE / skeleton height, lower is better",
    **FOOT_SKATE_METRICS,
}


def reconstruction_rows(
    clips: Sequence[Motion], reconstruct: Callable[[Motion], Motion]
) -> list[dict[str, Any]]:
    """Per-clip pose error of ``reconstruct(clip)`` beside the static baselines.

    Methods: :data:`MODEL`, ``mean_pose`` (the clip's temporal mean pose) and
    ``mean_pose_on_trajectory`` (its mean root-relative pose along the true root
    path), see :mod:`skelagnostic.baselines`. Positions are compared in metres
    over the frames both motions have (at the clip's frame rate). Each method's
    foot skate on the clip's contacts (:func:`foot_skate_rows`) comes with it, and
    the clip's own as :data:`GROUND_TRUTH` (when the skeleton has legs).

    Args:
        clips: The held-out clips.
        reconstruct: The model's output for a clip, on the clip's skeleton.

    Returns:
        Rows for :class:`Evaluation` with :data:`RECONSTRUCTION_METRICS`.
    """
    rows = []
    for clip in track(clips, "held-out clips"):
        pred = reconstruct(clip)
        if pred.fps != clip.fps:
            pred = pred.resample(clip.fps)
        truth_m, pred_m = clip.to_metres(), pred.to_metres()
        frames = min(truth_m.num_frames, pred_m.num_frames)
        truth = truth_m.global_positions()[:frames].double()
        height = truth_m.skeleton.height()
        guesses = {
            MODEL: pred_m.global_positions()[:frames].double(),
            "mean_pose": mean_pose(truth),
            "mean_pose_on_trajectory": mean_pose_on_trajectory(truth),
        }
        sk = truth_m.skeleton
        skates = foot_skate_rows(guesses, truth, skate_feet(sk), clip.fps, sk.up_index, height)
        values = {}
        for method, guess in guesses.items():
            err = float((guess - truth).norm(dim=-1).mean())
            values[method] = {"mpjpe_cm": 100.0 * err, "mpjpe_over_height": err / height}
            values[method] |= skates.get(method, {})
        if skates:
            values[GROUND_TRUTH] = skates[GROUND_TRUTH]
        rows.append({"clip": str(clip.name), "frames": frames, "values": values})
    return rows
