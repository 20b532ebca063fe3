"""Suite ``matching``: frequency-scaled motion matching on synthetic phase manifolds.

Per database size (frames; 1000 frames per clip, 60 fps, 10-D manifold + 30-D
pose descriptor + frequency, see :mod:`benchmarks.suites.synthetic`):

* ``query_ms_<size>``: latency per query of
  :func:`skelagnostic.matching.frequency_scaled_motion_matching` (exact bounded
  search) against the naive exact scan the authors use: every window's 600-D
  resampled feature precomputed, then a dense brute-force distance + argmin per
  query (chunked over the database so the baseline fits in memory).
* ``identical_matches_<size>``: share of queries where both pick the same window.
* ``build_ms_per_window_<size>``: database + index build time per window against
  a per-window build loop like the authors' (timed on 2000 windows).
* ``database_mib_<size>``: bytes held by the database and its search index,
  against the precomputed window features the dense scan needs.
* ``peak_rss_mib_<size>``: peak resident memory of a fresh process generating
  the data, building and querying, against the same for the dense baseline.

Each side runs in its own subprocess so the peak memory belongs to it alone.
"""

from __future__ import annotations

import time
from typing import Any

import torch

from benchmarks.harness import Result, run_child, timeit_median

SIZES: dict[str, list[int]] = {
    "smoke": [10_000],
    "default": [10_000, 100_000, 1_000_000],
    "large": [1_000_000],
}
SETTINGS: dict[str, dict[str, int]] = {
    "smoke": {"query_frames": 240, "repeats": 2, "naive_queries": 3},
    "default": {"query_frames": 600, "repeats": 3, "naive_queries": 3},
    "large": {"query_frames": 600, "repeats": 5, "naive_queries": 5},
}
FPS = 60.0
FRAMES_PER_CLIP = 1000
LAMBDA1, LAMBDA2 = 0.5, 1.0
BASELINE = "authors' dense scan"


def _label(frames: int) -> str:
    return f"{frames // 1_000_000}M" if frames >= 1_000_000 else f"{frames // 1000}k"


def _setup(frames: int) -> tuple[Any, Any, dict[str, torch.Tensor], float]:
    from benchmarks.suites.synthetic import synthetic_features
    from skelagnostic.matching import MotionDatabase

    features, lengths = synthetic_features(frames, max(1, frames // FRAMES_PER_CLIP), fps=FPS)
    start = time.perf_counter()
    db = MotionDatabase(features, lengths, fps=FPS)
    index = db.window_index("manifold", "pose", frequency="frequency")
    build = time.perf_counter() - start
    return db, index, features, build


def _query(query_frames: int) -> dict[str, torch.Tensor]:
    from benchmarks.suites.synthetic import synthetic_features

    features, _ = synthetic_features(query_frames, 1, fps=FPS, seed=99)
    return features


def child_fast(frames: int, query_frames: int, repeats: int) -> dict[str, Any]:
    """Build + frequency-scaled matching with the exact bounded search."""
    from skelagnostic.matching import frequency_scaled_motion_matching

    db, index, _, build = _setup(frames)
    query = _query(query_frames)
    out: dict[str, Any] = {}

    def once() -> None:
        result = frequency_scaled_motion_matching(
            db, query, lambda1=LAMBDA1, lambda2=LAMBDA2, output=[]
        )
        out["windows"] = result.windows.tolist()

    seconds = timeit_median(once, repeats=repeats, warmup=1)
    return {
        "build_s": build,
        "database_bytes": db.nbytes + index.nbytes,
        "num_windows": index.num_windows,
        "query_s": seconds / len(out["windows"]),
        "windows": out["windows"],
    }


def _loop_build_ms_per_window(db: Any, index: Any, count: int = 2000) -> float:
    """The authors' way: one window at a time, sliced and interpolated to 60 samples."""
    control = db.normalized("manifold")
    picks = torch.linspace(0, index.num_windows - 1, count).long().tolist()
    start = time.perf_counter()
    rows = []
    for w in picks:
        k, t = int(index.starts[w]), int(index.lengths[w])
        window = control[k : k + t + 1].T[None]  # [1, D, t + 1]
        grid = torch.nn.functional.interpolate(
            window, size=t * index.samples + 1, mode="linear", align_corners=True
        )[0, :, : t * index.samples : t]
        rows.append(grid.T.reshape(-1))
    torch.stack(rows)
    return (time.perf_counter() - start) / count * 1000


def child_naive(frames: int, query_frames: int, naive_queries: int) -> dict[str, Any]:
    """The baseline: precomputed 600-D window features, dense brute-force scan per query."""
    from skelagnostic.matching.windows import cycle_lengths, sample_frames

    db, index, _, _ = _setup(frames)
    loop_ms = _loop_build_ms_per_window(db, index)
    starts, lengths, samples = index.starts, index.lengths, index.samples
    dim = samples * index.control.shape[1]
    table = torch.empty(index.num_windows, dim)
    for lo in range(0, index.num_windows, 16384):
        s, w = starts[lo : lo + 16384], lengths[lo : lo + 16384]
        resampled = sample_frames(index.control, s, w, samples, samples, s + w)
        table[lo : lo + s.numel()] = resampled.reshape(s.numel(), dim)
    start_pose = index.pose[starts]
    next_pose = index.pose[starts + lengths]
    period = lengths.float()

    def scan(q: torch.Tensor, t: float, pose: torch.Tensor | None) -> int:
        best_cost, best = float("inf"), -1
        for lo in range(0, index.num_windows, 65536):
            cost = (table[lo : lo + 65536] - q).square().sum(1)
            if pose is not None:
                cost += LAMBDA1 * (start_pose[lo : lo + 65536] - pose).square().sum(1)
            cost += LAMBDA2 * (period[lo : lo + 65536] - t).square()
            k = int(torch.argmin(cost))  # first minimum: ties go to the lowest window
            if float(cost[k]) < best_cost:
                best_cost, best = float(cost[k]), lo + k
        return best

    query = _query(query_frames)
    control = db.normalize("manifold", query["manifold"])
    periods = cycle_lengths(query["frequency"][:, 0], FPS)
    last = torch.tensor([query_frames - 1])
    chosen: list[int] = []
    times: list[float] = []
    i, pose = 0, None
    while i < query_frames and len(chosen) < naive_queries:
        t = periods[i : i + 1]
        q = sample_frames(control, torch.tensor([i]), t, samples, samples, last).reshape(-1).float()
        if not chosen:
            scan(q, float(t), pose)  # warm-up
        begin = time.perf_counter()
        best = scan(q, float(t), pose)
        times.append(time.perf_counter() - begin)
        chosen.append(best)
        pose = next_pose[best]
        i += int(t)
    table_bytes = sum(t.numel() * t.element_size() for t in (table, start_pose, period))
    return {
        "loop_build_ms": loop_ms,
        "database_bytes": db.nbytes + table_bytes,
        "query_s": sorted(times)[len(times) // 2],
        "windows": chosen,
    }


def run(size: str) -> list[Result]:
    """Run the suite at one size (``smoke``, ``default`` or ``large``)."""
    settings = SETTINGS[size]
    results: list[Result] = []
    for frames in SIZES[size]:
        label = _label(frames)
        fast, fast_rss = run_child(
            "benchmarks.suites.matching:child_fast",
            frames=frames,
            query_frames=settings["query_frames"],
            repeats=settings["repeats"],
        )
        naive, naive_rss = run_child(
            "benchmarks.suites.matching:child_naive",
            frames=frames,
            query_frames=settings["query_frames"],
            naive_queries=settings["naive_queries"],
        )
        compared = len(naive["windows"])
        same = sum(a == b for a, b in zip(fast["windows"], naive["windows"], strict=False))
        results += [
            Result(f"query_ms_{label}", "ms", fast["query_s"] * 1e3, BASELINE,
                   naive["query_s"] * 1e3),
            Result(f"identical_matches_{label}", "fraction", same / compared,
                   higher_is_better=True),
            Result(f"build_ms_per_window_{label}", "ms",
                   fast["build_s"] / fast["num_windows"] * 1e3,
                   "authors' per-window build", naive["loop_build_ms"]),
            Result(f"database_mib_{label}", "MiB", fast["database_bytes"] / 2**20, BASELINE,
                   naive["database_bytes"] / 2**20),
            Result(f"peak_rss_mib_{label}", "MiB", fast_rss, BASELINE, naive_rss),
        ]  # fmt: skip
    return results
