"""The matching suite's faiss baselines: same windows and costs, skipped when faiss is absent."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from benchmarks.suites import matching, matching_faiss  # noqa: E402

faiss = pytest.importorskip("faiss", reason="faiss-cpu (the bench extra) is not installed")


@pytest.fixture(scope="module")
def database() -> tuple[object, object, dict[str, torch.Tensor]]:
    db, index, _, _ = matching._setup(20_000)
    return db, index, matching_faiss.query_set(db, index, 300, 12)


def test_faiss_rows_give_eq9_costs(database: tuple) -> None:
    """A faiss row's squared distance to a query row is the exact cost of that window."""
    _, index, qs = database
    rows = matching_faiss._rows(index, 100, 164).double()
    query = matching_faiss._query_rows(qs)[3].double()
    exact = index.exact_costs(
        torch.arange(100, 164),
        qs["queries"][3],
        int(qs["lengths"][3]),
        qs["poses"][3],
        matching.LAMBDA1,
        matching.LAMBDA2,
    )
    torch.testing.assert_close((rows - query).square().sum(1), exact, rtol=1e-5, atol=1e-5)


def test_faiss_flat_picks_our_windows_and_hnsw_is_scored_against_them(database: tuple) -> None:
    _, index, qs = database
    torch.set_num_threads(1)
    rows = matching_faiss._query_rows(qs)
    flat = faiss.IndexFlatL2(rows.shape[1])
    matching_faiss._fill(flat, index)
    assert flat.ntotal == index.num_windows
    assert matching_faiss._index_bytes(flat) == index.num_windows * 631 * 4
    count = rows.shape[0]
    searches = [matching_faiss.our_query(index, qs), matching_faiss.faiss_query(flat, rows)]
    (ours, labels), seconds = matching_faiss.paired(searches, count, repeats=2)
    assert len(ours) == len(labels) == count and all(s > 0 for s in seconds)
    costs = [matching_faiss._exact_cost(index, qs, i, w) for i, w in enumerate(labels)]
    assert costs == pytest.approx([c for _, c in ours], rel=1e-12)
    mine = {"windows": [w for w, _ in ours], "costs": [c for _, c in ours]}
    share, ties = matching_faiss.same_or_tied(mine, {"windows": labels, "costs": costs})
    assert share == 1.0 and ties == 0
    assert labels == mine["windows"]
    hnsw = faiss.IndexHNSWFlat(rows.shape[1], 8)
    matching_faiss._fill(hnsw, index)
    assert matching_faiss._index_bytes(hnsw) > matching_faiss._index_bytes(flat)
    search = matching_faiss.faiss_query(hnsw, rows)
    hnsw.hnsw.efSearch = 2048
    ef, recall = matching_faiss.pick_ef(mine["windows"], {2048: [search(i) for i in range(count)]})
    assert ef == 2048 and recall >= 0.9


def test_same_or_tied_counts_exact_ties_only() -> None:
    ours = {"windows": [1, 2, 3, 4], "costs": [0.5, 1.0, 2.0, 3.0]}
    theirs = {"windows": [1, 7, 8, 4], "costs": [0.5, 1.0, 2.0 + 1e-12, 3.0]}
    assert matching_faiss.same_or_tied(ours, theirs) == (0.75, 1)


def test_pick_ef_takes_the_smallest_reaching_the_goal_else_the_best() -> None:
    ours = list(range(100))

    def miss(k: int) -> list[int]:
        return [-1] * k + list(range(k, 100))

    assert matching_faiss.pick_ef(ours, {64: miss(0), 16: miss(5), 32: miss(1)}) == (32, 0.99)
    assert matching_faiss.pick_ef(ours, {16: miss(9), 32: miss(3), 64: miss(4)}) == (32, 0.97)


@pytest.mark.slow
def test_suite_skips_faiss_with_a_reason_when_missing(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "faiss", None)  # import faiss -> ImportError
    assert "faiss-cpu is not installed" in (matching_faiss.faiss_missing() or "")
    results = matching.run("smoke")
    assert "faiss baselines skipped: faiss-cpu is not installed" in capsys.readouterr().out
    names = [r.name for r in results]
    assert "query_ms_10k" in names and not any("faiss" in n for n in names)
