"""faiss baselines of the ``matching`` suite: the same windows, searched by a vector library.

Eq. 9's cost of window ``k`` for a query window is a squared Euclidean distance
in ``L * Dc + 1 + Dj`` dimensions (631 in the suite)::

    ||[P, sqrt(lambda2) t_q, sqrt(lambda1) J] - [Q_k, sqrt(lambda2) t_k, sqrt(lambda1) J_k]||^2

so faiss answers it exactly with ``IndexFlatL2`` over one row per window, and
approximately with ``IndexHNSWFlat`` over the same rows. Both indexes are filled
chunk by chunk from the windows (the ``[W, 631]`` matrix exists only inside
faiss). Queries are independent: the window starting at evenly spaced frames
of the suite's query sequence, with that frame's own pose descriptor as start
pose, so every method answers the same questions one query at a time.

Each faiss index is built in its own subprocess
(:func:`benchmarks.harness.run_child`), which also builds our index and times
our search interleaved with faiss's, query by query (:func:`paired`), so a busy
spell of the shared machine slows both alike. faiss runs with as many OpenMP
threads as torch has (``--threads 1``: one thread).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import torch

from benchmarks.harness import Result

#: HNSW graph degree ``M`` and construction beam (faiss's default ``efConstruction``).
HNSW_M = 32
HNSW_EF_CONSTRUCTION = 40
#: ``efSearch`` values tried, smallest first; the first with recall@1 >= RECALL_GOAL is reported.
EF_SEARCH = (16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384)
RECALL_GOAL = 0.99
#: Windows turned into faiss rows at a time.
_ADD_CHUNK = 16384
FLAT = "faiss IndexFlatL2 (exact)"
HNSW = "faiss IndexHNSWFlat"


def faiss_missing() -> str | None:
    """Why the faiss baselines cannot run (``None`` when ``faiss`` imports)."""
    try:
        import faiss  # noqa: F401
    except ImportError as err:
        return f"faiss-cpu is not installed ({err}); pip install -e '.[bench]'"
    return None


def query_set(db: Any, index: Any, query_frames: int, count: int) -> dict[str, torch.Tensor]:
    """``count`` independent query windows of the suite's query sequence.

    Returns:
        ``queries [n, L * Dc]`` float64 resampled normalised windows, ``lengths [n]``
        their periods and ``poses [n, Dj]`` float64 normalised start poses.
    """
    from benchmarks.suites.matching import FPS, _query
    from skelagnostic.matching.windows import cycle_lengths, sample_frames

    query = _query(query_frames)
    control = db.normalize("manifold", query["manifold"])
    periods = cycle_lengths(query["frequency"][:, 0], FPS)
    frames = torch.linspace(0, query_frames - 1, count).round().long().unique()
    last = torch.full_like(frames, query_frames - 1)
    samples = index.samples
    windows = sample_frames(control, frames, periods[frames], samples, samples, last)
    return {
        "queries": windows.reshape(frames.numel(), -1),
        "lengths": periods[frames],
        "poses": db.normalize("pose", query["pose"][frames]).double(),
    }


def our_query(index: Any, qs: dict[str, torch.Tensor]) -> Callable[[int], tuple[int, float]]:
    """``i -> (window, cost)``: :meth:`WindowIndex.search` on query ``i`` of :func:`query_set`."""
    from benchmarks.suites.matching import LAMBDA1, LAMBDA2

    def one(i: int) -> tuple[int, float]:
        ids, cost = index.search(
            qs["queries"][i : i + 1],
            qs["lengths"][i : i + 1],
            qs["poses"][i : i + 1],
            lambda_pose=LAMBDA1,
            lambda_period=LAMBDA2,
        )
        return int(ids[0]), float(cost[0])

    return one


def paired(
    searches: list[Callable[[int], Any]], count: int, repeats: int
) -> tuple[list[list[Any]], list[float]]:
    """Time several searches on the same queries, interleaved so they share the machine's load.

    Every query is searched ``repeats`` times by each search in turn (after one
    warm-up each), so a busy spell of the shared machine slows all of them alike.

    Returns:
        Every search's answers and, per search, the median over the queries of
        each query's median seconds.
    """
    for search in searches:
        search(0)  # warm-up
    answers: list[list[Any]] = [[] for _ in searches]
    medians: list[list[float]] = [[] for _ in searches]
    for i in range(count):
        times: list[list[float]] = [[] for _ in searches]
        last: list[Any] = [None] * len(searches)
        for _ in range(max(1, repeats)):
            for k, search in enumerate(searches):
                begin = time.perf_counter()
                last[k] = search(i)
                times[k].append(time.perf_counter() - begin)
        for k in range(len(searches)):
            answers[k].append(last[k])
            medians[k].append(statistics.median(times[k]))
    return answers, [statistics.median(m) for m in medians]


def _rows(index: Any, lo: int, hi: int) -> torch.Tensor:
    """Eq. 9 rows ``[Q_k, sqrt(lambda2) t_k, sqrt(lambda1) J_k]`` of windows ``lo:hi``, float32."""
    from benchmarks.suites.matching import LAMBDA1, LAMBDA2
    from skelagnostic.matching.windows import sample_frames

    s, w = index.starts[lo:hi], index.lengths[lo:hi]
    control = sample_frames(index.control, s, w, index.samples, index.samples, s + w)
    parts = [
        control.reshape(hi - lo, -1),
        LAMBDA2**0.5 * w.double()[:, None],
        LAMBDA1**0.5 * index.pose[s].double(),
    ]
    return torch.cat(parts, dim=1).float().contiguous()


def _query_rows(qs: dict[str, torch.Tensor]) -> torch.Tensor:
    from benchmarks.suites.matching import LAMBDA1, LAMBDA2

    parts = [
        qs["queries"],
        LAMBDA2**0.5 * qs["lengths"].double()[:, None],
        LAMBDA1**0.5 * qs["poses"],
    ]
    return torch.cat(parts, dim=1).float().contiguous()


def _fill(faiss_index: Any, index: Any) -> float:
    """Add every window's row to ``faiss_index``; returns the seconds it took."""
    start = time.perf_counter()
    for lo in range(0, index.num_windows, _ADD_CHUNK):
        faiss_index.add(_rows(index, lo, min(index.num_windows, lo + _ADD_CHUNK)).numpy())
    return time.perf_counter() - start


def _index_bytes(faiss_index: Any) -> int:
    """Bytes a flat or HNSW-flat faiss index holds: its vectors, plus the graph for HNSW."""
    import faiss

    if not hasattr(faiss_index, "hnsw"):
        return faiss_index.ntotal * faiss_index.code_size
    storage = faiss.downcast_index(faiss_index.storage)
    graph = faiss_index.hnsw
    return (
        storage.ntotal * storage.code_size
        + 4 * graph.neighbors.size()
        + 8 * graph.offsets.size()
        + 4 * graph.levels.size()
    )


def faiss_query(faiss_index: Any, rows: torch.Tensor) -> Callable[[int], int]:
    """``i -> window``: ``faiss_index`` searched for query row ``i`` alone (as matching asks)."""
    array = rows.numpy()
    return lambda i: int(faiss_index.search(array[i : i + 1], 1)[1][0, 0])


def _setup_faiss(frames: int, query_frames: int, queries: int) -> tuple[Any, Any, dict]:
    import faiss

    from benchmarks.suites.matching import _setup

    faiss.omp_set_num_threads(torch.get_num_threads())
    db, index, _, _ = _setup(frames)
    return faiss, index, query_set(db, index, query_frames, queries)


def child_flat(frames: int, query_frames: int, queries: int, repeats: int) -> dict[str, Any]:
    """faiss ``IndexFlatL2`` on the Eq. 9 rows against our search, interleaved (:func:`paired`).

    Returns both sides' windows and float64 exact costs (to tell an exact tie
    from a different answer), both median seconds per query, the build seconds
    and the bytes the faiss index holds.
    """
    faiss, index, qs = _setup_faiss(frames, query_frames, queries)
    rows = _query_rows(qs)
    flat = faiss.IndexFlatL2(rows.shape[1])
    build_s = _fill(flat, index)
    count = rows.shape[0]
    (ours, theirs), (ours_s, flat_s) = paired(
        [our_query(index, qs), faiss_query(flat, rows)], count, repeats
    )
    return {
        "ours": {"windows": [w for w, _ in ours], "costs": [c for _, c in ours]},
        "flat": {
            "windows": theirs,
            "costs": [_exact_cost(index, qs, i, w) for i, w in enumerate(theirs)],
        },
        "ours_s": ours_s,
        "query_s": flat_s,
        "build_s": build_s,
        "index_bytes": _index_bytes(flat),
    }


def _exact_cost(index: Any, qs: dict[str, torch.Tensor], i: int, window: int) -> float:
    from benchmarks.suites.matching import LAMBDA1, LAMBDA2

    cost = index.exact_costs(
        torch.tensor([window]),
        qs["queries"][i],
        int(qs["lengths"][i]),
        qs["poses"][i],
        LAMBDA1,
        LAMBDA2,
    )
    return float(cost[0])


def child_hnsw(frames: int, query_frames: int, queries: int, repeats: int) -> dict[str, Any]:
    """faiss ``IndexHNSWFlat`` (``M = HNSW_M``) on the Eq. 9 rows, tuned, against our search.

    Every ``EF_SEARCH`` answers all queries once; the smallest reaching
    :data:`RECALL_GOAL` against our exact answers (:func:`pick_ef`) is then timed
    against our search, interleaved (:func:`paired`).

    Returns the build seconds, the bytes the index holds (vectors and graph), the
    chosen ``efSearch``, its recall@1 and both median seconds per query.
    """
    faiss, index, qs = _setup_faiss(frames, query_frames, queries)
    rows = _query_rows(qs)
    hnsw = faiss.IndexHNSWFlat(rows.shape[1], HNSW_M)
    hnsw.hnsw.efConstruction = HNSW_EF_CONSTRUCTION
    build_s = _fill(hnsw, index)
    count = rows.shape[0]
    ours = [our_query(index, qs)(i)[0] for i in range(count)]
    search = faiss_query(hnsw, rows)
    sweep = {}
    for ef in EF_SEARCH:
        hnsw.hnsw.efSearch = ef
        sweep[ef] = [search(i) for i in range(count)]
    ef, recall = pick_ef(ours, sweep)
    hnsw.hnsw.efSearch = ef
    _, (ours_s, hnsw_s) = paired([our_query(index, qs), search], count, repeats)
    return {
        "build_s": build_s,
        "index_bytes": _index_bytes(hnsw),
        "ef_search": ef,
        "recall": recall,
        "ours_s": ours_s,
        "query_s": hnsw_s,
    }


def same_or_tied(ours: dict[str, Any], flat: dict[str, Any]) -> tuple[float, int]:
    """Share of queries where faiss flat picks our window or one of exactly our cost.

    Returns:
        The share and how many of those were exact ties on a different window.
    """
    same = ties = 0
    for a, b, ca, cb in zip(
        ours["windows"], flat["windows"], ours["costs"], flat["costs"], strict=True
    ):
        if a == b:
            same += 1
        elif ca == cb:
            ties += 1
    return (same + ties) / len(ours["windows"]), ties


def pick_ef(ours: list[int], sweep: dict[int, list[int]]) -> tuple[int, float]:
    """Smallest ``efSearch`` reaching :data:`RECALL_GOAL` (else the best one) and its recall@1.

    Args:
        ours: The exact search's window of every query.
        sweep: ``efSearch`` -> HNSW's window of every query.
    """
    best: tuple[int, float] | None = None
    for ef in sorted(sweep):
        hits = sum(a == b for a, b in zip(ours, sweep[ef], strict=True))
        recall = hits / len(ours)
        if recall >= RECALL_GOAL:
            return ef, recall
        if best is None or recall > best[1]:
            best = (ef, recall)
    assert best is not None
    return best


def results(
    label: str, ours: dict[str, Any], index_mib: float, frames: int, settings: dict[str, int]
) -> list[Result]:
    """Run both faiss children (each also times our search, interleaved) and compare.

    Args:
        label: Size label of the figures (``1M``).
        ours: ``build_s`` of our database and index and ``peak_rss_mib`` of our
            matching process (``child_fast``).
        index_mib: Memory of our database and index.
        frames: Database frames.
        settings: The suite's settings at this size.
    """
    from benchmarks.harness import run_child

    kwargs = {"frames": frames, "query_frames": settings["query_frames"],
              "queries": settings["faiss_queries"], "repeats": settings["repeats"]}  # fmt: skip
    flat, flat_rss = run_child("benchmarks.suites.matching_faiss:child_flat", **kwargs)
    hnsw, hnsw_rss = run_child("benchmarks.suites.matching_faiss:child_hnsw", **kwargs)
    share, ties = same_or_tied(flat["ours"], flat["flat"])
    tuned = f"{HNSW} (M={HNSW_M}, efSearch={hnsw['ef_search']})"
    flat_mib, hnsw_mib = flat["index_bytes"] / 2**20, hnsw["index_bytes"] / 2**20
    rss = ours["peak_rss_mib"]
    return [
        Result(f"search_ms_{label}_faiss_flat", "ms", flat["ours_s"] * 1e3, FLAT,
               flat["query_s"] * 1e3),
        Result(f"identical_matches_faiss_flat_{label}", "fraction", share, higher_is_better=True),
        Result(f"exact_ties_faiss_flat_{label}", "queries", float(ties)),
        Result(f"build_s_{label}_faiss_flat", "s", ours["build_s"], FLAT, flat["build_s"]),
        Result(f"index_mib_{label}_faiss_flat", "MiB", index_mib, FLAT, flat_mib),
        Result(f"peak_rss_mib_{label}_faiss_flat", "MiB", rss, FLAT, flat_rss),
        Result(f"search_ms_{label}_faiss_hnsw", "ms", hnsw["ours_s"] * 1e3, tuned,
               hnsw["query_s"] * 1e3),
        Result(f"recall_at_1_faiss_hnsw_{label}", "fraction", hnsw["recall"],
               higher_is_better=True),
        Result(f"m_faiss_hnsw_{label}", "M", float(HNSW_M)),
        Result(f"ef_search_faiss_hnsw_{label}", "efSearch", float(hnsw["ef_search"])),
        Result(f"build_s_{label}_faiss_hnsw", "s", ours["build_s"], HNSW, hnsw["build_s"]),
        Result(f"index_mib_{label}_faiss_hnsw", "MiB", index_mib, HNSW, hnsw_mib),
        Result(f"peak_rss_mib_{label}_faiss_hnsw", "MiB", rss, HNSW, hnsw_rss),
    ]  # fmt: skip
