import pytest
import torch
from _matching_helpers import FPS, cycle_clip, random_clips

from skelagnostic.matching import MatchingError, MotionDatabase, WindowIndex, cycle_lengths
from skelagnostic.matching.windows import sample_frames


class TestCycleLengths:
    def test_steady_frequency_gives_the_period(self):
        assert cycle_lengths(torch.full((60,), 2.0), FPS)[:30].tolist() == [15] * 30
        assert cycle_lengths(torch.full((90,), 1.0), FPS)[0] == 30

    def test_variable_frequency(self):
        freq = torch.tensor([3.0] * 5 + [6.0] * 20)  # 0.1 then 0.2 cycles per frame
        periods = cycle_lengths(freq, FPS)
        assert periods[0] == 5 + 3  # 0.5 cycle in 5 frames, then 3 frames of 0.2 (0.6)
        assert periods[5] == 5

    def test_database_windows_stop_at_the_clip_end(self):
        freq = torch.full((40,), 3.0)  # period 10
        ends = torch.tensor([20] * 20 + [40] * 20)
        periods = cycle_lengths(freq, FPS, ends)
        # window k..k+9 plus its continuation k+10 must be in the clip: k <= 9
        assert periods[:10].tolist() == [10] * 10
        assert periods[10:20].tolist() == [0] * 10
        assert periods[20:30].tolist() == [10] * 10

    def test_query_tail_is_extrapolated_with_the_last_frequency(self):
        periods = cycle_lengths(torch.full((12,), 3.0), FPS)
        assert periods.tolist() == [10] * 12

    def test_bad_frequencies(self):
        with pytest.raises(MatchingError, match="frequency"):
            cycle_lengths(torch.tensor([1.0, -1.0]), FPS)
        with pytest.raises(MatchingError, match="never completes"):
            cycle_lengths(torch.tensor([1.0, 0.0]), FPS)


class TestSampleFrames:
    def test_integer_positions_are_exact_and_between_is_linear(self):
        values = torch.arange(20.0)[:, None] * torch.tensor([[1.0, -2.0]])
        out = sample_frames(values, torch.tensor([3]), torch.tensor([4]), 8, 9, torch.tensor([19]))
        expected = 3 + torch.arange(9, dtype=torch.float64) * 0.5
        torch.testing.assert_close(out[0, :, 0], expected)
        torch.testing.assert_close(out[0, :, 1], -2 * expected)

    def test_reads_are_clamped_to_last(self):
        values = torch.arange(10.0)[:, None]
        out = sample_frames(values, torch.tensor([8]), torch.tensor([4]), 4, 4, torch.tensor([9]))
        assert out[0, :, 0].tolist() == [8.0, 9.0, 9.0, 9.0]


def build(db: MotionDatabase, **kwargs) -> WindowIndex:
    return WindowIndex.build(db, ["manifold"], "pose", **kwargs)


class TestWindowIndex:
    def test_windows_never_cross_a_clip_boundary(self):
        db = MotionDatabase.from_clips(random_clips(6, (15, 40), seed=3), fps=FPS)
        for index in (build(db, frequency="frequency"), build(db, length=7)):
            clips, local = db.locate(index.starts)
            clip_len = db.clip_starts[clips + 1] - db.clip_starts[clips]
            # the continuation frame start + length is still in the same clip
            assert bool((local + index.lengths <= clip_len - 1).all())
            assert index.num_windows > 0 and index.nbytes > 0

    def test_every_valid_window_is_listed(self):
        db = MotionDatabase.from_clips([cycle_clip(3.0, 25), cycle_clip(3.0, 12)], fps=FPS)
        index = build(db, frequency="frequency", samples=10)
        # clip 0: 0..14 (continuation 10..24); clip 1 (frames 25..36): 25, 26
        assert index.starts.tolist() == [*range(15), 25, 26]
        assert index.lengths.tolist() == [10] * 17

    @pytest.mark.parametrize("seed", [0, 1, 2])
    @pytest.mark.parametrize("basis_size", [1, 4, 64])
    def test_lower_bounds_never_exceed_the_exact_cost(self, seed, basis_size):
        db = MotionDatabase.from_clips(random_clips(5, (30, 60), seed=seed), fps=FPS)
        index = build(db, frequency="frequency", samples=12, basis_size=basis_size)
        gen = torch.Generator().manual_seed(seed)
        queries = torch.randn(3, 12 * 3, generator=gen, dtype=torch.float64)
        lengths = torch.tensor([8, 13, 20])
        poses = torch.randn(3, 5, generator=gen, dtype=torch.float64)
        bounds = index.lower_bounds(queries, lengths, poses, 0.5, 1.0)
        everything = torch.arange(index.num_windows)
        for b in range(3):
            exact = index.exact_costs(everything, queries[b], int(lengths[b]), poses[b], 0.5, 1.0)
            assert bool((bounds[b].double() <= exact).all())

    @pytest.mark.parametrize("seed", range(4))
    def test_fast_search_equals_the_naive_scan(self, seed):
        db = MotionDatabase.from_clips(random_clips(8, (40, 90), seed=seed), fps=FPS)
        index = build(db, frequency="frequency", samples=15, basis_size=8)
        gen = torch.Generator().manual_seed(100 + seed)
        queries = torch.randn(6, 15, 3, generator=gen)
        lengths = torch.randint(8, 16, (6,), generator=gen)
        poses = torch.randn(6, 5, generator=gen)
        for kwargs in ({}, {"max_period_ratio": 1.5}, {"lambda_pose": 0.0, "lambda_period": 0.0}):
            fast = index.search(queries, lengths, poses, **kwargs)
            naive = index.search(queries, lengths, poses, method="naive", **kwargs)
            assert torch.equal(fast[0], naive[0])
            assert torch.equal(fast[1], naive[1])
        no_pose = index.search(queries, lengths)
        assert torch.equal(no_pose[0], index.search(queries, lengths, method="naive")[0])

    def test_bound_prunes_most_windows_on_smooth_features(self):
        clips = [cycle_clip(hz, 300, phase0=hz / 7) for hz in (0.8, 1.1, 1.5, 2.0, 2.6)]
        db = MotionDatabase.from_clips(clips, fps=FPS)
        index = build(db, frequency="frequency", basis_size=8)
        query = sample_frames(
            index.control, index.starts[[700]], index.lengths[[700]], 30, 30,
            index.starts[[700]] + index.lengths[[700]],
        ).reshape(1, -1)  # fmt: skip
        pose = index.pose[index.starts[[700]]].double()
        bounds = index.lower_bounds(query, index.lengths[[700]], pose, 0.5, 1.0)[0]
        everything = torch.arange(index.num_windows)
        exact = index.exact_costs(everything, query[0], int(index.lengths[700]), pose[0], 0.5, 1.0)
        candidates = int((bounds <= exact.min()).sum())
        assert 1 <= candidates < 0.05 * index.num_windows

    def test_ties_go_to_the_lowest_window(self):
        clip = cycle_clip(2.0, 90)  # every 15 frames the features repeat exactly
        for name in clip:
            clip[name] = torch.cat([clip[name][:15]] * 6)
        db = MotionDatabase.from_clips([clip], fps=FPS)
        index = build(db, frequency="frequency", samples=15)
        window = sample_frames(
            index.control, torch.tensor([30]), torch.tensor([15]), 15, 15, torch.tensor([45])
        ).reshape(1, -1)
        for method in ("fast", "naive"):
            ids, cost = index.search(window, torch.tensor([15]), method=method)
            assert int(index.starts[ids[0]]) == 0
            assert float(cost[0]) == 0.0

    def test_period_ratio_cap_can_exclude_everything(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 90)], fps=FPS)  # period 30
        index = build(db, frequency="frequency", samples=10)
        with pytest.raises(MatchingError, match="max_period_ratio"):
            index.search(torch.zeros(1, 10 * 4), torch.tensor([10]), max_period_ratio=2.0)

    def test_bad_arguments(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 90)], fps=FPS)
        with pytest.raises(MatchingError, match="exactly one"):
            build(db)
        with pytest.raises(MatchingError, match="'nope'"):
            WindowIndex.build(db, ["nope"], length=3)
        with pytest.raises(MatchingError, match="1 channel"):
            build(db, frequency="manifold")
        with pytest.raises(MatchingError, match="no candidate window"):
            build(db, length=200)
        with pytest.raises(MatchingError, match="length"):
            build(db, length=0)
        index = build(db, length=5)
        with pytest.raises(MatchingError, match="method"):
            index.search(torch.zeros(1, 20), torch.tensor([5]), method="approximate")
        with pytest.raises(MatchingError, match="start_pose"):
            index.search(torch.zeros(1, 20), torch.tensor([5]), torch.zeros(1, 2))
        with pytest.raises(MatchingError, match="query_lengths"):
            index.search(torch.zeros(2, 20), torch.tensor([5]))
        with pytest.raises(MatchingError, match="query_lengths"):
            index.search(torch.zeros(1, 20), torch.tensor([0]))
        with pytest.raises(MatchingError, match=r"queries: expected \[B, 5, 4\]"):
            index.search(torch.zeros(1, 7), torch.tensor([5]))
        with pytest.raises(MatchingError, match="NaN"):
            index.search(torch.full((1, 20), float("nan")), torch.tensor([5]))
        with pytest.raises(MatchingError, match="start_pose: holds NaN"):
            index.search(torch.zeros(1, 20), torch.tensor([5]), torch.full((1, 3), float("inf")))

    def test_cached_on_the_database(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 90)], fps=FPS)
        first = db.window_index("manifold", "pose", frequency="frequency")
        assert db.window_index(["manifold"], "pose", frequency="frequency") is first
        assert first.samples == 30  # round(fps) by default
        assert db.window_index("manifold", "pose", length=10).samples == 10


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_matches_cpu():
    clips = random_clips(4, (40, 60), seed=5)
    cpu = MotionDatabase.from_clips(clips, fps=FPS)
    gpu = cpu.to("cuda")
    queries = torch.randn(3, 30 * 3, generator=torch.Generator().manual_seed(0))
    lengths = torch.tensor([10, 20, 30])
    a = cpu.window_index("manifold", "pose", frequency="frequency").search(queries, lengths)
    b = gpu.window_index("manifold", "pose", frequency="frequency").search(queries.cuda(), lengths)
    assert torch.equal(a[0], b[0].cpu())
