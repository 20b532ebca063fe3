"""``experiment=humot_cpu2h``, ``data.source=humot_mix``: a corpus split plus procedural humans."""

from pathlib import Path

import pytest
from skelagnostic_humot.data import corpus_and_procedural_source
from skelagnostic_humot.evaluation.held_out import topology_status, trained_hierarchies

import skelagnostic as sa
from skelagnostic.cli.app import build_datamodule, compose
from skelagnostic.errors import SkelagnosticError
from skelagnostic.evaluation import held_out


def _corpus(folder: Path) -> Path:
    """Two LaFAN1-named files (procedural biped22 walks, in cm): subject 1 and subject 5."""
    folder.mkdir()
    for i, subject in enumerate((1, 5)):
        clip = sa.procedural.generate("biped22", "walk", seconds=2.0, fps=30, seed=50 + i)[0]
        sa.write_bvh(clip, folder / f"walk1_subject{subject}.bvh")
    return folder


def test_cpu2h_preset_composes_the_reduced_network_and_the_mixed_data(humot_pm, tmp_path):
    cfg = compose(
        ["model=humot", "experiment=humot_cpu2h", f"run_dir={tmp_path}"], plugin_manager=humot_pm
    )
    assert cfg.data.source == "humot_mix" and cfg.data.preset == "lafan1"
    assert list(cfg.data.kinds) == ["biped22", "biped17"]  # biped31 (CMU's hierarchy) unseen
    assert (cfg.data.window, cfg.data.stride, cfg.data.val_fraction) == (30, 6, 0.0)
    assert (cfg.model.dim, cfg.model.blocks, cfg.model.kernel_size) == (64, 1, 3)
    assert cfg.trainer.max_steps > 0 and cfg.trainer.max_time is not None
    # model=humot alone keeps the paper's network
    paper = compose(["model=humot", f"run_dir={tmp_path}"], plugin_manager=humot_pm)
    assert (paper.model.dim, paper.model.blocks) == (128, 4)


def test_mixed_data_keeps_the_corpus_test_split_and_adds_procedural_topologies(humot_pm, tmp_path):
    root = _corpus(tmp_path / "lafan1")
    cfg = compose(
        [
            "model=humot",
            "experiment=humot_cpu2h",
            f"run_dir={tmp_path}",
            f"data.root={root}",
            "data.clips_per_gait=1",
            "data.seconds=1.5",
            f"data.cache_dir={tmp_path / 'cache'}",
        ],
        plugin_manager=humot_pm,
    )
    dm = build_datamodule(cfg, humot_pm)
    held = held_out(dm)
    assert held.split == "test"
    assert [Path(c.name).name for c in held.clips] == ["walk1_subject5.bvh"]
    assert sorted(dm.datasets["train"]) == ["lafan1", "procedural/biped17", "procedural/biped22"]
    trained = trained_hierarchies(held)
    assert topology_status(sa.procedural.skeleton("biped31"), trained) == "unseen"
    assert topology_status(sa.procedural.skeleton("biped17"), trained) == "seen"


def test_mixed_data_rejects_non_human_kinds(tmp_path):
    with pytest.raises(SkelagnosticError, match=r"data\.kinds"):
        corpus_and_procedural_source(tmp_path, kinds=["quadruped"])
    sa.write_bvh(sa.procedural.generate("biped31", "walk", seconds=1.0)[0], tmp_path / "a.bvh")
    only = corpus_and_procedural_source(tmp_path, preset="cmu", kinds=[])
    assert [p.name for p in only.parts] == ["cmu"]
