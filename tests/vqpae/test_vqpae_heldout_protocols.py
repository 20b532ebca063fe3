"""Issue #27's VQ-PAE figures: Tables 1 and 2 per character, procedural gaits, contact rhythm.

Each figure is checked against a value computed another way: codes and errors built by
hand, the generator's known stride frequencies, synthetic contact signals.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.embed import ClipEmbedding, embed_clip
from skelagnostic_vqpae.protocols.manifold import manifold_protocol
from skelagnostic_vqpae.protocols.procedural import PROCEDURAL_SEED, procedural_kind
from skelagnostic_vqpae.protocols.rhythm import frequency_head_figures, rhythm_figures
from skelagnostic_vqpae.protocols.tables import phase_oracle_errors, table1, table2
from skelagnostic_vqpae.protocols.transfer import transfer_protocol

from skelagnostic import procedural
from skelagnostic.analysis import (
    LOCOMOTION_SPEED,
    contact_frequency,
    contact_lock,
    contact_onsets,
    gait_frequency,
    gait_phase,
    locomotion_frames,
    locomotion_runs,
    motion_onsets,
)
from skelagnostic.core.motion import Motion
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.evaluation import MODEL, held_out

# --- Table 2 -------------------------------------------------------------------------------


def test_table2_of_hand_made_codes() -> None:
    human = torch.tensor([0, 0, 1, 2, 5, 5])  # codes {0, 1, 2, 5}
    dog = torch.tensor([1, 1, 2, 3, 3, 3, 3])  # codes {1, 2, 3}
    out = table2({"human": human, "dog": dog})
    assert out["characters"] == ["human", "dog"]
    assert out["codes_used"] == {"human": 4, "dog": 3}
    assert out["codes_shared"] == 2 and out["codes_used_any"] == 5  # {1, 2} of {0, 1, 2, 3, 5}
    assert out["shared_codes"] == [1, 2]
    assert out["shared_of_used"] == pytest.approx(2 / 5)
    assert out["shared_of_own"] == {"human": pytest.approx(2 / 4), "dog": pytest.approx(2 / 3)}
    # human: frames 2 and 3 of 6 on {1, 2}; dog: frames 0, 1, 2 of 7
    assert out["frame_share"] == {"human": pytest.approx(2 / 6), "dog": pytest.approx(3 / 7)}
    assert out["frames"] == {"human": 6, "dog": 7}


def test_table2_shared_codes_of_the_training_windows() -> None:
    held = {"human": torch.tensor([0, 0, 1, 2, 5]), "dog": torch.tensor([1, 1, 3])}
    trained = {"human": torch.tensor([0, 1, 2, 2]), "dog": torch.tensor([0, 1, 3, 4])}
    out = table2(held, trained)  # shared on the training windows: {0, 1}
    assert out["codes_shared_training"] == 2
    assert out["frame_share_training_shared"] == {
        "human": pytest.approx(3 / 5),
        "dog": pytest.approx(2 / 3),
    }
    assert out["frame_share"] == {"human": pytest.approx(1 / 5), "dog": pytest.approx(2 / 3)}
    # the paper's figure: training windows on {0, 1}; human 2 of 4, dog 2 of 4
    assert out["shared_codes_training"] == [0, 1]
    assert out["frame_share_training"] == {
        "human": pytest.approx(2 / 4),
        "dog": pytest.approx(2 / 4),
    }
    assert out["frames_training"] == {"human": 4, "dog": 4}
    assert out["frame_share_heldout_on_training_shared"] == out["frame_share_training_shared"]
    assert "codes_shared_training" not in table2(held)
    assert "frame_share_training" not in table2(held)


def _on(codes: list[int], shared: set[int]) -> float:
    """Share of ``codes`` in ``shared``, counted one frame at a time."""
    return sum(1 for c in codes if c in shared) / len(codes)


def test_table2_heldout_share_on_training_codes_does_not_grow_with_the_clips() -> None:
    """Hand-built codes: more held-out clips share more codes, the training codes stay.

    Training windows: the human on codes 0-5, the dog on 3-7, so codes 3, 4, 5 are
    shared. The human's held-out clips sit on 0 (a code only it uses in training) and
    on 3; the dog's first clip on 3 and 6, its second clip on 0. With one dog clip
    the held-out clips share code 3 only; with two also code 0, so ``frame_share``
    of the human jumps from the frames on 3 to every frame, while the share on the
    training-shared codes (3, 4, 5) does not move.
    """
    trained = {
        "human": torch.tensor([0, 1, 2, 3, 4, 5, 5, 5]),
        "dog": torch.tensor([3, 4, 5, 6, 7, 7]),
    }
    human = [0, 0, 0, 3]
    dog_clips = [[3, 3, 6, 6], [0, 0]]
    both = set(range(6)) & set(range(3, 8))
    assert both == {3, 4, 5}
    figures = []
    for n_dog in (1, 2):
        dog = [c for clip in dog_clips[:n_dog] for c in clip]
        out = table2({"human": torch.tensor(human), "dog": torch.tensor(dog)}, trained)
        figures.append(out)
        assert out["codes_shared_training"] == 3 and out["shared_codes_training"] == [3, 4, 5]
        assert out["frame_share_heldout_on_training_shared"] == {
            "human": pytest.approx(_on(human, both)),
            "dog": pytest.approx(_on(dog, both)),
        }
        assert out["frame_share_training"] == {
            name: pytest.approx(_on(c.tolist(), both)) for name, c in trained.items()
        }
    one, two = figures
    assert one["frame_share"]["human"] == pytest.approx(1 / 4)  # only code 3 shared
    assert two["frame_share"]["human"] == pytest.approx(1.0)  # codes 0 and 3 shared
    held_human = [f["frame_share_heldout_on_training_shared"]["human"] for f in figures]
    assert held_human == [pytest.approx(1 / 4)] * 2  # unchanged by the second dog clip
    # the paper's figure: human 5 of 8 windows on {3, 4, 5}, dog 3 of 6
    assert two["frame_share_training"] == {
        "human": pytest.approx(5 / 8),
        "dog": pytest.approx(3 / 6),
    }


def test_table2_against_counting_three_characters() -> None:
    gen = torch.Generator().manual_seed(0)
    codes = {
        name: torch.randint(lo, hi, (n,), generator=gen)
        for name, lo, hi, n in (("a", 0, 12, 400), ("b", 4, 16, 300), ("c", 2, 10, 50))
    }
    out = table2(codes)
    counts = {name: Counter(c.tolist()) for name, c in codes.items()}
    every = [k for k in range(16) if all(counts[n][k] > 0 for n in counts)]
    anyone = [k for k in range(16) if any(counts[n][k] > 0 for n in counts)]
    assert out["codes_shared"] == len(every) and out["codes_used_any"] == len(anyone)
    for name, count in counts.items():
        on_shared = sum(count[k] for k in every)
        assert out["frame_share"][name] == pytest.approx(on_shared / sum(count.values()))
        assert out["codes_used"][name] == len(count)


# --- Table 1 and the locomotion rule ---------------------------------------------------------


def test_table1_weights_frames_and_keeps_locomotion_apart() -> None:
    yes, no = True, False
    errors = {
        "human": [
            # model, mean pose (m), locomotion
            (torch.tensor([0.01, 0.03]), torch.tensor([0.04, 0.04]), torch.tensor([yes, no])),
            (
                torch.tensor([0.02, 0.02, 0.05]),
                torch.tensor([0.1, 0.1, 0.1]),
                torch.tensor([yes, yes, no]),
            ),
        ],
        "dog": [(torch.tensor([0.01]), torch.tensor([0.02]), torch.tensor([no]))],
    }
    out = table1(errors)
    human = out["human"]
    assert human["all"]["model"] == pytest.approx(100 * 0.13 / 5)  # per frame, cm
    assert human["all"]["mean_pose"] == pytest.approx(100 * 0.38 / 5)
    assert human["all"]["frames"] == 5
    assert human["locomotion"]["model"] == pytest.approx(100 * 0.05 / 3)
    assert human["locomotion"]["mean_pose"] == pytest.approx(100 * 0.24 / 3)
    assert human["locomotion"]["ratio"] == pytest.approx(0.05 / 0.24)
    assert out["dog"]["all"]["ratio"] == pytest.approx(0.5)
    assert out["dog"]["locomotion"]["frames"] == 0
    assert math.isnan(out["dog"]["locomotion"]["model"])


def test_locomotion_frames_follow_the_root_speed() -> None:
    clip, _ = procedural.generate("quadruped", "idle", seconds=4.0, fps=30, seed=0)
    height = clip.skeleton.height()
    t = torch.arange(clip.num_frames, dtype=torch.float64) / clip.fps
    speed = 2 * LOCOMOTION_SPEED * height  # twice the threshold after 2 s, still before
    z = torch.where(t < 2.0, torch.zeros_like(t), speed * (t - 2.0))
    root = clip.root_positions.double().clone()
    root[:, 2] = z
    moved = Motion(clip.skeleton, clip.rotations, root, clip.fps)
    loco = locomotion_frames(moved)
    margin = 9  # the centred 0.5 s span reaches 7-8 frames across the start
    assert not loco[: 60 - margin].any() and loco[60 + margin :].all()
    walk, _ = procedural.generate("biped22", "walk", seconds=4.0, fps=30, seed=1)
    assert locomotion_frames(walk).all()
    assert not locomotion_frames(procedural.generate("biped22", "idle", seconds=4.0)[0]).any()


# --- procedural gaits --------------------------------------------------------------------------


def test_procedural_kind_recognises_the_generator_rigs_only() -> None:
    for kind in procedural.KINDS:
        assert procedural_kind(procedural.skeleton(kind, scale=0.0093)) == kind
    rig = procedural.skeleton("biped22")
    turned = Skeleton(  # same joints, rest offsets along another axis (a LaFAN1-like rig)
        rig.joint_names, rig.parents, rig.offsets[:, [1, 2, 0]], name="turned"
    )
    assert procedural_kind(turned) is None


# --- foot contacts -----------------------------------------------------------------------------


def test_contact_onsets_of_a_synthetic_signal() -> None:
    fps, hz = 60.0, 1.3
    t = np.arange(int(8 * fps)) / fps
    # two feet half a cycle apart; each lifts once per cycle and rests on the ground between
    feet = np.stack([np.maximum(np.sin(2 * np.pi * hz * t + p), 0.0) ** 2 for p in (0, np.pi)], 1)
    onsets = contact_onsets(feet, fps, min_lift=0.1)
    for foot in onsets:
        assert np.diff(foot) / fps == pytest.approx(np.full(len(foot) - 1, 1 / hz), abs=1e-3)
    # touch-down where the lifted arch ends: sin(...)^2 falls through 0.25 at phase 5 pi / 6
    assert onsets[0][0] / fps == pytest.approx((5 / 6) / (2 * hz), abs=2e-3)
    # on a raised floor (a step up after 4 s) the touch-downs keep their rhythm
    stepped = feet + np.where(t >= 4.0, 3.0, 0.0)[:, None]
    raised = contact_onsets(stepped, fps, min_lift=0.1)[0]
    assert np.diff(raised[raised / fps > 5.0]) / fps == pytest.approx(1 / hz, abs=1e-3)
    # a foot that barely moves does not step
    assert all(len(o) == 0 for o in contact_onsets(0.01 * feet, fps, min_lift=0.1))


@pytest.fixture(scope="module")
def walks(shared_data):
    """Steady real gaits: a LaFAN1 walk (frames 600-1800) and a MANN dog walk, in metres."""
    from skelagnostic.io import read_bvh

    human = read_bvh(shared_data / "human" / "lafan1" / "walk4_subject1.bvh").to_metres()
    dog = read_bvh(shared_data / "dog" / "mann" / "D1_008_KAN01_001.bvh").to_metres()
    return human[600:1800], dog


def test_contact_frequency_of_real_walks_is_their_gait_frequency(walks) -> None:
    for clip in walks:
        assert contact_frequency(clip) == pytest.approx(gait_frequency(clip), rel=0.1)
        # the same frames played 1.3x faster: 1.3x the touch-downs per second (the local
        # range window is in seconds, so it spans fewer frames: not exactly)
        faster = Motion(clip.skeleton, clip.rotations, clip.root_positions, 1.3 * clip.fps)
        assert contact_frequency(faster) == pytest.approx(1.3 * contact_frequency(clip), rel=0.05)


def test_gait_phase_of_real_walks_advances_at_their_gait_frequency(walks) -> None:
    human, dog = walks
    for clip in (human, dog):  # defined on most locomotion frames, in [0, 1)
        phase, loco = gait_phase(clip), locomotion_frames(clip).numpy()
        finite = np.isfinite(phase)
        assert finite[loco].mean() > 0.85
        assert phase[finite].min() >= 0 and phase[finite].max() < 1
    for clip in (human[620:830], dog):  # steady stretches (the human stops around 560)
        phase = gait_phase(clip)
        finite = np.isfinite(phase)
        # cycles per second over the frames with a phase, against the feet's fore-aft swing
        steps = np.diff(phase)[finite[1:] & finite[:-1]] % 1.0
        rate = steps.sum() / (len(steps) / clip.fps)
        assert rate == pytest.approx(gait_frequency(clip), rel=0.05)


def test_gait_phase_is_undefined_while_the_character_stands(walks) -> None:
    clip = walks[0][620:830]  # 7 s of steady walk, then the same with a stop in the middle
    pause = int(4 * clip.fps)  # 4 s standing on frame 105
    frames = torch.cat([torch.arange(105), torch.full((pause,), 105), torch.arange(105, 210)])
    paused = Motion(clip.skeleton, clip.rotations[frames], clip.root_positions[frames], clip.fps)
    phase, steady = gait_phase(paused), gait_phase(clip)
    assert np.isnan(phase[105 + int(clip.fps) : 105 + pause - int(clip.fps)]).all()
    assert np.isfinite(steady[105 - 30 : 105 + 30]).all()  # walking through, it is defined
    walking = np.isfinite(phase[:60]).mean(), np.isfinite(phase[-60:]).mean()
    assert min(walking) > 0.5


def test_phase_oracle_against_grouping_by_hand() -> None:
    gen = np.random.default_rng(0)
    pose = torch.from_numpy(gen.normal(size=(60, 4, 3)))
    phase = torch.from_numpy(gen.uniform(0, 1, 60))
    phase[:5] = math.nan
    mask = torch.from_numpy(gen.uniform(size=60) < 0.7)
    out = phase_oracle_errors(pose, phase, mask, bins=4)
    rows = [(f, int(4 * float(phase[f]))) for f in range(60) if mask[f] and f >= 5]
    for f, b in rows:
        mean = np.mean([pose[g].numpy() for g, b2 in rows if b2 == b], axis=0)
        expected = np.linalg.norm(pose[f].numpy() - mean, axis=-1).mean()
        assert float(out[f]) == pytest.approx(expected, rel=1e-12)
    evaluated = {f for f, _ in rows}
    assert all(math.isnan(float(out[f])) for f in range(60) if f not in evaluated)
    # one bin: the mean pose of the evaluated frames, the mean-pose baseline's figure
    whole = phase_oracle_errors(pose, phase.nan_to_num(0.5), torch.ones(60, dtype=torch.bool), 1)
    centred = pose - pose.mean(0)
    assert torch.allclose(whole, centred.norm(dim=-1).mean(-1))


def test_table1_reports_the_phase_oracle_on_phased_locomotion_frames() -> None:
    nan, yes, no = math.nan, True, False
    errors = {
        "human": [
            # model, mean pose, locomotion, oracle (NaN: no gait phase)
            (
                torch.tensor([0.02, 0.04, 0.06, 0.08]),
                torch.tensor([0.1, 0.1, 0.2, 0.2]),
                torch.tensor([yes, yes, yes, no]),
                torch.tensor([0.05, nan, 0.1, 0.01]),
            ),
        ],
    }
    loco = table1(errors)["human"]["locomotion"]
    assert loco["phase_oracle_frames"] == 2  # frames 0 and 2 (frame 3 is not locomotion)
    assert loco["phase_oracle"] == pytest.approx(100 * 0.15 / 2)
    assert loco["phased_ratio"] == {
        MODEL: pytest.approx(0.08 / 0.3),
        "phase_oracle": pytest.approx(0.15 / 0.3),
    }
    assert loco["ratio"] == pytest.approx(0.12 / 0.4)  # all locomotion frames, as before
    assert "phase_oracle" not in table1({"h": [e[:3] for e in errors["human"]]})["h"]["locomotion"]


def test_contact_lock_of_hand_made_onsets() -> None:
    source = [np.arange(0.0, 100.0, 10.0), np.arange(5.0, 100.0, 10.0)]
    lagged = [np.arange(2.0, 100.0, 10.0) + 0.5 * k for k in range(4)]  # 4 feet, fixed lags
    assert contact_lock(source, lagged) == pytest.approx(1.0)
    drifting = [np.arange(0.0, 100.0, 12.5)]  # 0.8 of the source's rate: phase walks around
    assert contact_lock(source, drifting) < 0.5
    assert math.isnan(contact_lock([np.array([1.0])], lagged))


def _retimed(clip: Motion, hz: float, target_hz: float) -> Motion:
    """``clip``'s frames played so that its gait frequency ``hz`` becomes ``target_hz``."""
    return Motion(clip.skeleton, clip.rotations, clip.root_positions, clip.fps * target_hz / hz)


def test_rhythm_of_a_dog_following_a_human_walk(walks) -> None:
    human, dog = walks
    source_hz, dog_hz = contact_frequency(human), contact_frequency(dog)
    itself = rhythm_figures(human, human)
    assert itself["contact_rhythm_error_pct"] == 0.0
    # the first foot locks to its own cycles (1), the other to a steady half cycle (less)
    assert itself["contact_lock"] > 0.75 and itself["contact_rhythm_within_10pct"] == 1.0
    follows = rhythm_figures(human, _retimed(dog, dog_hz, source_hz))
    assert follows["contact_rhythm_error_pct"] < 5  # the local range window is in seconds
    assert follows["contact_rhythm_within_10pct"] == 1.0
    expected = 100 * abs(follows["contact_hz"] / source_hz - 1)
    assert follows["contact_rhythm_error_pct"] == pytest.approx(expected)
    rushed = rhythm_figures(human, _retimed(dog, dog_hz, 1.3 * source_hz))
    assert 20 < rushed["contact_rhythm_error_pct"] < 40  # played 30 % too fast
    assert rushed["contact_rhythm_within_10pct"] == 0.0
    drifting = rhythm_figures(human, _retimed(human, 1.0, 1.3))["contact_lock"]
    assert drifting < 0.5 * itself["contact_lock"]
    assert itself["locomotion_rhythm_error_pct"] == 0.0  # over the human's walks only


def test_locomotion_rhythm_counts_only_the_source_walks(walks) -> None:
    walk = walks[0][620:830]  # 7 s of steady walk
    fps, pause = walk.fps, int(4 * walk.fps)
    # the source stands still 4 s in the middle; the output walks on through the pause
    stand = torch.cat([torch.arange(105), torch.full((pause,), 105), torch.arange(105, 210)])
    keep_walking = torch.cat(
        [torch.arange(105), torch.arange(105, 105 + pause) % 210, torch.arange(105, 210)]
    )
    source, output = (
        Motion(walk.skeleton, walk.rotations[f], walk.root_positions[f], fps)
        for f in (stand, keep_walking)
    )
    runs = locomotion_runs(source)
    assert len(runs) == 2
    assert runs[0][1] <= 105 + 0.5 * fps and runs[1][0] >= 105 + pause - 0.5 * fps
    figures = rhythm_figures(source, output)
    assert figures["contact_rhythm_error_pct"] > 30  # the whole clip: the pause counts
    # inside the runs, by hand: touch-downs per second and foot on both sides
    seconds = sum(b - a for a, b in runs) / fps

    def rate(motion: Motion) -> float:
        onsets = motion_onsets(motion)
        inside = sum(((o >= a) & (o < b)).sum() for o in onsets for a, b in runs)
        return inside / len(onsets) / seconds

    expected = 100 * abs(rate(output) / rate(source) - 1)
    assert figures["locomotion_rhythm_error_pct"] == pytest.approx(expected)
    assert figures["locomotion_rhythm_error_pct"] < 10
    assert len(locomotion_runs(source, min_seconds=10.0)) == 0
    nothing = rhythm_figures(source[: int(fps)], output[: int(fps)])  # 1 s: no run
    assert math.isnan(nothing["locomotion_rhythm_error_pct"])
    assert math.isnan(nothing["locomotion_rhythm_within_10pct"])


# --- the frequency head against the feet -------------------------------------------------------


def _constant_head(motion: Motion, hz: float, dataset: str = "dog") -> ClipEmbedding:
    """An embedding of ``motion`` whose frequency head reads ``hz`` on every frame."""
    frames = motion.num_frames
    return ClipEmbedding(
        phase=torch.zeros(frames),
        frequency=torch.full((frames,), hz),
        code=torch.zeros(frames, dtype=torch.long),
        amplitude=torch.zeros(frames, 2),
        manifold=torch.zeros(frames, 1),
        fps=motion.fps,
        dataset=dataset,
    )


def test_frequency_head_figures_on_procedural_gaits_of_known_frequency() -> None:
    """Heads at known ratios of the generator's stride frequency, judged by that frequency.

    The reference is the generator's frequency itself (procedural feet are not grounded,
    so their touch-down rate is not the stride frequency); the idle clip has no
    locomotion run and is left out. Expected: errors 0, 8, 50 (a sub-harmonic) and
    25 %, two of four clips within 10 %.
    """
    cases = [("walk", 0, 1.0), ("trot", 1, 1.08), ("gallop", 2, 0.5), ("walk", 3, 1.25)]
    cases.append(("idle", 4, 1.0))
    clips, embeddings, known = [], [], {}
    for gait, seed, ratio in cases:
        motion, info = procedural.generate("quadruped", gait, seconds=6.0, fps=30, seed=seed)
        motion.name = f"{gait}_{seed}"
        known[motion.name] = float(info["frequency"])
        clips.append(motion)
        embeddings.append(_constant_head(motion, ratio * known[motion.name]))

    def truth(motion: Motion) -> torch.Tensor:
        return torch.full((motion.num_frames,), known[str(motion.name)])

    out = frequency_head_figures(clips, embeddings, reference=truth)
    assert out["tolerance_pct"] == pytest.approx(10.0)
    assert list(out["per_clip"]) == ["walk_0", "trot_1", "gallop_2", "walk_3"]  # no idle
    for gait, seed, ratio in cases[:4]:
        row = out["per_clip"][f"{gait}_{seed}"]
        hz = known[f"{gait}_{seed}"]
        assert row["touchdown_hz"] == pytest.approx(hz)
        assert row["head_hz"] == pytest.approx(ratio * hz, rel=1e-6)
        assert row["error_pct"] == pytest.approx(100 * abs(ratio - 1), abs=1e-4)
        assert row["within"] is (abs(ratio - 1) <= 0.10)
    assert out["characters"] == {
        "dog": {"clips": 4, "within": 2, "without_touchdowns": 0, "share_within": 0.5}
    }
    # the default reference, the feet's touch-downs: procedural feet dip more than once
    # per stride, so a head that reads the true stride frequency is far off there
    default = frequency_head_figures(clips[:1], embeddings[:1])
    (row,) = default["per_clip"].values()
    assert row["touchdown_hz"] > 1.3 * known["walk_0"] and not row["within"]
    with pytest.raises(ValueError, match="1 given for 2 clips"):
        frequency_head_figures(clips[:2], embeddings[:1])


# --- the protocols on a tiny model -------------------------------------------------------------


@pytest.fixture
def tiny(helpers, tmp_path):
    """A VQ-PAE trained a few steps on procedural biped + quadruped (no quality expected)."""
    return helpers["tiny"](tmp_path, 0.3)


def test_manifold_protocol_on_the_training_clips_says_so(tiny, tmp_path) -> None:
    """``evaluate split=train``: Table 1 over the training clips, as the paper measures it."""
    model, held = tiny
    train = held_out(held.datamodule, "train")
    names = sorted(k for k, v in held.datamodule.assigned_splits.items() if v == "train")
    assert train.names == names and not set(names) & set(held.names)
    with torch.no_grad():
        out = manifold_protocol(model, train, tmp_path, procedural_seeds=0)
    assert [r["clip"] for r in out.rows] == train.names
    assert out.extra["num_codes"] == 8
    heads = out.extra["frequency_head"]
    assert set(heads["per_clip"]) <= set(train.names)
    for name, counts in heads["characters"].items():
        rows = [r for r in heads["per_clip"].values() if r["character"] == name]
        assert counts["clips"] == len(rows) and counts["within"] == sum(r["within"] for r in rows)
    assert out.notes[0].startswith(
        "evaluated clips: the training split (clips the model trained on, not held out); "
        "codebook size K = 8"
    )
    for name, figures in out.extra["table1"].items():
        rows = [r for r in out.rows if r["character"] == name]
        assert figures["all"]["frames"] == sum(r["frames"] for r in rows)


def test_manifold_protocol_tables_per_character(tiny, tmp_path) -> None:
    model, held = tiny
    with torch.no_grad():
        out = manifold_protocol(model, held, tmp_path, procedural_seeds=1)
        codes: dict[str, list[int]] = {}
        for clip in held.clips:  # codes again, straight from the encoder
            latent = model.encode(clip)
            name = model.dataset_names[int(latent.extras["dataset"])]
            codes.setdefault(name, []).extend(latent.extras["code"].tolist())
    t2 = out.extra["table2"]
    every = set.intersection(*(set(c) for c in codes.values()))
    for name, c in codes.items():
        assert t2["codes_used"][name] == len(set(c))
        assert t2["frame_share"][name] == pytest.approx(sum(k in every for k in c) / len(c))
    assert t2["codes_shared"] == len(every)
    assert out.extra["overlap"]["overlap"] == pytest.approx(len(every) / 8)  # kept as before
    # Table 1 from the rows: frame-weighted mean of the per-clip figures
    assert "pose_mpjpe_locomotion_cm" in out.metrics
    for name, figures in out.extra["table1"].items():
        rows = [r for r in out.rows if r["character"] == name]
        frames = sum(r["frames"] for r in rows)
        for method in (MODEL, "mean_pose"):
            weighted = sum(r["frames"] * r["values"][method]["pose_mpjpe_cm"] for r in rows)
            assert figures["all"][method] == pytest.approx(weighted / frames, rel=1e-6)
        assert figures["locomotion"]["frames"] == sum(r["locomotion_frames"] for r in rows)
        assert 0 <= figures["locomotion"]["phase_oracle_frames"] <= figures["locomotion"]["frames"]
        clip_mean = np.mean([r["values"][MODEL]["phase_r2"] for r in rows])
        assert out.extra["per_character"][name][MODEL]["phase_r2"] == pytest.approx(clip_mean)
    # held-out procedural gaits: unseen seeds, the generator's frequencies
    gaits = out.extra["procedural"]
    assert gaits["characters"] == {
        "procedural/biped22": "biped22",
        "procedural/quadruped": "quadruped",
    }
    assert len(gaits["clips"]) == 2 + 3  # walk, run; walk, trot, gallop
    assert min(gaits["seeds"]) >= PROCEDURAL_SEED and gaits["note"] is None
    trained_ids = {c.id for s in held.datamodule.sources for c in s.clips()}
    for row in gaits["clips"]:
        assert row["clip"] not in trained_ids
        _, info = procedural.generate(row["kind"], row["gait"], seconds=6.0, seed=row["seed"])
        assert row["true_hz"] == pytest.approx(info["frequency"])
        assert row["frequency_error_pct"] == pytest.approx(
            100 * abs(row["predicted_hz"] - row["true_hz"]) / row["true_hz"]
        )
    clip, _ = procedural.generate("biped22", "walk", seconds=6.0, fps=20, seed=gaits["seeds"][0])
    with torch.no_grad():
        emb = embed_clip(model, clip.convert_units("m"))  # metres, as in training
    first = gaits["clips"][0]
    assert first["gait"] == "walk" and first["kind"] == "biped22"
    assert first["predicted_hz"] == pytest.approx(float(emb.frequency[10:-10].median()))


def test_procedural_gaits_are_absent_for_real_rigs(tiny, tmp_path) -> None:
    model, held = tiny
    spec = model.hparams["datasets"]["procedural/biped22"]
    sk = Skeleton.from_dict(spec["skeleton"])
    spec["skeleton"] = Skeleton(sk.joint_names, sk.parents, sk.offsets[:, [1, 2, 0]]).to_dict()
    with torch.no_grad():
        out = manifold_protocol(model, held, tmp_path, procedural_seeds=1)
    gaits = out.extra["procedural"]
    assert gaits["characters"]["procedural/biped22"] is None
    assert {r["character"] for r in gaits["clips"]} == {"procedural/quadruped"}
    assert (
        "no procedural gaits for procedural/biped22" in gaits["note"] and gaits["note"] in out.notes
    )


def test_transfer_protocol_reports_the_contact_rhythm(tiny, tmp_path) -> None:
    model, held = tiny
    with torch.no_grad():
        out = transfer_protocol(model, held, tmp_path)
    for row in out.rows:
        assert set(row["values"]["source"]) <= {"foot_skate_cm_s", "foot_skate_ratio"}
        for method, values in row["values"].items():
            if method == "source":  # a reference: the source's own foot skate
                continue
            assert values["gait_ratio"] == pytest.approx(values["output_hz"] / row["source_hz"])
            error = values["contact_rhythm_error_pct"]
            if math.isfinite(error):
                assert error == pytest.approx(
                    100 * abs(values["contact_hz"] / row["source_contact_hz"] - 1)
                )
                assert values["contact_rhythm_within_10pct"] == float(error <= 10)
            run_error = values["locomotion_rhythm_error_pct"]
            if math.isfinite(run_error):
                assert values["locomotion_rhythm_within_10pct"] == float(run_error <= 10)


def _turned(clip: Motion, angle: float, shift: tuple[float, float, float]) -> Motion:
    """``clip`` turned by ``angle`` radians about the up (Y) axis and moved by ``shift``."""
    from skelagnostic.core import quaternion as Q

    half = torch.tensor(angle / 2, dtype=torch.float64)
    yaw = torch.stack([half.cos(), torch.zeros(()), half.sin(), torch.zeros(())])
    yaw = yaw.to(clip.dtype).expand(clip.num_frames, 4)
    rotations = clip.rotations.clone()
    rotations[:, 0] = Q.mul(yaw, rotations[:, 0])
    root = Q.rotate(yaw, clip.root_positions) + torch.tensor(shift, dtype=clip.dtype)
    return Motion(clip.skeleton, rotations, root, clip.fps, name=clip.name, units=clip.units)


def test_average_pose_error_ignores_heading_and_place(tiny, tmp_path) -> None:
    """Table 1 compares poses in the root's facing frame: turning a clip changes nothing."""
    model, held = tiny
    turned = type(held)(
        held.split, [_turned(c, 2.1, (3.0, 0.0, -2.0)) for c in held.clips], held.datamodule
    )
    with torch.no_grad():
        before = manifold_protocol(model, held, tmp_path, procedural_seeds=0)
        after = manifold_protocol(model, turned, tmp_path, procedural_seeds=0)
    for a, b in zip(after.rows, before.rows, strict=True):
        for method in (MODEL, "mean_pose"):
            for metric in ("pose_mpjpe_cm", "pose_mpjpe_locomotion_cm"):
                x, y = a["values"][method][metric], b["values"][method][metric]
                assert x == pytest.approx(y, rel=1e-4, abs=1e-4) or (
                    math.isnan(x) and math.isnan(y)
                )
