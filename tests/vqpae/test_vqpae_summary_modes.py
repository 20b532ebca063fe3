"""The VQ-PAE end-of-fit summary's modes (summary=auto|full|quick|none) on a tiny run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from skelagnostic_vqpae.protocols.summary import SUMMARY_PLANS

from skelagnostic.callbacks import FitSummary


def _summary(tiny_fit: dict[str, Any], mode: str) -> Path:
    """Run the end-of-fit summary again in ``mode``; its directory."""
    out = tiny_fit["root"] / mode
    FitSummary(name="vqpae", dirpath=out, mode=mode).on_fit_end(
        tiny_fit["trainer"], tiny_fit["model"]
    )
    return out


def _train_dogs(tiny_fit: dict[str, Any]) -> int:
    from skelagnostic.evaluation import clips_of_split

    model = tiny_fit["model"]
    return sum(model.dataset_of(c.skeleton) == 1 for c in clips_of_split(tiny_fit["dm"], "train"))


def test_a_tiny_run_gets_the_quick_summary(tiny_fit: dict[str, Any]) -> None:
    run = tiny_fit["root"] / "auto"
    metrics = json.loads((run / "vqpae_metrics.json").read_text())
    assert metrics["summary"]["mode"] == "quick"
    assert "3 optimiser steps" in metrics["summary"]["reason"]
    transfer, quick = metrics["transfer"], SUMMARY_PLANS["quick"]
    assert len(transfer["per_clip"]) == quick.transfer_clips == 1
    assert transfer["excerpt_seconds"] == quick.transfer_seconds
    assert len(transfer["database_clips"]) == min(quick.database_clips, _train_dogs(tiny_fit))
    assert (run / "vqpae_transfer.png").stat().st_size > 0  # the picture
    assert not (run / "vqpae_transfer.gif").exists()  # no animation in the quick summary
    text = (run / "summary.md").read_text()
    assert "Summary: the aligner's quick summary" in text and "## Table 2" in text
    table = metrics["table2"]
    assert set(table["frame_share_training"]) == set(tiny_fit["model"].dataset_names)
    assert table["codes_shared_training"] == len(table["shared_codes_training"])
    # the top of summary.md says whether the run shows a shared manifold, with its figures
    headline = text.split("\n\n")[2]
    assert headline.startswith("**Shared manifold")
    assert f"{table['codes_shared_training']} of {table['num_codes']} codes are used" in headline
    assert "share no code" in headline or "they share code" in headline


def test_full_summary_transfers_more_and_animates(
    tiny_fit: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    import skelagnostic.viz

    rendered: dict[str, Any] = {}  # what FitSummary asks render_motion to draw, by file name
    original = skelagnostic.viz.render_motion

    def spy(motions: Any, out: Any, **options: Any) -> Any:
        rendered[Path(out).name] = (motions, options)
        return original(motions, out, **options)

    monkeypatch.setattr(skelagnostic.viz, "render_motion", spy)
    run = _summary(tiny_fit, "full")
    metrics = json.loads((run / "vqpae_metrics.json").read_text())
    assert metrics["summary"] == {"mode": "full", "reason": "summary=full"}
    transfer = metrics["transfer"]
    assert transfer["excerpt_seconds"] == SUMMARY_PLANS["full"].transfer_seconds
    assert len(transfer["database_clips"]) == _train_dogs(tiny_fit)  # every training dog clip
    held = [c for c in tiny_fit["dm"].assigned_splits.values() if c == "val"]
    assert 1 <= len(transfer["per_clip"]) <= min(3, len(held))
    for name in ("vqpae_transfer.png", "vqpae_transfer.gif", "vqpae_manifold.png"):
        assert (run / name).stat().st_size > 0
    assert "Animation `vqpae_transfer.gif`" in (run / "summary.md").read_text()
    _check_animation(run / "vqpae_transfer.gif", *rendered["vqpae_transfer.gif"])


def _check_animation(gif: Path, motions: list[Any], options: dict[str, Any]) -> None:
    """The transfer GIF: large panels, named as the picture names them, the dogs at one scale."""
    from PIL import Image
    from skelagnostic_vqpae.protocols.summary import RENDER_PANEL

    from skelagnostic.viz import render_frames

    with Image.open(gif) as image:
        assert image.size == (4 * RENDER_PANEL[0], RENDER_PANEL[1])
        assert image.size[1] >= 400 and image.n_frames > 1
    assert gif.stat().st_size < 4 * 2**20  # a few MB at most
    labels = options["labels"]
    assert "its own scale" in labels[0]
    assert [label.split(": ")[1].split("\n")[0] for label in labels[1:]] == [
        "VQ-PAE",
        "unscaled matching",
        "best clip at its own rate",
    ]
    drawn = {k: v for k, v in options.items() if k not in ("fps", "sheet_frames")}
    out = render_frames(motions, times=[0.0], **drawn)
    dogs = out.scales[1:]  # pixels per metre of the three dog panels
    assert np.ptp(dogs) < 1e-6 * dogs[0], out.scales
    assert {m.units for m in motions} == {"m"}


def test_none_writes_no_transfer_artefacts(tiny_fit: dict[str, Any]) -> None:
    run = _summary(tiny_fit, "none")
    assert {p.name for p in run.iterdir()} == {"vqpae_metrics.json", "summary.md"}
    metrics = json.loads((run / "vqpae_metrics.json").read_text())
    assert metrics["summary"]["mode"] == "none"
    assert not {"transfer", "table2", "usage"} & set(metrics)
    assert "no aligner summary" in (run / "summary.md").read_text()


def test_table2_summary_on_known_codes() -> None:
    from types import SimpleNamespace

    import torch
    from skelagnostic_vqpae.protocols.summary import shared_manifold_headline, table2_summary

    def clips(*codes: list[int]) -> list[Any]:
        return [SimpleNamespace(code=torch.tensor(c)) for c in codes]

    built = SimpleNamespace(num_codes=16)
    aligner = SimpleNamespace(dataset_names=["human", "dog"], _require_built=lambda: built)
    train = {"human": clips([1, 1, 2], [3]), "dog": clips([2, 3, 3, 5])}  # shared: 2, 3
    held = {"human": clips([4, 7, 9, 2]), "dog": clips([10, 10])}
    figures, text = table2_summary(aligner, held, train)
    assert figures["codes_shared_training"] == 2 and figures["shared_codes_training"] == [2, 3]
    assert figures["frame_share_training"] == {"human": 0.5, "dog": 0.75}  # the paper's figure
    assert figures["frame_share_heldout_on_training_shared"] == {"human": 0.25, "dog": 0.0}
    assert figures["codes_heldout"] == {"human": [2, 4, 7, 9], "dog": [10]}
    assert figures["heldout_source_target_shared"] == []
    assert "| `human` | 50.0 % | 25.0 % | 3 | 2, 4, 7, 9 |" in text
    assert "they share no code" in text
    headline = shared_manifold_headline(figures, aligner.dataset_names)
    assert "2 of 16 codes are used by both characters' training clips" in headline
    assert "human 50 %, dog 75 % of the training frames" in headline
    assert "human 25 %, dog 0 % of the held-out frames on them" in headline
    assert headline.endswith("on other codes.")  # the held-out clips share no code: said
    held["dog"] = clips([7, 10])
    shared, _ = table2_summary(aligner, held, train)
    assert shared_manifold_headline(shared, aligner.dataset_names).endswith("share code 7.")
    _, without = table2_summary(aligner, {}, train)  # no validation split
    assert "| `dog` | 75.0 % | n/a | 3 | none |" in without
