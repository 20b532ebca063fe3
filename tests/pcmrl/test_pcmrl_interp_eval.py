"""PC-MRL Table 1 protocol (interp.evaluation): reference values and pcmrl.interpolation."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import lightning as L
import numpy as np
import pytest
import torch
from skelagnostic_pcmrl.evaluation import interpolation_protocol
from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
from skelagnostic_pcmrl.interp.evaluation import evaluate, format_table, position_stats, windows

from skelagnostic import Motion, procedural
from skelagnostic.baselines import lerp_slerp
from skelagnostic.core import quaternion as Q
from skelagnostic.evaluation import EvaluationError, HeldOut, held_out

#: The foot-skate figures every motion protocol reports beside its own (issue 50, item 4).
SKATE = {"foot_skate_cm_s", "foot_skate_ratio"}


def _clips() -> list[Motion]:
    out = []
    for seed, gait in ((5, "walk"), (6, "run")):
        motion, _ = procedural.generate("biped31", gait, seconds=2.2, fps=30, seed=seed)
        out.append(motion.convert_units("m"))
    return out


def test_oracle_scores_zero_and_lerp_matches_a_direct_computation() -> None:
    clips = _clips()
    report = evaluate(
        {"oracle": lambda m, k: m, "LERP": lerp_slerp}, clips, window=32, stride=16, gaps=(5, 15)
    )
    assert report["protocol"]["windows"] == len(windows(clips, 32, 16)) == 6
    for gap in ("5", "15"):
        oracle = dict(report["results"]["oracle"][gap])
        skate = {k: oracle.pop(k) for k in SKATE}  # the truth's own skate: the oracle is it
        assert set(oracle) == {f"{p}{m}" for p in ("", "lafan1_") for m in ("l2p", "l2q", "npss")}
        assert all(v == pytest.approx(0.0, abs=1e-12) for v in oracle.values())
        assert skate["foot_skate_cm_s"] >= 0 and 0 <= skate["foot_skate_ratio"] <= 1
        assert report["results"]["LERP"][gap]["l2p"] > 0
        assert report["results"]["LERP"][gap]["lafan1_l2p"] > 0
    # L2P of LERP at gap 15 by hand: centred positions, z-scored with the windows' stats,
    # L2 norm per non-key frame, mean over frames
    wins = windows(clips, 32, 16)
    mean, std = position_stats(wins)
    keys = [0, 15, 30, 31]
    errs = []
    for w in wins:
        pred = lerp_slerp(w, keys).double()
        centre = w.double().root_positions.mean(0).clone()
        centre[1] = 0.0
        a = ((pred.global_positions() - centre).flatten(1) - mean) / std
        b = ((w.double().global_positions() - centre).flatten(1) - mean) / std
        per_frame = (a - b).norm(dim=-1)
        errs.append(per_frame[[t for t in range(32) if t not in keys]])
    expected = float(torch.cat(errs).mean())
    assert report["results"]["LERP"]["15"]["lafan1_l2p"] == pytest.approx(expected, rel=1e-6)
    # longer gaps are harder for LERP
    assert report["results"]["LERP"]["15"]["l2p"] > report["results"]["LERP"]["5"]["l2p"]
    assert (
        report["results"]["LERP"]["15"]["lafan1_l2p"] > report["results"]["LERP"]["5"]["lafan1_l2p"]
    )
    table = format_table(report)
    assert table.splitlines()[0].startswith("| Method | L2P 5 | L2P 15 | L2Q 5")
    assert "| oracle | 0.0000" in table


def _tiny_trained(tmp_path: Path) -> PcmrlInterpAligner:
    """A stage-2 model of the procedural biped31 (CMU-31) hierarchy after 2 steps."""
    L.seed_everything(0)
    dm = PcmrlInterpDataModule(fps=30, window=32, batch_size=4, samples_per_epoch=8)
    model = PcmrlInterpAligner(
        dim=16,
        heads=2,
        layers=1,
        ff_mult=2,
        max_relative=16,
        scheduler={"_target_": "skelagnostic.aligners.optim.linear_warmup", "steps": 1},
    )
    trainer = L.Trainer(
        max_steps=2,
        accelerator="cpu",
        logger=False,
        default_root_dir=tmp_path,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
    )
    trainer.fit(model, datamodule=dm)
    return model.eval()


def test_interpolation_protocol_rows_beside_lerp(tmp_path: Path) -> None:
    model = _tiny_trained(tmp_path)
    clips = _clips()
    clips[0].name, clips[1].name = "walk", "run"
    short = clips[1][:20]
    short.name = "short"
    held = HeldOut("test", [*clips, short], SimpleNamespace(window=32))
    with torch.no_grad():
        out = interpolation_protocol(model, held, tmp_path)
    assert [r["clip"] for r in out.rows] == ["walk", "run"]
    assert any("short" in n for n in out.notes)
    assert out.methods == ["model", "lerp_slerp", "ground_truth"]
    assert set(out.metrics) == {
        f"{p}{k}@{g}" for p in ("", "lafan1_") for k in ("l2p", "l2q", "npss") for g in (5, 15, 30)
    } | {f"{k}@{g}" for k in SKATE for g in (5, 15, 30)}
    # the same figures as the Table 1 function on the clip, with the shared statistics
    stats = position_stats(windows(clips, 32, 16))
    direct = evaluate({"LERP": lerp_slerp}, clips[:1], 32, 16, stats=stats)
    for key in ("l2p", "npss", "lafan1_l2p"):
        assert out.rows[0]["values"]["lerp_slerp"][f"{key}@15"] == pytest.approx(
            direct["results"]["LERP"]["15"][key]
        )
    for values in out.rows[1]["values"].values():
        assert all(v >= 0 and v == v for v in values.values())


def test_evaluate_needs_long_enough_clips() -> None:
    from skelagnostic.errors import SkelagnosticError

    with pytest.raises(SkelagnosticError, match="no clip has 128 frames"):
        evaluate({"LERP": lerp_slerp}, _clips(), window=128)


def test_authors_metrics_of_lerp_by_hand() -> None:
    """The protocol's authors' L2P of LERP: keys pasted, metres, mean over all frames."""
    from skelagnostic.errors import SkelagnosticError

    clips = _clips()
    report = evaluate(
        {"LERP": lerp_slerp}, clips, window=32, stride=16, gaps=(15,), metrics=("authors",)
    )
    assert set(report["results"]["LERP"]["15"]) - SKATE == {"l2p", "l2q", "npss"}
    wins = windows(clips, 32, 16)
    keys = [0, 15, 30, 31]
    err = []
    for w in wins:
        pred = lerp_slerp(w, keys).to_metres().double().global_positions()
        err.append((pred - w.to_metres().double().global_positions()).flatten(1).norm(dim=-1))
    assert report["results"]["LERP"]["15"]["l2p"] == pytest.approx(float(torch.cat(err).mean()))
    assert report["results"]["LERP"]["15"]["l2p"] > 0
    assert "| LERP |" in format_table(report)
    with pytest.raises(SkelagnosticError, match="metrics"):
        evaluate({"LERP": lerp_slerp}, clips, window=32, metrics=("paper",))


def _centred(motion: Motion) -> np.ndarray:
    """``[T, J*3]`` global positions minus the mean horizontal root position (numpy)."""
    pos = motion.double().global_positions().numpy()
    centre = motion.double().root_positions.numpy().mean(axis=0)
    centre[motion.skeleton.up_index] = 0.0
    return (pos - centre).reshape(len(pos), -1)


def test_lafan1_l2p_is_normalised_with_the_training_clips(tmp_path: Path) -> None:
    """lafan1_l2p z-scores with the run's training clips (the benchmark's subjects 1-4)."""
    model = _tiny_trained(tmp_path)
    dm = PcmrlInterpDataModule(
        fps=30, window=32, val_fraction=0.0, test_fraction=0.25, cache_dir=tmp_path / "c"
    )
    held = held_out(dm)
    splits = list(dm.assigned_splits.values())
    assert held.split == "test" and len(held.clips) == splits.count("test") >= 1
    with torch.no_grad():
        out = interpolation_protocol(model, held, tmp_path)
    assert any("training clips" in n for n in out.notes)
    # by hand: statistics of the training clips' 32-frame windows every 16 frames
    train = [
        source.load(ref).resample(30.0)
        for source in dm.sources
        for ref in source.clips()
        if dm.assigned_splits[ref.id] == "train"
    ]
    assert len(train) == splits.count("train") >= 2
    flat = np.concatenate(
        [_centred(m[s : s + 32]) for m in train for s in range(0, m.num_frames - 31, 16)]
    )
    mean, std = flat.mean(axis=0), np.maximum(flat.std(axis=0, ddof=1), 1e-3)
    clip = held.clips[0]
    keys = [0, 15, 30, 31]
    errors = []
    for start in range(0, clip.num_frames - 31, 16):
        w = clip[start : start + 32]
        pred = lerp_slerp(w, keys).double().global_positions().numpy().reshape(32, -1)
        centre = w.double().root_positions.numpy().mean(axis=0)
        centre[w.skeleton.up_index] = 0.0
        pred = pred - np.tile(centre, w.skeleton.num_joints)
        err = np.linalg.norm((pred - mean) / std - (_centred(w) - mean) / std, axis=-1)
        errors.extend(err[[t for t in range(32) if t not in keys]])
    value = out.rows[0]["values"]["lerp_slerp"]["lafan1_l2p@15"]
    assert value == pytest.approx(float(np.mean(errors)), rel=1e-6)
    # L2Q of LERP by hand: global quaternions (sign-continuous), non-key frames
    errors = []
    for start in range(0, clip.num_frames - 31, 16):
        w = clip[start : start + 32]
        q = Q.continuity(w.double().global_rotations(), dim=-3).numpy()
        p = Q.continuity(lerp_slerp(w, keys).double().global_rotations(), dim=-3).numpy()
        err = np.linalg.norm((p - q).reshape(32, -1), axis=-1)
        errors.extend(err[[t for t in range(32) if t not in keys]])
    value = out.rows[0]["values"]["lerp_slerp"]["lafan1_l2q@15"]
    assert value == pytest.approx(float(np.mean(errors)), rel=1e-6)


def test_evaluation_data_may_hold_only_test_clips(tmp_path: Path) -> None:
    """Every clip held out (data.test_pattern=.), e.g. CMU clips for a CMU-hierarchy model."""
    from skelagnostic import write_bvh
    from skelagnostic.data import bvh_sources
    from skelagnostic.errors import SkelagnosticError

    model = _tiny_trained(tmp_path)
    for seed in (3, 4):
        motion, _ = procedural.generate("biped31", "walk", seconds=2.5, fps=30, seed=seed)
        write_bvh(motion, tmp_path / f"walk{seed}.bvh")

    def data() -> PcmrlInterpDataModule:
        sources = bvh_sources([tmp_path], test_pattern=".", units="cm")
        return PcmrlInterpDataModule(sources, fps=30, window=32, cache_dir=tmp_path / "c")

    dm = data()
    held = held_out(dm)
    assert held.split == "test" and sorted(Path(n).stem for n in held.names) == ["walk3", "walk4"]
    with pytest.raises(SkelagnosticError, match="no training clips"):
        dm.train_dataloader()
    with torch.no_grad():
        out = interpolation_protocol(model, held, tmp_path)
    assert len(out.rows) == 2
    assert any("evaluated windows (no training clip)" in n for n in out.notes)
    with pytest.raises(SkelagnosticError, match="no training clips"):
        data().setup("fit")


def test_interpolation_protocol_refuses_another_hierarchy(tmp_path: Path) -> None:
    model = _tiny_trained(tmp_path)
    motion, _ = procedural.generate("biped22", "walk", seconds=2.2, fps=30, seed=1)
    motion.name = "biped22_walk"
    with pytest.raises(EvaluationError, match=r"biped22_walk.*another hierarchy.*data=cmu"):
        interpolation_protocol(model, HeldOut("test", [motion.convert_units("m")]), tmp_path)


@pytest.mark.data
def test_cli_evaluates_a_cmu_hierarchy_model_on_every_cmu_clip(
    shared_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """`evaluate ckpt_path=RUN data=bvh data.paths=[DIR] data.test_pattern=.` (Table 1 on CMU)."""
    from skelagnostic import cli

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SKELAGNOSTIC_CACHE", str(tmp_path / "cache"))
    fit = [
        "model=pcmrl_interp",
        "experiment=pcmrl_interp_cpu",
        "threads=1",
        "model.dim=16",
        "model.heads=2",
        "model.layers=1",
        "data.clips_per_gait=1",
        "data.val_fraction=0",
        "data.samples_per_epoch=8",
        "trainer.max_steps=2",
        "logger=csv",
        "run_dir=s2",
    ]
    assert cli.main(["fit", *fit]) == 0, capsys.readouterr().err
    cmu = shared_data / "human" / "cmu"
    args = [
        "evaluate",
        "ckpt_path=s2",
        "data=bvh",
        f"data.paths=[{cmu}]",
        "data.units=cmu",
        "data.test_pattern=.",
        "run_dir=ev",
    ]
    assert cli.main(args) == 0, capsys.readouterr().err
    report = json.loads((tmp_path / "ev" / "evaluation.json").read_text())
    assert report["protocol"] == "pcmrl.interpolation" and report["data"]["source"] == "bvh"
    assert report["data"]["split"] == "test"
    assert sorted(Path(c).stem for c in report["data"]["clips"]) == ["131_01", "131_03"]
    assert report["methods"] == ["model", "lerp_slerp", "ground_truth"]
    assert len(report["per_clip"]) == 2
    for metric in ("l2p@15", "lafan1_l2p@30"):
        values = [r["values"]["lerp_slerp"][metric] for r in report["per_clip"]]
        assert report["mean"]["lerp_slerp"][metric] == pytest.approx(sum(values) / 2)
