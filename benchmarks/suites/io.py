"""Suite ``io``: BVH reading, forward kinematics and BVH writing against pybvh.

On the LaFAN1 clip ``human/lafan1/walk4_subject1.bvh`` (3.5 MB, 4918 frames,
22 joints) from the shared data (``SKELAGNOSTIC_TEST_DATA`` or
``../shared/data``); ``--size smoke`` uses its first 400 frames. Without the
shared data a procedural clip of the same size is written and used, and the
result names say so.

* ``read_bvh``: ``skelagnostic.read_bvh`` vs ``pybvh.read_bvh_file``.
* ``global_positions``: all-joint world positions from a loaded file,
  ``Motion.global_positions()`` vs pybvh's ``Bvh.joint_positions()``. pybvh
  caches its result on the object, so each of its repeats times a freshly read
  object (the read itself is not timed).
* ``read_bvh+global_positions``: a file to world positions, end to end.
  ``read_bvh`` converts Euler angles to quaternions only when the rotations are
  first used, so the conversion is timed here (and not in ``read_bvh``).
* ``write_bvh``: ``skelagnostic.write_bvh`` vs ``pybvh.write_bvh_file``.

Unless ``--threads`` is given, torch runs on one thread here: pybvh is
single-threaded numpy, so that compares like with like. Before timing, both
libraries' positions must agree within 1e-4 relative to the clip's extent;
otherwise the suite fails instead of reporting a speed.
"""

from __future__ import annotations

import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from benchmarks.harness import REPO_ROOT, THREADS_ENV, Result, timeit_median

BASELINE_PACKAGES = ("pybvh",)
CLIP = Path("human") / "lafan1" / "walk4_subject1.bvh"
REPEATS = {"smoke": 3, "default": 9, "large": 15}


def _clip(size: str, workdir: Path) -> tuple[Path, str]:
    import skelagnostic as sa

    root = os.environ.get("SKELAGNOSTIC_TEST_DATA")
    data = Path(root) if root else REPO_ROOT.parent / "shared" / "data"
    source = data / CLIP
    if source.is_file():
        label = "lafan1 walk4_subject1"
        motion = None
    else:
        label = "procedural biped22 (shared data absent)"
        motion, _ = sa.procedural.generate("biped22", "walk", seconds=4917 / 30, fps=30)
    if size == "smoke":
        motion = (motion if motion is not None else sa.read_bvh(source))[:400]
        label += ", first 400 frames"
    if motion is None:
        return source, label
    path = workdir / "clip.bvh"
    sa.write_bvh(motion, path)
    return path, label


def _fresh_pybvh_fk(path: Path, repeats: int) -> float:
    import pybvh

    times = []
    for _ in range(repeats + 1):
        bvh = pybvh.read_bvh_file(path)
        start = time.perf_counter()
        bvh.joint_positions()
        times.append(time.perf_counter() - start)
    return float(np.median(times[1:]))


def run(size: str) -> list[Result]:
    """Run the suite at ``size`` and return its results."""
    import pybvh

    import skelagnostic as sa

    warnings.filterwarnings("ignore", module="pybvh")
    if not os.environ.get(THREADS_ENV):
        # pybvh is single-threaded numpy: compare like with like unless --threads says otherwise
        torch.set_num_threads(1)
    repeats = REPEATS[size]
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        path, label = _clip(size, workdir)
        motion = sa.read_bvh(path)
        ours = motion.global_positions().numpy()
        theirs = np.asarray(pybvh.read_bvh_file(path).joint_positions())
        extent = float(np.abs(theirs).max())
        error = float(np.abs(ours - theirs).max()) / extent
        if ours.shape != theirs.shape or error > 1e-4:
            raise RuntimeError(
                f"io suite: positions disagree with pybvh on {label} "
                f"(shapes {ours.shape} vs {theirs.shape}, max relative error {error:.2e})"
            )
        frames = motion.num_frames
        read_ours = timeit_median(lambda: sa.read_bvh(path), repeats)
        read_base = timeit_median(lambda: pybvh.read_bvh_file(path), repeats)
        fk_ours = timeit_median(motion.global_positions, repeats)
        fk_base = _fresh_pybvh_fk(path, repeats)
        e2e_ours = timeit_median(lambda: sa.read_bvh(path).global_positions(), repeats)
        e2e_base = timeit_median(lambda: pybvh.read_bvh_file(path).joint_positions(), repeats)
        bvh_obj = pybvh.read_bvh_file(path)
        write_ours = timeit_median(lambda: sa.write_bvh(motion, workdir / "ours.bvh"), repeats)
        write_base = timeit_median(
            lambda: pybvh.write_bvh_file(bvh_obj, workdir / "theirs.bvh"), repeats
        )
    tag = f" ({label}, {frames} frames, {torch.get_num_threads()} thread(s))"
    return [
        Result("read_bvh" + tag, "ms", read_ours * 1e3, "pybvh.read_bvh_file", read_base * 1e3),
        Result(
            "global_positions" + tag,
            "ms",
            fk_ours * 1e3,
            "pybvh Bvh.joint_positions",
            fk_base * 1e3,
        ),
        Result(
            "read_bvh+global_positions" + tag,
            "ms",
            e2e_ours * 1e3,
            "pybvh.read_bvh_file + joint_positions",
            e2e_base * 1e3,
        ),
        Result("write_bvh" + tag, "ms", write_ours * 1e3, "pybvh.write_bvh_file", write_base * 1e3),
        Result("positions_max_rel_diff_vs_pybvh" + tag, "ratio", error),
    ]
