"""benchmarks/vqpae_frequency_window.py: transfer rhythm with other matching-frequency rules."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.embed import embed_clip
from skelagnostic_vqpae.protocols.rhythm import rhythm_figures
from skelagnostic_vqpae.transfer import build_database, phase_rate, transfer

from script_loader import load_script
from skelagnostic import procedural, read_bvh, write_bvh

script = load_script("benchmarks/vqpae_frequency_window.py", "vqpae_frequency_window")

FPS = 20


@pytest.fixture
def run_dir(trained: dict, tmp_path: Path) -> Path:
    """A run directory: the trained checkpoint and a split.json of BVH clips on disk."""
    clips = tmp_path / "clips"
    clips.mkdir()
    split = {}
    made = [
        ("biped22", "walk", 21, "val", 0.9),
        ("biped22", "run", 22, "test", 1.3),
        ("quadruped", "walk", 23, "train", 1.0),
        ("quadruped", "trot", 24, "train", 1.6),
        ("quadruped", "walk", 25, "val", 1.1),
    ]
    for kind, gait, seed, part, hz in made:
        motion, _ = procedural.generate(kind, gait, seconds=5.0, fps=FPS, seed=seed, frequency=hz)
        path = clips / f"{kind}_{gait}_{seed}.bvh"
        write_bvh(motion, path)
        split[str(path)] = part
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    shutil.copy(trained["ckpt"], run / "checkpoints" / "last.ckpt")
    (run / "split.json").write_text(json.dumps({"counts": {}, "clips": split}))
    return run


def test_default_rule_reproduces_the_transfer(trained: dict, run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "sweep.json"
    summary = script.main(
        [str(run_dir / "checkpoints" / "last.ckpt"), "--variants", "rule", "phase:2",
         "head_median:1", "--json", str(out)]
    )  # fmt: skip
    assert json.loads(out.read_text()) == json.loads(json.dumps(summary))
    split = json.loads((run_dir / "split.json").read_text())["clips"]
    # independently: the default transfer of each held-out human clip onto the dog's
    # training clips, as vqpae.transfer makes it (``rule`` is its default rule)
    model = trained["model"]
    dogs = [read_bvh(p) for p, s in sorted(split.items()) if "quadruped" in p and s == "train"]
    db = build_database(model, dogs)
    rows = summary["variants"]["rule"]["clips"]
    assert set(rows) == {"biped22_walk_21.bvh", "biped22_run_22.bvh"}
    for path, part in split.items():
        if "biped22" not in path:
            continue
        source = read_bvh(path)
        expected = rhythm_figures(source, transfer(model, source, db).motion)
        row = rows[Path(path).name]
        assert row["split"] == part
        assert row["whole"] == pytest.approx(expected["contact_rhythm_error_pct"], nan_ok=True)
        assert row["walks"] == pytest.approx(expected["locomotion_rhythm_error_pct"], nan_ok=True)
    means = summary["variants"]["rule"]["mean"]
    assert means["all"]["whole"] == pytest.approx(np.nanmean([r["whole"] for r in rows.values()]))
    # the estimates are compared with the feet on the held-out clips of both characters
    estimates = summary["variants"]["phase:2"]["estimates"]
    assert estimates["procedural/biped22"]["frames"] > 0
    assert estimates["procedural/quadruped"]["frames"] > 0


def test_rules_compute_their_definitions(trained: dict) -> None:
    model = trained["model"]
    clip, _ = procedural.generate("biped22", "run", seconds=4.0, fps=FPS, seed=31)
    emb = embed_clip(model, clip)
    window = int(model.characters[0].pae.window)
    measured = phase_rate(emb.phase, emb.fps, 2 * FPS + 1)  # 2 s
    phase = script.frequencies("phase:2", emb, clip, window)
    expected = torch.where(measured > 0, measured.float(), emb.frequency.float())
    torch.testing.assert_close(phase, expected)
    head = emb.frequency.double().numpy()
    median = script.frequencies("head_median:1", emb, clip, window).numpy()
    half = FPS // 2
    for i in (0, 5, len(head) // 2, len(head) - 1):
        assert median[i] == pytest.approx(np.median(head[max(0, i - half) : i + half + 1]))
    with pytest.raises(SystemExit, match="unknown variant"):
        script.frequencies("mean:2", emb, clip, window)
