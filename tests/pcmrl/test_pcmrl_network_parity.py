"""PC-MRL networks equal the authors' for their weights (issue #26, item 6).

``tests/fixtures/pcmrl_net`` holds small networks of the authors' code
(github.com/MiniEval/PC-MRL) with their outputs, written by
``scripts/fixtures/pcmrl_network_parity.py``; the tests need none of their code.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from skelagnostic_pcmrl.authors import load_stage1, load_stage2, read_state
from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
from skelagnostic_pcmrl.interp.clips import Clip, TrainWindows
from skelagnostic_pcmrl.interp.data import PcmrlInterpDataModule
from skelagnostic_pcmrl.interp.keyframes import window_features
from skelagnostic_pcmrl.interp.rpa import (
    authors_rest_pose_rotations,
    lateral_axis,
    left_right_pairs,
    mirrored_tail_offsets,
)
from skelagnostic_pcmrl.points import ZeroLengthBoneWarning, sample_layout
from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner
from skelagnostic_pcmrl.recon.fps import farthest_point_sampling

import skelagnostic as sa
from skelagnostic.core import quaternion as Q
from skelagnostic.core.kinematics import fk_from_global
from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import POINT_GROUPS

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "pcmrl_net"
OUT = torch.load(FIXTURES / "outputs.pt", weights_only=False)
TOL = 1e-4


@pytest.fixture(scope="module")
def stage1() -> torch.nn.Module:
    return load_stage1(FIXTURES / "stage1.pt", heads=OUT["sizes"]["heads"], k=OUT["sizes"]["k"])


def test_fps_keeps_the_authors_indices_at_every_stage(stage1: torch.nn.Module) -> None:
    xyz = OUT["clouds"].flatten(0, 1)[..., :3]
    for expected in OUT["fps"]:
        idx = farthest_point_sampling(xyz, expected.shape[-1])
        assert torch.equal(idx, expected)
        xyz = torch.gather(xyz, 1, idx[..., None].expand(-1, -1, 3))


def test_point_encoder_equals_the_authors(stage1: torch.nn.Module) -> None:
    with torch.no_grad():
        out = stage1.encoder(OUT["clouds"].flatten(0, 1))
    assert (out - OUT["encoder"]).abs().max() < TOL


def test_temporal_transformer_equals_the_authors(stage1: torch.nn.Module) -> None:
    with torch.no_grad():
        out = stage1.temporal(OUT["features"])
    assert (out - OUT["temporal"]).abs().max() < TOL


def test_stage1_forward_equals_the_authors(stage1: torch.nn.Module) -> None:
    with torch.no_grad():
        out = stage1(OUT["clouds"])
    assert out.shape == OUT["stage1"].shape
    assert (out - OUT["stage1"]).abs().max() < TOL


def test_stage2_network_equals_the_authors() -> None:
    case = OUT["stage2"]
    net = load_stage2(FIXTURES / "stage2.pt", heads=case["sizes"]["heads"])
    with torch.no_grad():
        out = net(case["inputs"], case["keys"])
    assert (out - case["output"]).abs().max() < TOL


def test_foq_and_rest_directions_equal_the_authors() -> None:
    case = OUT["foq"]
    rot = case["global"]
    num_b, num_t, num_j = rot.shape[:3]
    keys = torch.ones(num_b, num_t, dtype=torch.bool)
    feats = window_features(
        rot,
        torch.zeros(num_b, num_t, 3),
        torch.zeros(num_b, num_j, 3),
        case["tails"].expand(num_b, -1, -1),
        keys,
        [-1] + [0] * (num_j - 1),
    )
    assert (feats["foq"] - case["foq"]).abs().max() < 1e-6
    assert (feats["q0"] - case["q0"][:, 0]).abs().max() < 1e-6
    direction = feats["inputs"][..., :-1].unflatten(-1, (num_j, 10))[..., 3:6]
    assert (direction - case["p_base"]).abs().max() < 1e-6
    assert torch.allclose(Q.mul(feats["foq"], feats["q0"][:, None]), rot, atol=1e-6)


def test_loader_names_the_file_and_key_at_fault(tmp_path: Path) -> None:
    state, _ = read_state(FIXTURES / "stage2.pt")
    del state["decoder.output.bias"]
    path = tmp_path / "CITL5000.pt"
    torch.save(state, path)
    with pytest.raises(SkelagnosticError, match=r"CITL5000\.pt.*'decoder\.output\.bias'"):
        load_stage2(path, heads=OUT["stage2"]["sizes"]["heads"])
    state1, _ = read_state(FIXTURES / "stage1.pt")
    state1["cloud_encoder.extra.weight"] = torch.zeros(1)
    with pytest.raises(SkelagnosticError, match=r"unexpected key 'cloud_encoder\.extra\.weight'"):
        load_stage1(state1)
    with pytest.raises(SkelagnosticError, match="no such checkpoint file"):
        load_stage1(tmp_path / "missing.pt")


def _rpa_skeleton() -> Skeleton:
    case = OUT["rpa"]
    groups = [POINT_GROUPS[g] for g in case["groups"]]
    return Skeleton(case["names"], case["parents"], case["offsets"], body_groups=groups)


def test_mirrored_tail_offsets_equal_the_authors_draw() -> None:
    case = OUT["rpa"]
    skeleton = _rpa_skeleton()
    assert [list(p) for p in left_right_pairs(skeleton)] == case["pairs"]
    gen = torch.Generator().manual_seed(case["seed"])
    # their aug_range is the width of the interval; mirror_axis=1 is the component they negate
    delta = mirrored_tail_offsets(skeleton, case["aug_range"] / 2, gen, mirror_axis=1)
    assert (delta - case["aug"]).abs().max() < 1e-7


def test_mirrored_tail_offsets_mirror_across_the_sagittal_plane_by_default() -> None:
    skeleton = _rpa_skeleton()
    assert lateral_axis(skeleton) == 0  # left joints at +x in this rest pose
    delta = mirrored_tail_offsets(skeleton, 0.05, torch.Generator().manual_seed(3))
    flip = torch.tensor([-1.0, 1.0, 1.0])
    for left, right in left_right_pairs(skeleton):
        assert torch.equal(delta[right], delta[left] * flip)
        assert float(delta[left].abs().max()) <= 0.05
    unpaired = [j for j, g in enumerate(skeleton.body_groups) if g == "spine"]
    assert not delta[unpaired].any()


def test_training_windows_draw_mirrored_offsets_when_asked() -> None:
    motion = sa.procedural.generate("biped31", "walk", seconds=2.0)[0]
    clip = Clip.from_motion(motion, "walk")
    windows = TrainWindows(
        [clip], 16, 2, 4, rpa_range=0.05, rpa_prob=1.0, samples=3, seed=1, rpa_offsets="mirrored"
    )
    skeleton = clip.skeleton
    flip = torch.ones(3)
    flip[lateral_axis(skeleton)] = -1.0
    spine = [j for j, g in enumerate(skeleton.body_groups) if g == "spine" and j > 0]
    for i in range(len(windows)):
        moved = windows[i]["offsets"] - clip.offsets
        assert moved.abs().max() > 0
        assert not moved[spine].any()
        for left, right in left_right_pairs(skeleton):
            assert torch.allclose(moved[right], moved[left] * flip, atol=1e-6)
    with pytest.raises(SkelagnosticError, match=r"data\.rpa_offsets"):
        PcmrlInterpDataModule(rpa_offsets="symmetric")


def test_authors_rest_pose_rotations_equal_their_augmentation() -> None:
    case = OUT["rpa"]
    rot, heads = case["global"][0], case["heads"][0]
    new = authors_rest_pose_rotations(
        rot, heads[:, 0], case["offsets"], case["tails"], case["parents"], case["aug"]
    )
    ref = case["global_aug"][0]
    # their IK returns the same rotations with the opposite quaternion sign (Algorithm 1)
    assert torch.minimum((new - ref).abs().amax(-1), (new + ref).abs().amax(-1)).max() < 1e-5
    pos = fk_from_global(new, heads[:, 0], case["offsets"], case["parents"])
    assert (pos - case["heads_aug"][0]).abs().max() < 1e-5
    moved = (Q.mul(new, Q.inv(rot))[..., 0].abs() < 1 - 1e-4).any(dim=0)
    assert moved[[1, 2, 3, 4, 6, 7, 8, 9]].any()  # the augmentation turned some bones


def test_training_windows_solve_rotations_as_the_authors_when_asked() -> None:
    motion = sa.procedural.generate("biped31", "walk", seconds=2.0)[0]
    clip = Clip.from_motion(motion, "walk")
    common = {"rpa_range": 0.05, "samples": 2, "seed": 4, "rpa_offsets": "mirrored"}
    plain = TrainWindows([clip], 16, 2, 4, rpa_prob=0.0, **common)
    augmented = TrainWindows([clip], 16, 2, 4, rpa_prob=1.0, rpa_solve="authors", **common)
    parents = clip.skeleton.parents
    for i in range(len(plain)):
        a, b = plain[i], augmented[i]
        assert torch.equal(b["offsets"], clip.offsets) and torch.equal(b["tails"], clip.tails)
        assert not torch.allclose(a["global_rotations"], b["global_rotations"], atol=1e-4)
        lengths = [
            fk_from_global(w["global_rotations"], w["root"], clip.offsets, parents) for w in (a, b)
        ]
        bones = [(p[:, 1:] - p[:, parents[1:]]).norm(dim=-1) for p in lengths]
        assert torch.allclose(bones[0], bones[1], atol=1e-5)
    with pytest.raises(SkelagnosticError, match=r"data\.rpa_solve"):
        PcmrlInterpDataModule(rpa_solve="lengths")


def test_stage1_aligner_with_the_authors_layout_starts_in_the_rest_pose() -> None:
    torch.manual_seed(0)
    with pytest.warns(ZeroLengthBoneWarning):
        model = PcmrlReconAligner(
            target="biped31",
            layout="authors",
            dim=4,
            stages=2,
            temporal_layers=1,
            num_source_points=64,
            canonical_yaw=False,
        )
    motion = sa.procedural.generate("biped22", "walk", seconds=0.4)[0].convert_units("m")
    src = sample_layout(motion.skeleton, 64, 0.05, batch=(1,))
    pts = src.points(
        motion.global_rotations().float()[None],
        motion.global_positions().float()[None],
        motion.skeleton.offsets,
    )
    out = model.reconstruct(pts, src.groups)
    rest = model.target_skeleton.rest_positions().float()
    centred = out["positions"][0, 0].detach() - out["root"][0, 0].detach()
    assert torch.allclose(centred, rest - rest[0], atol=0.1)
    with pytest.raises(SkelagnosticError, match="temporal_dim"):
        PcmrlReconAligner(layout="authors", temporal_dim=32)
    with pytest.raises(SkelagnosticError, match=r"model\.layout"):
        PcmrlInterpAligner(layout="post")
