import math

import pytest
import torch

import skelagnostic as sa
from skelagnostic.matching import (
    MatchingError,
    MotionDatabase,
    assemble_motion,
    frequency_scaled_motion_matching,
    motion_matching,
)


def features(motion: sa.Motion, info: dict) -> dict[str, torch.Tensor]:
    phase = 2 * math.pi * info["phase"]
    return {
        "manifold": torch.stack([phase.sin(), phase.cos()], 1),
        "pose": motion.root_local_velocities().reshape(motion.num_frames, -1),
        "frequency": torch.full((motion.num_frames, 1), info["frequency"]),
    }


@pytest.fixture(scope="module")
def library() -> tuple[list[sa.Motion], list[dict], MotionDatabase]:
    gaits = ["walk", "run", "walk", "run"]
    clips = [
        sa.procedural.generate(kind="biped22", gait=g, seconds=4, fps=30, seed=s, scale=1.0)
        for s, g in enumerate(gaits)
    ]
    motions = [m for m, _ in clips]
    feats = [features(m, info) for m, info in clips]
    return motions, feats, MotionDatabase.from_clips(feats, fps=30)


def test_replaying_a_clip_reproduces_it(library):
    motions, feats, db = library
    query = {name: values[10:70] for name, values in feats[1].items()}
    result = frequency_scaled_motion_matching(db, query, initial_pose=query["pose"][0])
    out = assemble_motion(motions, result, db)
    assert out.num_frames == 60 and out.fps == 30
    assert out.skeleton == motions[0].skeleton
    # the segments before the (padded) last one replay clip 1 without a break
    replay = sum(s.out_length for s in result.segments[:-1])
    assert all(s.clip == 1 for s in result.segments[:-1]) and replay > 30
    torch.testing.assert_close(out.rotations[:replay], motions[1].rotations[10 : 10 + replay])
    torch.testing.assert_close(
        out.root_positions[:replay], motions[1].root_positions[10 : 10 + replay]
    )


def test_transitions_are_re_anchored_and_smoothed(library):
    motions, _, db = library
    qm, qi = sa.procedural.generate(kind="biped22", gait="walk", seconds=3, fps=30, seed=42)
    result = motion_matching(db, features(qm, qi), 10)
    soft = assemble_motion(motions, result, db)
    hard = assemble_motion(motions, result, db, halflife=None)
    assert soft.num_frames == hard.num_frames == qm.num_frames
    cuts = [s.start for s in result.segments[1:] if s.start < qm.num_frames - 1]
    # the root never teleports: each segment starts where the previous would have gone
    step = (hard.root_positions[1:] - hard.root_positions[:-1]).norm(dim=-1)
    assert step.max() < 3 * step.median()

    def accel_at_cuts(motion: sa.Motion) -> torch.Tensor:
        pos = motion.global_positions()
        acc = (pos[2:] - 2 * pos[1:-1] + pos[:-2]).norm(dim=-1).amax(-1)
        return acc[[c - 1 for c in cuts]].sum()

    assert accel_at_cuts(soft) < accel_at_cuts(hard)


def test_bad_input(library):
    motions, feats, db = library
    result = motion_matching(db, {"manifold": feats[0]["manifold"][:20]}, 10, pose=None)
    with pytest.raises(MatchingError, match="motions: got 3"):
        assemble_motion(motions[:3], result, db)
    with pytest.raises(MatchingError, match=r"motions\[2\]: has 60 frames"):
        assemble_motion([*motions[:2], motions[2][:60], motions[3]], result, db)
    with pytest.raises(MatchingError, match="fps"):
        assemble_motion(
            [*motions[:3], motions[3].resample(60)[: motions[3].num_frames]], result, db
        )
    with pytest.raises(MatchingError, match="halflife"):
        assemble_motion(motions, result, db, halflife=-1)


@pytest.mark.data
def test_real_clip_finds_itself(lafan_clip):
    motion = sa.read_bvh(lafan_clip)
    velocities = motion.root_local_velocities().reshape(motion.num_frames, -1)
    halves = [motion[:200], motion[200:]]
    db = MotionDatabase.from_clips(
        [{"pose": velocities[:200]}, {"pose": velocities[200:]}], fps=motion.fps
    )
    query = {"pose": velocities[250:310]}
    result = motion_matching(db, query, 15, control="pose", pose=None)
    assert [(s.clip, s.frame) for s in result.segments] == [(1, 50), (1, 65), (1, 80), (1, 95)]
    out = assemble_motion(halves, result, db)
    torch.testing.assert_close(out.rotations, motion.rotations[250:310])
    torch.testing.assert_close(out.root_positions, motion.root_positions[250:310])
