"""``humot.ablations``: the paper's ablations retrained at an equal budget, on held-out clips."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from skelagnostic_humot.ablations import ABLATIONS, METRICS, ablation_protocol
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import HumotDataModule

from skelagnostic.data import ProceduralSource
from skelagnostic.evaluation import MODEL, EvaluationError, held_out


def _held(tmp_path: Path):
    # biped31 has CMU's zero-length hip bones, which the bone-length metric must leave out
    source = ProceduralSource(kinds=["biped31"], gaits=["walk"], clips_per_gait=3, seconds=2.0)
    dm = HumotDataModule(
        [source], cache_dir=tmp_path / "cache", batch_size=4, val_fraction=0.0, test_fraction=0.34
    )
    return held_out(dm)


def test_ablations_train_each_variant_and_measure_held_out_clips(tmp_path, humot_small):
    torch.manual_seed(0)
    model = HumotAligner(**humot_small).eval()
    held = _held(tmp_path)
    assert held.split == "test" and held.clips
    with torch.no_grad():  # as `skelagnostic evaluate` calls protocols
        out = ablation_protocol(model, held, tmp_path, steps=2)
    assert [r["clip"] for r in out.rows] == held.names
    methods = [MODEL, *ABLATIONS, "mean_pose", "mean_pose_on_trajectory"]
    assert out.methods == methods
    values = out.rows[0]["values"]
    for name in (MODEL, *ABLATIONS):
        assert set(values[name]) == set(METRICS)
        assert all(v >= 0 for v in values[name].values())
    # trained: the variants moved away from the evaluated (untrained) weights and apart
    assert values["full"]["mpjpe_cm"] != values[MODEL]["mpjpe_cm"]
    assert values["no_subsampling"]["mpjpe_cm"] != values["full"]["mpjpe_cm"]
    assert out.extra["steps"] == 2
    assert "2 optimiser steps" in out.notes[0]


def test_ablations_reject_a_bad_budget_or_an_unknown_option(tmp_path, humot_small):
    model = HumotAligner(**humot_small).eval()
    held = _held(tmp_path)
    with pytest.raises(EvaluationError, match="steps must be a positive integer"):
        ablation_protocol(model, held, tmp_path, steps=0)
    with pytest.raises(EvaluationError, match=r"variant 'x' changes \['nope'\]"):
        ablation_protocol(model, held, tmp_path, steps=1, variants={"x": {"nope": 1}})
