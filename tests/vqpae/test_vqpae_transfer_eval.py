"""The vqpae.transfer protocol: model-free gait frequency, smoothness, and the protocol itself."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import lightning as L
import pytest
import torch
from skelagnostic_vqpae.aligner import (
    AUTHORS_OPTIMIZER,
    COSINE_SCHEDULER,
    PREVIOUS_DEFAULTS,
    VqpaeAligner,
)
from skelagnostic_vqpae.protocols.transfer import OWN_RATE, UNSCALED, transfer_protocol

from skelagnostic import procedural
from skelagnostic.analysis import acceleration, foot_joints, gait_frequency
from skelagnostic.core.motion import Motion
from skelagnostic.evaluation import MODEL, EvaluationError, held_out


@pytest.mark.parametrize(
    ("kind", "gait"),
    [
        ("biped22", "walk"),
        ("biped22", "run"),
        ("quadruped", "walk"),
        ("quadruped", "trot"),
        ("quadruped", "gallop"),
    ],
)
@pytest.mark.parametrize("fps", [30, 60])
def test_gait_frequency_reads_the_generator_frequency(kind: str, gait: str, fps: int) -> None:
    for seed in (1000, 1001):
        clip, info = procedural.generate(
            kind, gait, seconds=6.0, fps=fps, seed=seed, turn_rate=15.0
        )
        assert gait_frequency(clip) == pytest.approx(info["frequency"], rel=0.01)


def test_gait_frequency_follows_a_slowed_copy() -> None:
    clip, info = procedural.generate("quadruped", "trot", seconds=8.0, fps=60, seed=4)
    for rate in (40.0, 90.0):  # the same frames played slower / faster
        replayed = Motion(clip.skeleton, clip.rotations, clip.root_positions, rate)
        assert gait_frequency(replayed) == pytest.approx(info["frequency"] * rate / 60, rel=0.01)
    explicit, _ = procedural.generate("biped22", "walk", seconds=8.0, fps=30, seed=4, frequency=0.7)
    assert gait_frequency(explicit) == pytest.approx(0.7, rel=0.01)


def test_gait_frequency_of_a_still_pose_is_nan() -> None:
    clip, _ = procedural.generate("biped22", "walk", seconds=3.0, fps=30, seed=0)
    still = Motion(
        clip.skeleton,
        clip.rotations[:1].expand_as(clip.rotations).clone(),
        clip.root_positions[:1].expand_as(clip.root_positions).clone(),
        30,
    )
    assert math.isnan(gait_frequency(still))


def test_feet_are_the_low_end_effectors() -> None:
    biped, _ = procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=0)
    dog, _ = procedural.generate("quadruped", "walk", seconds=2.0, fps=30, seed=0)
    assert len(foot_joints(biped)) == 2 and len(foot_joints(dog)) == 4
    assert all("Hand" not in biped.skeleton.joint_names[j] for j in foot_joints(biped))


def test_acceleration_sees_a_cut() -> None:
    clip, _ = procedural.generate("quadruped", "walk", seconds=4.0, fps=30, seed=0)
    n = clip.num_frames // 2
    rot = torch.cat([clip.rotations[:n], clip.rotations[n + 7 :]])  # a jump of 7 frames
    root = torch.cat(
        [
            clip.root_positions[:n],
            clip.root_positions[n + 7 :] - clip.root_positions[n + 7] + clip.root_positions[n],
        ]
    )
    cut = Motion(clip.skeleton, rot, root, clip.fps)
    mean_smooth, max_smooth = acceleration(clip)
    mean_cut, max_cut = acceleration(cut)
    assert max_cut > 2 * max_smooth and mean_cut > mean_smooth
    assert mean_smooth > 0


@pytest.fixture
def tiny_run(helpers, tmp_path):
    """A VQ-PAE trained a few steps (no quality expected) and its held-out clips."""
    L.seed_everything(0, verbose=False)
    dm = helpers["datamodule"](tmp_path / "cache")
    dm.test_fraction = 0.3
    model = VqpaeAligner(
        num_codes=8,
        kernel_size=7,
        **{
            **PREVIOUS_DEFAULTS,
            "optimizer": {**AUTHORS_OPTIMIZER, "lr": 1e-3},
            "scheduler": {**COSINE_SCHEDULER, "period": 1000},
        },
    )
    helpers["trainer"](tmp_path, 3, validate=False).fit(model, datamodule=dm)
    return model.eval(), held_out(dm)


def test_transfer_protocol_runs_on_a_tiny_model(tiny_run, tmp_path) -> None:
    model, held = tiny_run
    humans = [c for c in held.clips if model.dataset_of(c.skeleton) == 0]
    assert humans, "the test data must hold out a clip of the first character"
    with torch.no_grad():
        out = transfer_protocol(model, held, tmp_path)
    assert [r["clip"] for r in out.rows] == [str(c.name) for c in humans]
    # the source human's own foot skate is a reference row, not a method (issue 50, item 4)
    assert out.methods == [MODEL, UNSCALED, OWN_RATE, "source"]
    for row, clip in zip(out.rows, humans, strict=True):
        assert row["source_hz"] == pytest.approx(gait_frequency(clip))
        assert set(row["values"]["source"]) == {"foot_skate_cm_s", "foot_skate_ratio"}
        for method in (MODEL, UNSCALED, OWN_RATE):
            values = row["values"][method]
            assert set(values) == set(out.metrics)
            assert values["accel_height_per_s2"] > 0
            if math.isfinite(values["output_hz"]):
                expected = 100 * abs(values["output_hz"] - row["source_hz"]) / row["source_hz"]
                assert values["frequency_error_pct"] == pytest.approx(expected)
    for plot in out.plots:
        assert (tmp_path / plot).stat().st_size > 0


def test_transfer_protocol_needs_two_characters(tiny_run, tmp_path) -> None:
    model, held = tiny_run
    dogs_only = type(held)(
        held.split, [c for c in held.clips if model.dataset_of(c.skeleton)], held.datamodule
    )
    with pytest.raises(EvaluationError, match="no held-out clip"):
        transfer_protocol(model, dogs_only, tmp_path)


def test_transfer_protocol_is_registered(vqpae_pm) -> None:
    spec = vqpae_pm.evaluation("vqpae.transfer", "vqpae")
    assert spec.function is transfer_protocol and not spec.default
    assert vqpae_pm.evaluation(None, "vqpae").name == "vqpae.manifold"


@pytest.mark.slow
def test_main_experiment_writes_the_transfer_summary(tmp_path, vqpae_cli, capsys) -> None:
    """``fit model=vqpae experiment=vqpae_main`` with a reduced budget, through the CLI."""
    args = [
        "fit",
        "model=vqpae",
        "experiment=vqpae_main",
        "trainer.max_steps=150",
        "trainer.max_time=00:00:01:30",
    ]
    assert vqpae_cli(args) == 0, capsys.readouterr().err
    (run,) = (tmp_path / "runs" / "vqpae" / "fit").iterdir()
    assert "## Transfer of held-out clips" in (run / "summary.md").read_text()
    transfer = json.loads((run / "vqpae_metrics.json").read_text())["transfer"]
    assert transfer["split"] == "val" and transfer["per_clip"]
    split = json.loads((run / "split.json").read_text())["clips"]
    assert all(split[row["clip"]] == "val" for row in transfer["per_clip"])
    assert all(split[clip] == "train" for clip in transfer["database_clips"])
    assert set(transfer["mean"]) == {MODEL, UNSCALED, OWN_RATE, "source"}
    for suffix in (".gif", ".png"):
        assert (run / f"vqpae_transfer{suffix}").stat().st_size > 0


def test_unscaled_transfer_replays_fixed_windows(tiny_run) -> None:
    from skelagnostic_vqpae.transfer import build_database, replayed_codes, transfer

    from skelagnostic.errors import SkelagnosticError
    from skelagnostic.evaluation import clips_of_split

    model, held = tiny_run
    human = next(c for c in held.clips if model.dataset_of(c.skeleton) == 0)
    dogs = [
        c for c in clips_of_split(held.datamodule, "train") if model.dataset_of(c.skeleton) == 1
    ]
    target = build_database(model, dogs)
    with torch.no_grad():
        result = transfer(model, human, target, scaled=False, replay_seconds=0.5)
    replay = round(0.5 * target.database.fps)
    assert all(s.length == replay for s in result.match.segments)
    assert all(s.out_length == replay for s in result.match.segments[:-1])
    assert result.motion.num_frames == len(result.source)
    # the picture's code strip: per output frame, the code of the dog frame replayed there
    codes = replayed_codes(result, target)
    assert len(codes) == sum(s.out_length for s in result.match.segments)
    for s in result.match.segments:  # same replay speed here: frame for frame
        replayed = target.embeddings[s.clip].code[s.frame : s.frame + s.out_length]
        assert torch.equal(codes[s.start : s.start + s.out_length], replayed)
    with pytest.raises(SkelagnosticError, match="replay_seconds"):
        transfer(model, human, target, scaled=False, replay_seconds=0.0)


def test_main_experiment_composes_a_cpu_budget(vqpae_pm) -> None:
    from skelagnostic.cli.app import compose

    cfg = compose(
        ["model=vqpae", "experiment=vqpae_main", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm
    )
    assert (
        cfg.model.num_codes == 4  # so the characters share codes in the budget (report, 34)
        and cfg.model.reinit_decay == 0.9
        and cfg.model.optimizer.lr == 1e-3
        and cfg.model.pose_mlp == "none"
    )
    assert cfg.data.source == "procedural" and cfg.data.fps == 30 and cfg.threads == 1
    assert cfg.trainer.max_time == "00:00:04:15" and cfg.trainer.max_epochs == -1
    # the settings it was measured with: the previous defaults (vqpae_plus, the paper's head)
    for key, value in PREVIOUS_DEFAULTS.items():
        if key == "scheduler":  # the cosine schedule, at the preset's own period
            assert cfg.model.scheduler._target_ == value["_target_"]
        elif key != "pose_mlp":
            assert cfg.model[key] == value, key
    assert cfg.data.pair_seconds == 0.1
    default = compose(["model=vqpae", "run_dir=/tmp/unused"], plugin_manager=vqpae_pm)
    assert default.model.num_codes == 32 and default.data.fps == 60  # paper-size defaults


def _touchdowns_by_hand(motion: Motion, max_interval: float = 2.0) -> list[float]:
    """Per frame: the mean over the feet of fps / (the stride interval holding the frame)."""
    from skelagnostic.analysis import motion_onsets

    onsets = [list(map(float, o)) for o in motion_onsets(motion)]
    out = []
    for t in range(motion.num_frames):
        rates = [
            motion.fps / (b - a)
            for foot in onsets
            for a, b in itertools.pairwise(foot)
            if a <= t <= b and 0 < b - a <= max_interval * motion.fps
        ]
        out.append(sum(rates) / len(rates) if rates else math.nan)
    return out


def test_touchdown_frequency_equals_the_stride_intervals_counted_by_hand(
    shared_data: Path,
) -> None:
    from skelagnostic.analysis import contact_frequency, touchdown_frequency
    from skelagnostic.io import read_bvh

    walk, _ = procedural.generate("quadruped", "trot", seconds=5.0, fps=30, seed=7)
    human = read_bvh(shared_data / "human" / "lafan1" / "walk4_subject1.bvh")[:1800]
    for motion in (walk, human):
        got = touchdown_frequency(motion)
        expected = torch.tensor(_touchdowns_by_hand(motion), dtype=torch.float32)
        assert torch.isfinite(got).sum() > motion.num_frames // 4
        assert torch.equal(torch.isnan(got), torch.isnan(expected))
        assert torch.allclose(got.nan_to_num(), expected.nan_to_num(), rtol=1e-5)
    # a steady gait: the per-frame rate is the clip's touch-down rate
    assert float(touchdown_frequency(walk).nanmean()) == pytest.approx(
        contact_frequency(walk), rel=0.05
    )
    # a standing pose has no stride
    still = Motion(
        walk.skeleton,
        walk.rotations[:1].expand_as(walk.rotations).clone(),
        walk.root_positions[:1].expand_as(walk.root_positions).clone(),
        30,
    )
    assert bool(torch.isnan(touchdown_frequency(still)).all())


def test_known_frequencies_replace_the_rules_where_given(tiny_run) -> None:
    from skelagnostic_vqpae.transfer import (
        build_database,
        matching_frequency,
        transfer,
        with_known_frequencies,
    )

    from skelagnostic.errors import SkelagnosticError
    from skelagnostic.evaluation import clips_of_split

    model, held = tiny_run
    human = next(c for c in held.clips if model.dataset_of(c.skeleton) == 0)
    dogs = [
        c for c in clips_of_split(held.datamodule, "train") if model.dataset_of(c.skeleton) == 1
    ]
    with torch.no_grad():
        plain = build_database(model, dogs)
        rule = [matching_frequency(e, model.characters[1].pae.window)[0] for e in plain.embeddings]
        known = [torch.full_like(r, float("nan")) for r in rule]
        known[0][: len(known[0]) // 2] = 1.25  # half of the first clip known
        given = build_database(model, dogs, frequencies=known)
        pairs = zip(known, rule, strict=True)
        expected = torch.cat([torch.where(torch.isnan(k), r, k) for k, r in pairs])
        assert torch.equal(given.database.raw("frequency")[:, 0], expected)
        # the same from the built database, without embedding its clips again
        again = with_known_frequencies(model, plain, known)
        assert again.embeddings == plain.embeddings
        for group in ("manifold", "frequency", "pose"):
            assert torch.equal(again.database.raw(group), given.database.raw(group)), group
        # the query: all-NaN keeps the rule, so the transfer is the plain one
        base = transfer(model, human, plain)
        frames = len(base.source)
        same = transfer(model, human, plain, frequency=torch.full((frames,), float("nan")))
        assert torch.equal(same.motion.rotations, base.motion.rotations)
        slow = transfer(model, human, plain, frequency=torch.full((frames,), 0.5))
        assert [s.out_length for s in slow.match.segments] != [
            s.out_length for s in base.match.segments
        ]
        with pytest.raises(SkelagnosticError, match=r"transfer: frequency: 3 frames"):
            transfer(model, human, plain, frequency=torch.ones(3))
        for bad in (0.0, -1.0, float("inf")):
            with pytest.raises(SkelagnosticError, match="must be positive and finite"):
                transfer(model, human, plain, frequency=torch.full((frames,), bad))
        with pytest.raises(SkelagnosticError, match=r"frequencies\[0\]"):
            build_database(model, dogs, frequencies=[torch.ones(2), *known[1:]])
        with pytest.raises(SkelagnosticError, match="frequency tracks"):
            build_database(model, dogs, frequencies=known[:1])


def test_transfer_protocol_reports_the_touchdown_bound(tiny_run, tmp_path) -> None:
    from skelagnostic_vqpae.protocols.rhythm import rhythm_figures
    from skelagnostic_vqpae.transfer import build_database, transfer

    from skelagnostic.analysis import touchdown_frequency
    from skelagnostic.evaluation import clips_of_split

    model, held = tiny_run
    with torch.no_grad():
        out = transfer_protocol(model, held, tmp_path)
    bound = out.extra["touchdown_periods"]
    assert set(bound["per_clip"]) == {r["clip"] for r in out.rows}
    assert 0 < bound["replaced"]["source"] <= 1 and 0 < bound["replaced"]["database"] <= 1
    for key, mean in bound["mean"].items():
        values = [f[key] for f in bound["per_clip"].values() if not math.isnan(f[key])]
        assert mean == pytest.approx(sum(values) / len(values)) if values else math.isnan(mean)
    assert any("touchdown_periods" in note for note in out.notes)
    # the first clip again, by hand: the frequencies from the feet on both sides
    human = next(c for c in held.clips if model.dataset_of(c.skeleton) == 0)
    dogs = [
        c for c in clips_of_split(held.datamodule, "train") if model.dataset_of(c.skeleton) == 1
    ]
    fps = model.hparams["datasets"][model.dataset_names[1]]["fps"]

    def at(m: Motion) -> Motion:
        return m if m.fps == fps else m.resample(fps)

    with torch.no_grad():
        db = build_database(model, dogs, frequencies=[touchdown_frequency(at(d)) for d in dogs])
        made = transfer(model, human, db, frequency=touchdown_frequency(at(human)))
    figures = rhythm_figures(human, made.motion)
    assert bound["per_clip"][str(human.name)] == pytest.approx(figures, nan_ok=True)
