import pytest
import torch
from skelagnostic_humot.data import (
    HumotDataModule,
    Topology,
    gather_subset,
    prepare_chunks,
    sample_keep,
)

import skelagnostic as sa
from skelagnostic.data import ProceduralSource
from skelagnostic.errors import SkelagnosticError


def test_sample_keep_probabilities():
    gen = torch.Generator().manual_seed(0)
    major = torch.tensor([True, False] * 5)
    keep = sample_keep(major, 20000, 0.1, 0.5, generator=gen)
    assert keep[:, major].float().mean().item() == pytest.approx(0.9, abs=0.01)
    assert keep[:, ~major].float().mean().item() == pytest.approx(0.5, abs=0.01)
    assert keep.any(dim=1).all()
    with pytest.raises(SkelagnosticError, match="p_other"):
        sample_keep(major, 1, 0.1, 1.0)


def test_two_subsets_are_independent():
    gen = torch.Generator().manual_seed(1)
    major = torch.zeros(12, dtype=torch.bool)
    a, b = (sample_keep(major, 5000, generator=gen) for _ in range(2))
    both = (a & b).float().mean().item()
    assert both == pytest.approx(0.25, abs=0.02)


def test_gather_subset_bones_skip_to_nearest_kept_ancestor():
    parents = [-1, 0, 1, 2, 0, 4]
    keep = torch.tensor(
        [[True, False, True, True, False, True], [False, True, True, False, False, False]]
    )
    sub = gather_subset(keep, parents)
    assert sub.index.tolist() == [[0, 2, 3, 5], [1, 2, 0, 0]]
    assert sub.mask.tolist() == [[True] * 4, [True, True, False, False]]
    bones0 = sub.bones[0][sub.bone_mask[0]].tolist()
    assert bones0 == [[0, 1], [1, 2], [0, 3]]  # 2->0 (1 dropped), 3->2, 5->0 (4 dropped)
    assert sub.bones[1][sub.bone_mask[1]].tolist() == [[0, 1]]
    x = torch.arange(6.0)[None, None, :, None].expand(2, 3, 6, 2)
    taken = sub.take(x, 2)
    assert taken[0, 0, :, 0].tolist() == [0, 2, 3, 5]
    assert taken[1, 0, :, 0].tolist() == [1, 2, 0, 0]


def test_prepare_chunks_centres_on_major_joints():
    motion = sa.procedural.generate("biped22", "walk", seconds=1.0, fps=30)[0]
    topo = Topology.of(motion.skeleton)
    world = motion.global_positions().float()[None] / 100
    pos, tmpl = prepare_chunks(world, topo)
    centre = pos[:, :, topo.major].mean(dim=(1, 2))
    assert centre.abs().max() < 1e-5
    assert tmpl.shape == (1, 22, 3)
    assert torch.allclose(tmpl[0, 0], torch.zeros(3))


@pytest.mark.data
def test_topology_templates_are_the_skeleton_template_at_its_bone_lengths(shared_data):
    """LaFAN1's rest pose is rotated: the template's frame must come from its real lengths."""
    from skelagnostic_humot.template import skeleton_template

    sk = sa.read_bvh(shared_data / "human/lafan1/Lafan1_example.bvh").skeleton
    topo = Topology.of(sk)
    torch.testing.assert_close(
        topo.templates(sk.bone_lengths().float()), skeleton_template(sk).float(), atol=1e-4, rtol=0
    )


def test_datamodule_chunks_and_drops_non_humans(tmp_path):
    source = ProceduralSource(
        kinds=["biped22", "biped17", "quadruped"], gaits=["walk"], clips_per_gait=2, seconds=2.0
    )
    dm = HumotDataModule([source], cache_dir=tmp_path, val_fraction=0.5)
    assert (dm.window, dm.stride, dm.batch_size, dm.fps) == (30, 6, 32, 30.0)
    dm.prepare_data()
    dm.setup("fit")
    assert len(dm.skeletons) == 2
    assert all(sk.morphology == "biped" for sk in dm.skeletons.values())
    assert len(dm.skipped) == 1
    item = next(iter(dm.datasets["train"].values()))[0]
    assert item["features"].shape[0] == 30


def test_datamodule_without_humans_fails_clearly(tmp_path):
    source = ProceduralSource(kinds=["quadruped"], gaits=["walk"], clips_per_gait=1, seconds=2.0)
    dm = HumotDataModule([source], cache_dir=tmp_path)
    with pytest.raises(SkelagnosticError, match="human"):
        dm.setup("fit")
