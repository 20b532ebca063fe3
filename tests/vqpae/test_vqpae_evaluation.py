"""The vqpae.manifold protocol and the functions the quality benchmark shares with it."""

from __future__ import annotations

import math

import lightning as L
import pytest
import torch
from skelagnostic_vqpae.aligner import (
    AUTHORS_OPTIMIZER,
    COSINE_SCHEDULER,
    PREVIOUS_DEFAULTS,
    VqpaeAligner,
)
from skelagnostic_vqpae.protocols.manifold import manifold_protocol
from skelagnostic_vqpae.protocols.tables import code_overlap, phase_line

from skelagnostic.evaluation import held_out


def test_phase_line_of_a_wrapped_linear_phase() -> None:
    t = torch.arange(50, dtype=torch.float64)
    wrapped = torch.remainder(0.07 * t + 0.5, 1.0) - 0.5  # cycles in [-1/2, 1/2)
    r2, slope = phase_line(wrapped)
    assert r2 == pytest.approx(1.0, abs=1e-12) and slope == pytest.approx(0.07)
    noisy = wrapped + 0.05 * torch.sin(t)
    assert phase_line(noisy)[0] < 1.0


def test_code_overlap_counts_shared_codes() -> None:
    out = code_overlap(
        {"human": torch.tensor([0, 0, 1, 2]), "dog": torch.tensor([1, 1, 2, 3])}, num_codes=8
    )
    assert out["usage"] == 0.5 and out["overlap"] == 0.25
    assert out["per_dataset"] == [0.5, 0.75]
    assert out["characters"] == ["human", "dog"] and out["codes_used"] == [3, 3]


def test_manifold_protocol_on_held_out_clips(helpers, tmp_path) -> None:
    L.seed_everything(0, verbose=False)
    dm = helpers["datamodule"](tmp_path / "cache")
    dm.test_fraction = 0.25
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
    model.eval()
    held = held_out(dm)
    assert held.split == "test"
    with torch.no_grad():
        out = manifold_protocol(model, held, tmp_path)
    assert [r["clip"] for r in out.rows] == held.names
    overlap = out.extra["overlap"]
    assert set(overlap["characters"]) == {r["character"] for r in out.rows}
    chance = out.rows[0]["values"]["chance"]["shared_code_share"]
    assert chance == pytest.approx(overlap["overlap"])  # shared codes / K
    for row in out.rows:
        model_values = row["values"]["model"]
        assert 0.0 <= model_values["shared_code_share"] <= 1.0
        assert model_values["phase_r2"] <= 1.0 + 1e-9
        if "pose_mpjpe_cm" in out.metrics:
            assert math.isfinite(model_values["pose_mpjpe_cm"])
            assert row["values"]["mean_pose"]["pose_mpjpe_cm"] > 0
    assert (tmp_path / "manifold.png").stat().st_size > 0


def test_evaluate_cli_on_a_tiny_vqpae_run(tmp_path, vqpae_cli, capsys) -> None:
    """fit a few steps, then ``skelagnostic evaluate ckpt_path=RUN``: the default protocol."""
    import json

    fit = [
        "fit",
        "model=vqpae",
        "threads=1",
        "trainer.max_steps=3",
        "model.num_codes=8",
        "data.kinds=[biped22,quadruped]",
        "data.clips_per_gait=2",
        "data.seconds=3.0",
        "data.fps=20",
        "data.test_fraction=0.25",
    ]
    assert vqpae_cli(fit) == 0, capsys.readouterr().err
    (run,) = (tmp_path / "runs" / "vqpae" / "fit").iterdir()
    capsys.readouterr()
    assert vqpae_cli(["evaluate", f"ckpt_path={run}", "threads=1"]) == 0, capsys.readouterr().err
    (evaluation,) = (tmp_path / "runs" / "vqpae" / "evaluate").iterdir()
    report = json.loads((evaluation / "evaluation.json").read_text())
    assert report["protocol"] == "vqpae.manifold" and report["data"]["split"] == "test"
    assert report["plots"] == ["evaluation.png", "manifold.png"]
    assert "chance" in report["methods"]
    assert "vqpae.manifold on the test split" in capsys.readouterr().out
