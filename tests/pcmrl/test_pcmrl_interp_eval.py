"""PC-MRL Table 1 protocol (interp_eval): reference values and the pcmrl.interpolation protocol."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import lightning as L
import pytest
import torch
from skelagnostic_pcmrl.evaluation import interpolation_protocol
from skelagnostic_pcmrl.interp import PcmrlInterpAligner
from skelagnostic_pcmrl.interp_data import PcmrlInterpDataModule
from skelagnostic_pcmrl.interp_eval import evaluate, format_table, position_stats, windows

from skelagnostic import Motion, procedural
from skelagnostic.baselines import lerp_slerp
from skelagnostic.evaluation import HeldOut


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
        oracle = report["results"]["oracle"][gap]
        assert set(oracle) == {f"{p}{m}" for p in ("", "lafan1_") for m in ("l2p", "l2q", "npss")}
        assert all(v == pytest.approx(0.0, abs=1e-12) for v in oracle.values())
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


def test_interpolation_protocol_rows_beside_lerp(tmp_path: Path) -> None:
    L.seed_everything(0)
    dm = PcmrlInterpDataModule(fps=30, window=32, batch_size=4, samples_per_epoch=8)
    model = PcmrlInterpAligner(
        dim=16, heads=2, layers=1, ff_mult=2, max_relative=16, warmup_steps=1
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
    model.eval()
    clips = _clips()
    clips[0].name, clips[1].name = "walk", "run"
    short = clips[1][:20]
    short.name = "short"
    held = HeldOut("test", [*clips, short], SimpleNamespace(window=32))
    with torch.no_grad():
        out = interpolation_protocol(model, held, tmp_path)
    assert [r["clip"] for r in out.rows] == ["walk", "run"]
    assert any("short" in n for n in out.notes)
    assert out.methods == ["model", "lerp_slerp"]
    assert set(out.metrics) == {
        f"{p}{k}@{g}" for p in ("", "lafan1_") for k in ("l2p", "l2q", "npss") for g in (5, 15, 30)
    }
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
    assert set(report["results"]["LERP"]["15"]) == {"l2p", "l2q", "npss"}
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
