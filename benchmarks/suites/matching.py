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
* ``*_faiss_flat_<size>``, ``*_faiss_hnsw_<size>``: our search alone against
  faiss's exact ``IndexFlatL2`` and its HNSW index on the same windows and
  queries (see :mod:`benchmarks.suites.matching_faiss`; skipped, with a printed
  reason, when faiss is not installed).

Each side runs in its own subprocess so the peak memory belongs to it alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import torch

from benchmarks.authors import authors_repo
from benchmarks.harness import Result, run_child, timeit_median
from benchmarks.suites.matching_faiss import faiss_missing
from benchmarks.suites.matching_faiss import results as faiss_results

SIZES: dict[str, list[int]] = {
    "smoke": [10_000],
    "default": [10_000, 100_000, 1_000_000],
    "large": [1_000_000],
}
SETTINGS: dict[str, dict[str, int]] = {
    "smoke": {"query_frames": 240, "repeats": 2, "naive_queries": 3, "faiss_queries": 20},
    "default": {"query_frames": 600, "repeats": 3, "naive_queries": 3, "faiss_queries": 100},
    "large": {"query_frames": 600, "repeats": 5, "naive_queries": 5, "faiss_queries": 200},
}
FPS = 60.0
FRAMES_PER_CLIP = 1000
LAMBDA1, LAMBDA2 = 0.5, 1.0
BASELINE = "authors' dense scan"
#: Distributions whose versions the JSON records (the faiss baselines).
BASELINE_PACKAGES = ("faiss-cpu",)
AUTHORS_CODE = "authors' find_nn_separate (official code)"


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


def _current_rss_mib() -> float | None:
    """Resident memory of this process now (MiB), from ``/proc``; None where unavailable."""
    try:
        for line in open("/proc/self/status").read().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def child_fast(frames: int, query_frames: int, repeats: int) -> dict[str, Any]:
    """Build + frequency-scaled matching with the exact bounded search."""
    from skelagnostic.matching import frequency_scaled_motion_matching

    start_rss = _current_rss_mib()  # python, torch and skelagnostic loaded, no data yet
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
        "start_rss_mib": start_rss,
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


def _dense_features(index: Any) -> torch.Tensor:
    """``[W, samples * Dc]`` float32: every window's resampled control features, precomputed."""
    from skelagnostic.matching.windows import sample_frames

    starts, lengths, samples = index.starts, index.lengths, index.samples
    table = torch.empty(index.num_windows, samples * index.control.shape[1])
    for lo in range(0, index.num_windows, 16384):
        s, w = starts[lo : lo + 16384], lengths[lo : lo + 16384]
        resampled = sample_frames(index.control, s, w, samples, samples, s + w)
        table[lo : lo + s.numel()] = resampled.reshape(s.numel(), -1)
    return table


def _replay(
    db: Any,
    index: Any,
    query_frames: int,
    count: int,
    scan: Callable[[torch.Tensor, float, torch.Tensor | None], int],
) -> tuple[list[int], list[float]]:
    """Frequency-scaled matching of the benchmark query with ``scan`` as the search.

    ``scan(q, t, pose)`` returns the window minimising Eq. 9 for the resampled query
    window ``q``, its period ``t`` (frames) and the normalised start pose (``None``
    for the first query). The first ``count`` queries are timed (the first one also
    runs once untimed, as a warm-up).

    Returns:
        The chosen windows and the time of each search (seconds).
    """
    from skelagnostic.matching.windows import cycle_lengths, sample_frames

    query = _query(query_frames)
    control = db.normalize("manifold", query["manifold"])
    periods = cycle_lengths(query["frequency"][:, 0], FPS)
    last = torch.tensor([query_frames - 1])
    next_pose = index.pose[index.starts + index.lengths]
    samples = index.samples
    chosen: list[int] = []
    times: list[float] = []
    i, pose = 0, None
    while i < query_frames and len(chosen) < count:
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
    return chosen, times


def child_naive(frames: int, query_frames: int, naive_queries: int) -> dict[str, Any]:
    """The baseline: precomputed 600-D window features, dense brute-force scan per query."""
    db, index, _, _ = _setup(frames)
    loop_ms = _loop_build_ms_per_window(db, index)
    table = _dense_features(index)
    start_pose = index.pose[index.starts]
    period = index.lengths.float()

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

    chosen, times = _replay(db, index, query_frames, naive_queries, scan)
    table_bytes = sum(t.numel() * t.element_size() for t in (table, start_pose, period))
    return {
        "loop_build_ms": loop_ms,
        "database_bytes": db.nbytes + table_bytes,
        "query_s": sorted(times)[len(times) // 2],
        "windows": chosen,
    }


def child_authors(frames: int, query_frames: int, queries: int, repo: str) -> dict[str, Any]:
    """The authors' own matching kernel, ``find_nn_separate``, on the same database and queries.

    Their database holds one row per window (``MotionMatchingDatabase.controls``,
    built here from the same windows); their kernel returns the argmin of
    ``||c - C|| + w_p ||p - P|| + w_f max(f / F, F / f)``. It is called as
    ``offline_motion_matching.py`` calls it once per query, with each row laid out
    as ``[C, sqrt(lambda2) t(k), sqrt(lambda1) J_k]`` and no separate pose or
    frequency (``None``: those terms are 0), so its Euclidean norm is the square
    root of Eq. 9's cost and its argmin is Eq. 9's. The first query has no start
    pose: it is matched against the leading ``[C, t]`` columns (a view, no copy).
    """
    from benchmarks.suites.authors_walkthedog import find_nn

    find_nn_separate = find_nn(repo)
    db, index, _, _ = _setup(frames)
    control = _dense_features(index)
    dim = control.shape[1]
    rows = torch.empty(index.num_windows, dim + 1 + index.pose.shape[1])
    rows[:, :dim] = control
    del control
    rows[:, dim] = LAMBDA2**0.5 * index.lengths.float()
    rows[:, dim + 1 :] = LAMBDA1**0.5 * index.pose[index.starts]
    periods = index.lengths.float()

    def scan(q: torch.Tensor, t: float, pose: torch.Tensor | None) -> int:
        parts = [q[None], torch.tensor([[LAMBDA2**0.5 * t]])]
        if pose is not None:
            parts.append(LAMBDA1**0.5 * pose[None].float())
        features = torch.cat(parts, dim=1)
        nn, _, _ = find_nn_separate(
            features, None, rows[:, : features.shape[1]], None, 0.0, None, periods, 0.0
        )
        return int(nn)

    chosen, times = _replay(db, index, query_frames, queries, scan)
    return {
        "database_bytes": rows.numel() * rows.element_size(),
        "query_s": sorted(times)[len(times) // 2],
        "windows": chosen,
    }


def run(size: str) -> list[Result]:
    """Run the suite at one size (``smoke``, ``default`` or ``large``).

    With ``--authors-repo walkthedog=DIR`` it also times the authors' own kernel
    (:func:`child_authors`) and adds ``query_ms_<N>_authors_code``,
    ``identical_matches_authors_code_<N>`` and ``peak_rss_mib_<N>_authors_code``.
    With faiss installed it adds the faiss baselines of :mod:`.matching_faiss`
    (``*_faiss_flat``, ``*_faiss_hnsw``); without it they are skipped with a
    printed reason.
    """
    settings = SETTINGS[size]
    repo = authors_repo("walkthedog")
    no_faiss = faiss_missing()
    if no_faiss is not None:
        print(f"matching: faiss baselines skipped: {no_faiss}", flush=True)
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
        database_mib = fast["database_bytes"] / 2**20
        results += [
            Result(f"query_ms_{label}", "ms", fast["query_s"] * 1e3, BASELINE,
                   naive["query_s"] * 1e3),
            Result(f"identical_matches_{label}", "fraction", same / compared,
                   higher_is_better=True),
            Result(f"build_ms_per_window_{label}", "ms",
                   fast["build_s"] / fast["num_windows"] * 1e3,
                   "authors' per-window build", naive["loop_build_ms"]),
            Result(f"database_mib_{label}", "MiB", database_mib, BASELINE,
                   naive["database_bytes"] / 2**20),
            Result(f"peak_rss_mib_{label}", "MiB", fast_rss, BASELINE, naive_rss),
            Result(f"peak_rss_over_database_{label}", "ratio", fast_rss / database_mib),
        ]  # fmt: skip
        if fast["start_rss_mib"] is not None:
            results.append(
                Result(
                    f"rss_growth_over_database_{label}",
                    "ratio",
                    (fast_rss - fast["start_rss_mib"]) / database_mib,
                )
            )
        if no_faiss is None:
            ours = {"build_s": fast["build_s"], "peak_rss_mib": fast_rss}
            results += faiss_results(label, ours, database_mib, frames, settings)
        if repo is not None:
            theirs, theirs_rss = run_child(
                "benchmarks.suites.matching:child_authors",
                frames=frames,
                query_frames=settings["query_frames"],
                queries=settings["naive_queries"],
                repo=str(repo),
            )
            same = sum(a == b for a, b in zip(fast["windows"], theirs["windows"], strict=False))
            results += [
                Result(
                    f"query_ms_{label}_authors_code",
                    "ms",
                    fast["query_s"] * 1e3,
                    AUTHORS_CODE,
                    theirs["query_s"] * 1e3,
                ),
                Result(
                    f"identical_matches_authors_code_{label}",
                    "fraction",
                    same / len(theirs["windows"]),
                    higher_is_better=True,
                ),
                Result(
                    f"peak_rss_mib_{label}_authors_code", "MiB", fast_rss, AUTHORS_CODE, theirs_rss
                ),
            ]
    return results
