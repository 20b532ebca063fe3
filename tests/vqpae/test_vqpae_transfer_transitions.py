"""Transfer output: inertialized transitions, and matching periods from the measured phase rate."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip
from skelagnostic_vqpae.transfer import (
    FREQUENCY_TOLERANCE,
    HALFLIFE,
    build_database,
    matching_frequency,
    phase_rate,
    transfer,
)

from skelagnostic import procedural, read_bvh, write_bvh
from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic.matching import MatchResult, MotionDatabase, assemble_motion, cycle_lengths

FPS = 20


def _jumps(motion: Motion) -> torch.Tensor:
    """``[F - 1]`` largest joint displacement (global positions) from each frame to the next."""
    pos = motion.global_positions().double()
    return (pos[1:] - pos[:-1]).norm(dim=-1).amax(-1)


def _shifted(match: MatchResult, database: MotionDatabase, frames: int) -> MatchResult:
    """``match`` with every other replay started ``frames`` later (or earlier) in its clip."""
    segments, source = [], match.source_frames.clone()
    for i, seg in enumerate(match.segments):
        if i % 2:
            lo, hi = database.clip_range(seg.clip)
            shift = frames if seg.frame + seg.length + frames < hi - lo - 1 else -frames
            assert seg.frame + shift >= 0
            source[seg.start : seg.start + seg.out_length] += shift
            seg = dataclasses.replace(seg, frame=seg.frame + shift)
        segments.append(seg)
    return dataclasses.replace(match, segments=segments, source_frames=source)


def test_transitions_jump_no_more_than_the_target_clips(trained: dict, tmp_path: Path) -> None:
    model = trained["model"]
    # dog walks and human walks at one stride frequency: the replays are barely time
    # warped, so the target clips' own frame-to-frame motion is the yardstick
    dogs = [
        procedural.generate("quadruped", "walk", seconds=4.0, fps=FPS, seed=s, frequency=0.8)[0]
        for s in (11, 12, 13)
    ]
    db = build_database(model, dogs)
    within = max(float(_jumps(m).max()) for m in db.motions)
    quarter = round(FPS / 0.8 / 4)  # a quarter of the dogs' stride, in frames
    for seed in (13, 14, 15):
        source, _ = procedural.generate(
            "biped22", "walk", seconds=6.0, fps=FPS, seed=seed, frequency=0.8
        )
        smooth = transfer(model, source, db)
        raw = transfer(model, source, db, halflife=None)
        # the same matching either way: only the splicing differs
        assert [s.frame for s in smooth.match.segments] == [s.frame for s in raw.match.segments]
        cuts = [s.start - 1 for s in smooth.match.segments[1:]]  # jump into a new replay
        assert len(cuts) >= 3
        # the written BVH is what a user gets
        path = tmp_path / f"dog{seed}.bvh"
        write_bvh(smooth.motion, path)
        assert float(_jumps(read_bvh(path))[cuts].max()) <= within, seed
        # the model may replay one stride after another seamlessly (a cycle of a periodic
        # clip); the control does not depend on it: every other replay of the same match
        # started a quarter stride off jumps at every cut when spliced raw, and stays
        # within the clips' own motion when inertialized as transfer does
        forced = _shifted(smooth.match, db.database, quarter)
        hard = assemble_motion(db.motions, forced, db.database, halflife=None)
        soft = assemble_motion(db.motions, forced, db.database, halflife=HALFLIFE)
        assert float(_jumps(hard)[cuts].min()) > 2 * within, seed
        assert float(_jumps(soft)[cuts].max()) <= within, seed


def test_transfer_rejects_a_bad_halflife(trained: dict) -> None:
    model = trained["model"]
    dog, _ = procedural.generate("quadruped", "walk", seconds=3.0, fps=FPS, seed=2)
    source, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=FPS, seed=3)
    with pytest.raises(SkelagnosticError, match="halflife"):
        transfer(model, source, build_database(model, [dog]), halflife=0.0)


def _embedding(phase: torch.Tensor, frequency: torch.Tensor, fps: float) -> ClipEmbedding:
    frames = phase.numel()
    return ClipEmbedding(
        phase,
        frequency,
        torch.zeros(frames, dtype=torch.long),
        torch.zeros(frames, 4),
        torch.zeros(frames, 2),
        fps,
        "x",
    )


def test_phase_rate_unwraps_the_pivot_phase() -> None:
    fps, hz = 30.0, 1.7
    t = torch.arange(90) / fps
    phase = torch.remainder(hz * t + 0.4, 1.0) - 0.5  # wraps every cycle
    assert torch.allclose(phase_rate(phase, fps, 31), torch.full((90,), hz, dtype=torch.float64))
    backwards = phase_rate(-phase, fps, 31)
    assert torch.allclose(backwards, torch.full((90,), -hz, dtype=torch.float64))
    assert phase_rate(phase[:1], fps, 31).tolist() == [0.0]
    with pytest.raises(SkelagnosticError, match="window"):
        phase_rate(phase, fps, 1)


def test_matching_frequency_keeps_the_head_within_the_tolerance() -> None:
    fps, hz = 30.0, 2.0
    phase = torch.remainder(hz * torch.arange(60) / fps, 1.0) - 0.5
    close = torch.full((60,), hz * (1 + FREQUENCY_TOLERANCE / 2))
    used, replaced = matching_frequency(_embedding(phase, close, fps), 31)
    assert not bool(replaced.any()) and torch.equal(used, close)


def test_matching_frequency_takes_the_phase_rate_beyond_the_tolerance() -> None:
    fps, hz = 30.0, 2.0
    phase = torch.remainder(hz * torch.arange(60) / fps, 1.0) - 0.5
    head = torch.full((60,), 1.0)  # the head says 1 Hz, the phase turns at 2 Hz
    head[:10] = hz  # except at the start, where they agree
    used, replaced = matching_frequency(_embedding(phase, head, fps), 31)
    assert not bool(replaced[:10].any()) and bool(replaced[10:].all())
    assert torch.allclose(used[10:], torch.full((50,), hz))
    # None: the head's estimates as they are (the paper); a still phase keeps the head's too
    assert torch.equal(matching_frequency(_embedding(phase, head, fps), 31, None)[0], head)
    still, replaced = matching_frequency(_embedding(torch.zeros(60), head, fps), 31)
    assert not bool(replaced.any()) and torch.equal(still, head)
    with pytest.raises(SkelagnosticError, match="frequency_tolerance"):
        matching_frequency(_embedding(phase, head, fps), 31, 0.0)


def test_transfer_periods_follow_the_rule(trained: dict) -> None:
    model = trained["model"]
    dogs = [
        procedural.generate("quadruped", g, seconds=3.0, fps=FPS, seed=5)[0]
        for g in ("walk", "trot")
    ]
    source, _ = procedural.generate("biped22", "run", seconds=3.0, fps=FPS, seed=6)
    emb = embed_clip(model, source)
    window = int(model.characters[0].pae.window)
    chosen = []
    for tolerance in (None, 1e-6):  # the head's periods; the measured phase rate's
        freq, _ = matching_frequency(emb, window, tolerance)
        db = build_database(model, dogs, frequency_tolerance=tolerance)
        result = transfer(model, source, db, frequency_tolerance=tolerance, halflife=None)
        periods = cycle_lengths(freq, FPS)
        lengths = [s.out_length for s in result.match.segments[:-1]]
        assert lengths == [int(periods[s.start]) for s in result.match.segments[:-1]]
        chosen.append(periods)
    assert not torch.equal(chosen[0], chosen[1])  # the two rules differ on this clip


def test_transfer_reuses_a_given_embedding(trained: dict) -> None:
    model = trained["model"]
    dogs = [procedural.generate("quadruped", "walk", seconds=3.0, fps=FPS, seed=7)[0]]
    source, _ = procedural.generate("biped22", "walk", seconds=3.0, fps=FPS, seed=8)
    db = build_database(model, dogs)
    fresh = transfer(model, source, db)
    emb = embed_clip(model, source)
    reused = transfer(model, source, db, embedding=emb)
    assert reused.source is emb  # not embedded again
    assert torch.equal(reused.motion.rotations, fresh.motion.rotations)
    assert torch.equal(reused.motion.root_positions, fresh.motion.root_positions)
    # the embedding of another character's clip is refused
    with pytest.raises(SkelagnosticError, match="embedding is of character"):
        transfer(model, source, db, embedding=db.embeddings[0])
