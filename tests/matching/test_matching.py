import math

import pytest
import torch
from _matching_helpers import FPS, cycle_clip, random_clips

from skelagnostic.matching import (
    MatchingError,
    MotionDatabase,
    frequency_scaled_motion_matching,
    motion_matching,
)


def slice_clip(clip: dict[str, torch.Tensor], a: int, b: int) -> dict[str, torch.Tensor]:
    return {name: values[a:b] for name, values in clip.items()}


class TestFindsItself:
    def test_classical_query_cut_from_the_database(self):
        clips = random_clips(5, (80, 120), seed=7)
        db = MotionDatabase.from_clips(clips, fps=FPS)
        query = slice_clip(clips[3], 10, 55)
        result = motion_matching(db, query, 15, initial_pose=clips[3]["pose"][10])
        assert [(s.clip, s.frame, s.length) for s in result.segments] == [
            (3, 10, 15),
            (3, 25, 15),
            (3, 40, 15),
        ]
        assert all(s.cost == 0.0 for s in result.segments)
        # one continuous replay: inertialization changes nothing
        torch.testing.assert_close(result.features["pose"], clips[3]["pose"][10:55])
        start = int(db.clip_starts[3]) + 10
        assert result.source_frames.tolist() == list(range(start, start + 45))

    def test_frequency_scaled_query_cut_from_the_database(self):
        clips = random_clips(5, (80, 120), seed=8)
        db = MotionDatabase.from_clips(clips, fps=FPS)
        query = slice_clip(clips[2], 5, 60)
        result = frequency_scaled_motion_matching(db, query, initial_pose=clips[2]["pose"][5])
        first = result.segments[0]
        assert (first.clip, first.frame, first.cost) == (2, 5, 0.0)
        # consecutive cycles of the same clip follow each other
        for prev, seg in zip(result.segments[:-2], result.segments[1:-1], strict=True):
            assert (seg.clip, seg.frame) == (2, prev.frame + prev.length)
            assert seg.cost == 0.0
        assert sum(s.out_length for s in result.segments) == 55
        assert result.features["manifold"].shape == (55, 3)


class TestFrequencyScaling:
    def test_twice_the_speed_is_matched_by_the_period_term(self):
        # same cycle shape at 1 Hz (period 30) and 2 Hz (period 15): only t(k) differs
        # (15 samples per window: both clips are sampled on whole frames, so they tie)
        clips = [cycle_clip(1.0, 120), cycle_clip(2.0, 120)]
        db = MotionDatabase.from_clips(clips, fps=FPS)
        query = slice_clip(clips[1], 3, 48)
        with_term = frequency_scaled_motion_matching(db, query, pose=None, samples=15)
        assert {s.clip for s in with_term.segments} == {1}
        assert all(s.length == 15 and s.out_length == 15 for s in with_term.segments)
        # without the period term the windows tie and the lowest index (the 1 Hz clip) wins
        without = frequency_scaled_motion_matching(db, query, pose=None, lambda2=0.0, samples=15)
        assert {s.clip for s in without.segments} == {0}
        assert all(s.cost == 0.0 for s in without.segments)
        # ... and its 30-frame cycles are time-warped to the query's 15 frames
        assert all(s.length == 30 and s.out_length == 15 for s in without.segments)
        torch.testing.assert_close(without.features["manifold"], query["manifold"])

    def test_output_is_time_warped_to_the_query_period(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 150)], fps=FPS)  # period 30
        query = cycle_clip(1.5, 40)  # period 20
        result = frequency_scaled_motion_matching(db, query, pose=None, halflife=None)
        seg = result.segments[0]
        assert (seg.length, seg.out_length) == (30, 20)
        expected = db.raw("manifold")[seg.frame : seg.frame + 31 : 3].double()  # every 1.5 frames
        warped = result.features["manifold"][:20:2].double()
        torch.testing.assert_close(warped, expected[:10], atol=1e-6, rtol=0)
        # the query's cycle shape is matched: phase 0 of the query <-> phase 0 in the clip
        assert seg.frame % 30 == 0

    def test_period_ratio_cap(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 120), cycle_clip(2.0, 120)], fps=FPS)
        query = cycle_clip(2.0, 30)
        result = frequency_scaled_motion_matching(
            db, query, pose=None, lambda2=0.0, max_period_ratio=1.5
        )
        assert {s.clip for s in result.segments} == {1}


class TestExactness:
    @pytest.mark.parametrize("seed", range(3))
    def test_sequences_equal_the_naive_scan(self, seed):
        clips = random_clips(10, (50, 120), seed=seed)
        db = MotionDatabase.from_clips(clips, fps=FPS, weights={"pose": 0.7})
        query = random_clips(1, (100, 100), seed=50 + seed)[0]
        fast = frequency_scaled_motion_matching(db, query, samples=20)
        naive = frequency_scaled_motion_matching(db, query, samples=20, search="naive")
        assert fast.segments == naive.segments
        fast = motion_matching(db, query, 12)
        naive = motion_matching(db, query, 12, search="naive")
        assert fast.segments == naive.segments

    def test_no_match_crosses_a_clip_boundary(self):
        clips = random_clips(12, (20, 45), seed=11)
        db = MotionDatabase.from_clips(clips, fps=FPS)
        query = random_clips(1, (150, 150), seed=12)[0]
        for result in (
            frequency_scaled_motion_matching(db, query),
            motion_matching(db, query, 10),
        ):
            for seg in result.segments:
                clip_len = clips[seg.clip]["pose"].shape[0]
                assert seg.frame + seg.length <= clip_len - 1


class TestInertializedOutput:
    def test_transitions_are_continuous(self):
        db = MotionDatabase.from_clips(random_clips(6, (40, 60), seed=21), fps=FPS)
        query = random_clips(1, (80, 80), seed=22)[0]
        hard = motion_matching(db, query, 10, pose=None, halflife=None)
        soft = motion_matching(db, query, 10, pose=None, halflife=0.1)
        assert hard.segments == soft.segments
        cuts = [s.start for s in hard.segments[1:]]
        jump_hard = hard.features["pose"][cuts] - hard.features["pose"][[c - 1 for c in cuts]]
        jump_soft = soft.features["pose"][cuts] - soft.features["pose"][[c - 1 for c in cuts]]
        assert jump_soft.norm(dim=1).sum() < 0.5 * jump_hard.norm(dim=1).sum()
        # before the first transition the output is the database motion itself
        torch.testing.assert_close(soft.features["pose"][:10], hard.features["pose"][:10])

    def test_output_groups(self):
        db = MotionDatabase.from_clips([cycle_clip(1.0, 100)], fps=FPS)
        result = motion_matching(db, cycle_clip(1.0, 20), 10, output=["pose"])
        assert list(result.features) == ["pose"]


class TestBadInput:
    @pytest.fixture
    def db(self) -> MotionDatabase:
        return MotionDatabase.from_clips([cycle_clip(1.0, 100)], fps=FPS)

    def test_query_errors(self, db):
        good = cycle_clip(1.0, 40)
        cases = [
            ({"pose": good["pose"], "frequency": good["frequency"]}, "missing control group"),
            ({**good, "manifold": torch.zeros(40, 3)}, "has 3 dims"),
            (
                {**good, "manifold": good["manifold"].index_fill(0, torch.tensor([7]), math.nan)},
                "NaN",
            ),
            ({**good, "frequency": -good["frequency"]}, "frequency"),
            ({"manifold": good["manifold"]}, "missing frequency group"),
            ({**good, "frequency": good["frequency"][:10]}, "expected 40 frames"),
            ({**good, "manifold": torch.zeros(0, 4)}, "empty"),
        ]
        for query, message in cases:
            with pytest.raises(MatchingError, match=message):
                frequency_scaled_motion_matching(db, query)

    def test_parameter_errors(self, db):
        query = cycle_clip(1.0, 40)
        with pytest.raises(MatchingError, match="replay_length"):
            motion_matching(db, query, 0)
        with pytest.raises(MatchingError, match="search"):
            motion_matching(db, query, 5, search="faiss")
        with pytest.raises(MatchingError, match="halflife"):
            motion_matching(db, query, 5, halflife=0)
        with pytest.raises(MatchingError, match="pose: unknown"):
            motion_matching(db, query, 5, pose="joints")
        with pytest.raises(MatchingError, match="output: unknown"):
            motion_matching(db, query, 5, output=["joints"])
        with pytest.raises(MatchingError, match="initial_pose"):
            motion_matching(db, query, 5, initial_pose=torch.zeros(7))
        with pytest.raises(MatchingError, match="database"):
            motion_matching({"manifold": query["manifold"]}, query, 5)
        with pytest.raises(MatchingError, match="frequency: unknown"):
            frequency_scaled_motion_matching(db, query, frequency="hz")
        with pytest.raises(MatchingError, match="no candidate window"):
            motion_matching(db, query, 500)
