"""The PC-MRL authors' stage-1 trainer (github MiniEval/PC-MRL) timed as a same-run baseline.

Used by the ``training`` suite's PC-MRL part when ``run.py --authors-repo
pcmrl=DIR`` is given. :func:`train_stage1` is meant for a child process
(:func:`benchmarks.harness.run_child`): it imports their ``train_pointcloud.py``
from the checkout (their code has no license file: it is run, never copied) and
runs their ``PointCloudTrainer.train`` loop unchanged, with these stand-ins
installed in ``sys.modules`` first (:func:`install_stand_ins`):

* ``pytorch3d.ops`` (a CUDA build, not installable on a CPU machine) by exact
  pure-torch equivalents, vectorised over the batch like pytorch3d's kernels:
  ``sample_farthest_points`` with its default ``random_start_point=False`` (the
  first point is index 0; each next one is the point whose smallest squared
  distance to the chosen ones is largest, ties to the lowest index),
  ``knn_points`` (squared distances, nearest first, ties by index) and
  ``knn_gather``;
* ``pytorch3d.transforms.euler_angles_to_matrix`` and ``matrix_to_quaternion``
  (their data loaders' start-up only) by the same formulas in pure torch;
* ``Tensor.cuda`` by the identity (their ``RelativePosition`` moves its tables
  to CUDA on every call);
* ``viewport.visualiser.Visualiser`` (a Qt window) by one that draws nothing;
* ``bezier`` (imported by their evaluation's interpolation helpers, not used in
  training) by a module whose ``Curve`` raises.

Each step is timed by wall clock between the ends of consecutive iterations of
their loop (the line their loop prints after the optimiser step is the mark:
``print`` in their module is replaced by one that records the time and
discards the text), so a step is their whole iteration: sampling the windows,
forward kinematics and the point clouds, the network, the KNN losses, backward,
gradient clipping, the optimiser, their log file.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import tempfile
import time
import types
from collections import namedtuple
from pathlib import Path
from typing import Any

import torch

_KNN = namedtuple("_KNN", "dists idx knn")


def sample_farthest_points(
    points: torch.Tensor, lengths: Any = None, K: int = 50, random_start_point: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """pytorch3d's ``sample_farthest_points`` for equal-size clouds, fixed start point."""
    if lengths is not None or random_start_point:
        raise NotImplementedError("only the defaults their code uses")
    batch, num, _ = points.shape
    rows = torch.arange(batch, device=points.device)
    idx = torch.zeros(batch, K, dtype=torch.int64, device=points.device)
    closest = torch.full((batch, num), math.inf, dtype=points.dtype, device=points.device)
    chosen = torch.zeros(batch, dtype=torch.int64, device=points.device)
    for i in range(K):
        idx[:, i] = chosen
        d = (points - points[rows, chosen].unsqueeze(1)).square().sum(-1)
        closest = torch.minimum(closest, d)
        chosen = closest.argmax(dim=1)  # the first maximum: ties to the lowest index
    return points[rows.unsqueeze(1), idx], idx


def knn_points(p1: torch.Tensor, p2: torch.Tensor, K: int = 1, **kwargs: Any) -> _KNN:
    """pytorch3d's ``knn_points`` (squared distances, sorted nearest first)."""
    if kwargs:
        raise NotImplementedError(f"only the defaults their code uses, not {sorted(kwargs)}")
    d = (p1.unsqueeze(2) - p2.unsqueeze(1)).square().sum(-1)
    dists, order = torch.sort(d, dim=-1, stable=True)
    return _KNN(dists[..., :K], order[..., :K], None)


def knn_gather(x: torch.Tensor, idx: torch.Tensor, lengths: Any = None) -> torch.Tensor:
    """pytorch3d's ``knn_gather``: ``out[b, m, k] = x[b, idx[b, m, k]]``."""
    rows = torch.arange(x.shape[0], device=x.device).view(-1, 1, 1)
    return x[rows, idx]


def _axis_angle_rotation(axis: str, angle: torch.Tensor) -> torch.Tensor:
    cos, sin = torch.cos(angle), torch.sin(angle)
    one, zero = torch.ones_like(angle), torch.zeros_like(angle)
    if axis == "X":
        flat = (one, zero, zero, zero, cos, -sin, zero, sin, cos)
    elif axis == "Y":
        flat = (cos, zero, sin, zero, one, zero, -sin, zero, cos)
    else:
        flat = (cos, -sin, zero, sin, cos, zero, zero, zero, one)
    return torch.stack(flat, -1).reshape((*angle.shape, 3, 3))


def euler_angles_to_matrix(euler_angles: torch.Tensor, convention: str) -> torch.Tensor:
    """pytorch3d's ``euler_angles_to_matrix``: the product of the three axis rotations."""
    mats = [
        _axis_angle_rotation(c, e)
        for c, e in zip(convention, torch.unbind(euler_angles, -1), strict=True)
    ]
    return mats[0] @ mats[1] @ mats[2]


def matrix_to_quaternion(matrix: torch.Tensor) -> torch.Tensor:
    """pytorch3d's ``matrix_to_quaternion`` (w first, the best-conditioned candidate)."""
    batch = matrix.shape[:-2]
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = torch.unbind(matrix.reshape((*batch, 9)), -1)
    diag = torch.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1
    )
    q_abs = torch.where(diag > 0, diag.clamp_min(0).sqrt(), torch.zeros_like(diag))
    candidates = torch.stack(
        [
            torch.stack([q_abs[..., 0] ** 2, m21 - m12, m02 - m20, m10 - m01], -1),
            torch.stack([m21 - m12, q_abs[..., 1] ** 2, m10 + m01, m02 + m20], -1),
            torch.stack([m02 - m20, m10 + m01, q_abs[..., 2] ** 2, m12 + m21], -1),
            torch.stack([m10 - m01, m20 + m02, m21 + m12, q_abs[..., 3] ** 2], -1),
        ],
        -2,
    )
    floor = torch.tensor(0.1, dtype=q_abs.dtype, device=q_abs.device)
    candidates = candidates / (2.0 * q_abs[..., None].max(floor))
    best = torch.nn.functional.one_hot(q_abs.argmax(-1), num_classes=4) > 0.5
    return candidates[best, :].reshape((*batch, 4))


def _not_in_training(*args: Any, **kwargs: Any) -> Any:
    raise RuntimeError("bezier is not used by their training step")


class _NoVisualiser:
    """Stand-in for their Qt ``Visualiser``: accepts the data and draws nothing."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        pass

    def update_data(self, *args: Any, **kwargs: Any) -> None:
        pass


def install_stand_ins() -> None:
    """Put the replacements listed in the module docstring in place (this process only)."""
    ops = types.ModuleType("pytorch3d.ops")
    ops.sample_farthest_points = sample_farthest_points  # type: ignore[attr-defined]
    ops.knn_points = knn_points  # type: ignore[attr-defined]
    ops.knn_gather = knn_gather  # type: ignore[attr-defined]
    transforms = types.ModuleType("pytorch3d.transforms")
    transforms.euler_angles_to_matrix = euler_angles_to_matrix  # type: ignore[attr-defined]
    transforms.matrix_to_quaternion = matrix_to_quaternion  # type: ignore[attr-defined]
    p3d = types.ModuleType("pytorch3d")
    p3d.ops, p3d.transforms = ops, transforms  # type: ignore[attr-defined]
    visualiser = types.ModuleType("viewport.visualiser")
    visualiser.Visualiser = _NoVisualiser  # type: ignore[attr-defined]
    viewport = types.ModuleType("viewport")
    viewport.visualiser = visualiser  # type: ignore[attr-defined]
    bezier = types.ModuleType("bezier")
    bezier.Curve = _not_in_training  # type: ignore[attr-defined]
    sys.modules.update(
        {
            "pytorch3d": p3d,
            "pytorch3d.ops": ops,
            "pytorch3d.transforms": transforms,
            "viewport": viewport,
            "viewport.visualiser": visualiser,
            "bezier": bezier,
        }
    )
    torch.Tensor.cuda = lambda self, *a, **k: self  # type: ignore[method-assign]


#: Windows of each batch that the authors' training loop draws every 50 iterations
#: (``n_vis`` in their ``train_pointcloud.py``): their smallest workable batch.
VISUALISED_WINDOWS = 4


class _Stop(Exception):
    """Raised by the timing ``print`` once enough iterations ran."""


def train_stage1(
    repo: str,
    source: str,
    target_skeleton: str,
    steps: int,
    warmup: int = 1,
    batch_size: int = 16,
    window: int = 64,
) -> dict[str, Any]:
    """Time ``steps`` iterations of the authors' stage 1 after ``warmup`` (child process).

    Args:
        repo: Checkout of github MiniEval/PC-MRL.
        source: A LaFAN1 BVH file: the training clip (their ``LaFANDataLoader``
            reads the directory it is linked into; 30 fps, as they subsample).
        target_skeleton: A CMU BVH file whose skeleton is the target (``cmu_skeleton``).
        steps: Timed iterations.
        warmup: Untimed iterations first (at least 1).
        batch_size: Windows per step (their ``PC-MRL.batch_size``, default 12).
        window: Frames per window (their ``GENERAL.max_length``, default 128).

    Returns:
        ``median_step_s``, ``mean_step_s`` and ``parameters`` of their network.
    """
    import json

    if batch_size < VISUALISED_WINDOWS:
        raise ValueError(
            f"the authors' stage 1 needs batch_size >= {VISUALISED_WINDOWS} (its training loop "
            f"draws the first {VISUALISED_WINDOWS} windows of each batch), got {batch_size}"
        )
    install_stand_ins()
    sys.path.insert(0, str(repo))
    cfg = json.loads((Path(repo) / "config.json").read_text())
    cfg["PC-MRL"]["batch_size"] = batch_size
    cfg["GENERAL"]["max_length"] = window
    import train_pointcloud
    from data.cmu import CMUDataLoader
    from data.lafan import LaFANDataLoader

    warmup = max(1, warmup)
    stamps: list[float] = []

    def mark(*args: Any, **kwargs: Any) -> None:
        stamps.append(time.perf_counter())
        if len(stamps) >= warmup + steps:
            raise _Stop

    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        clips = Path(tmp) / "lafan1"
        clips.mkdir()
        (clips / Path(source).name).symlink_to(Path(source).resolve())
        os.chdir(tmp)
        try:
            (Path(tmp) / "ckpt_pc-mrl").mkdir()
            loaders = [LaFANDataLoader(str(clips), source, min_length=window)]
            skeleton = CMUDataLoader.setup_skeleton(target_skeleton, "cpu")
            trainer = train_pointcloud.PointCloudTrainer(loaders, skeleton, cfg=cfg, device="cpu")
            train_pointcloud.print = mark
            try:
                trainer.train(50000)  # their run length: sets the learning-rate schedule
            except _Stop:
                pass
        finally:
            os.chdir(cwd)
    times = [b - a for a, b in zip(stamps[warmup - 1 :], stamps[warmup:], strict=False)]
    return {
        "median_step_s": statistics.median(times),
        "mean_step_s": statistics.fmean(times),
        "parameters": sum(p.numel() for p in trainer.model.parameters()),
    }
