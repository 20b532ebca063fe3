"""The stage-1 aligner: shapes, unit quaternions, valid motions, zero-length bones, learning."""

from __future__ import annotations

import pytest
import torch
from skelagnostic_pcmrl.points import ZeroLengthBoneWarning, sample_layout
from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner, end_effector_pairs
from skelagnostic_pcmrl.recon.point_transformer import PointTransformerEncoder, VectorAttention

import skelagnostic as sa
from skelagnostic import procedural
from skelagnostic.core import quaternion as Q
from skelagnostic.errors import SkelagnosticError


@pytest.fixture
def model(pcmrl_tiny) -> PcmrlReconAligner:
    torch.manual_seed(0)
    with pytest.warns(ZeroLengthBoneWarning, match="LHipJoint, RHipJoint, LowerBack"):
        # the floor- and heading-free frames of the CPU presets (off by default: not the paper's)
        return PcmrlReconAligner(
            target="biped31", chunk=16, centre_up=True, canonical_yaw=True, **pcmrl_tiny
        ).eval()


def test_paper_sized_encoder_pools_256_points_to_one_1024_vector() -> None:
    enc = PointTransformerEncoder(5, dim=64, stages=4, heads=4, k=8)
    assert enc.out_channels == 1024
    x = torch.randn(2, 256, 8)
    assert enc(x).shape == (2, 1024)
    widths = [d.mlp[0].out_features for d in enc.down]
    assert widths == [128, 256, 512, 1024]


def test_encoder_is_permutation_invariant() -> None:
    torch.manual_seed(0)
    enc = PointTransformerEncoder(5, dim=8, stages=2, heads=2).eval()
    x = torch.randn(3, 64, 8)
    perm = torch.randperm(64)
    # FPS starts at point 0: keep it first so both orders pick the same centres
    perm = torch.cat([torch.tensor([0]), perm[perm != 0]])
    assert torch.allclose(enc(x), enc(x[:, perm]), atol=1e-5)


def test_vector_attention_matches_a_loop_over_each_points_neighbours() -> None:
    """Zhao et al. Eq. 3-4, computed point by point with brute-force nearest neighbours."""
    torch.manual_seed(0)
    layer = VectorAttention(6, k=3).double().eval()
    xyz = torch.randn(1, 7, 3, dtype=torch.float64)
    x = torch.randn(1, 7, 6, dtype=torch.float64)
    q, k, v = layer.qkv(layer.norm1(x)).chunk(3, dim=-1)
    expected = torch.empty_like(x)
    for i in range(7):
        dist = [(float((xyz[0, i] - xyz[0, j]).norm()), j) for j in range(7)]
        nbrs = [j for _, j in sorted(dist)[:3]]
        assert nbrs[0] == i  # a point is its own nearest neighbour
        acc = torch.zeros(6, dtype=torch.float64)
        logits, values = [], []
        for j in nbrs:
            delta = layer.theta(xyz[0, i] - xyz[0, j])
            logits.append(layer.gamma(q[0, i] - k[0, j] + delta))
            values.append(v[0, j] + delta)
        weights = torch.stack(logits).softmax(dim=0)  # per channel, over the neighbours
        for w, val in zip(weights, values, strict=True):
            acc = acc + w * val
        h = x[0, i] + layer.proj(acc)
        expected[0, i] = h + layer.ff(layer.norm2(h))
    assert torch.allclose(layer(x, xyz), expected, atol=1e-10)


@pytest.mark.parametrize("attention", ["vector", "none"])
def test_encoder_attention_options_keep_shapes_and_permutation_invariance(attention) -> None:
    torch.manual_seed(0)
    enc = PointTransformerEncoder(
        5, dim=8, stages=2, heads=2, attention=attention, attention_k=4
    ).eval()
    x = torch.randn(3, 64, 8)
    assert enc(x).shape == (3, 32)
    perm = torch.randperm(63) + 1
    perm = torch.cat([torch.tensor([0]), perm])  # FPS starts at point 0
    assert torch.allclose(enc(x), enc(x[:, perm]), atol=1e-5)
    if attention == "none":
        assert not any(p.numel() for p in [*enc.attn0.parameters(), *enc.attn.parameters()])


def test_encoder_rejects_unknown_attention() -> None:
    with pytest.raises(SkelagnosticError, match="attention='knn' is not one of full, vector"):
        PointTransformerEncoder(5, dim=8, stages=1, attention="knn")


@pytest.mark.parametrize("attention", ["full", "vector"])
def test_zero_layer_scale_starts_attention_blocks_as_the_identity(attention) -> None:
    torch.manual_seed(0)
    scaled = PointTransformerEncoder(
        5, dim=8, stages=2, heads=2, attention=attention, layer_scale=0.0
    ).eval()
    plain = PointTransformerEncoder(5, dim=8, stages=2, heads=2, attention="none").eval()
    plain.load_state_dict(scaled.state_dict(), strict=False)
    x = torch.randn(2, 64, 8)
    assert torch.allclose(scaled(x), plain(x), atol=1e-6)
    scaled.attn0.scale1.gamma.data.fill_(0.5)
    assert not torch.allclose(scaled(x), plain(x), atol=1e-4)


def test_reconstruction_outputs_unit_quaternions_and_consistent_positions(model) -> None:
    motion = procedural.generate("biped22", "walk", seconds=1.0)[0].convert_units("m")
    layout = sample_layout(motion.skeleton, 64, 0.05, batch=(2,))
    pts = layout.points(
        motion.global_rotations().float().expand(2, -1, -1, -1),
        motion.global_positions().float().expand(2, -1, -1, -1),
        motion.skeleton.offsets,
    )
    out = model.reconstruct(pts, layout.groups)
    target = model.target_skeleton
    assert out["rotations"].shape == (2, motion.num_frames, target.num_joints, 4)
    assert torch.allclose(out["rotations"].norm(dim=-1), torch.ones(()), atol=1e-5)
    assert out["raw"].shape[-2] < target.num_joints  # joints without a non-zero bone skipped
    # Eq. 1 positions agree with core forward kinematics of the derived local rotations
    from skelagnostic_pcmrl.points import global_to_local

    local = global_to_local(out["rotations"][0].detach(), target.parents)
    ref = sa.Motion(target, local, out["root"][0].detach(), 30.0).global_positions()
    assert torch.allclose(out["positions"][0].detach(), ref.float(), atol=1e-5)
    # the untrained network starts at the target's rest pose, root at the cloud centroid,
    # turned about the up axis only (canonical_yaw): heights and ground radii are kept
    rest = target.rest_positions().float()
    rest = rest - rest[0]
    centred = out["positions"][0, 0].detach() - out["root"][0, 0].detach()
    assert torch.allclose(centred[:, 1], rest[:, 1], atol=0.1)
    assert torch.allclose(centred[:, [0, 2]].norm(dim=-1), rest[:, [0, 2]].norm(dim=-1), atol=0.1)
    # ... facing the way the source faces: the same left-minus-right direction
    left = [target.index(n) for n in ("LeftShoulder", "LeftUpLeg")]
    right = [target.index(n) for n in ("RightShoulder", "RightUpLeg")]
    lateral = (centred[left] - centred[right]).sum(0)[[0, 2]]
    src = motion.skeleton
    src_pos = motion.global_positions()[0].float()
    src_lat = (
        src_pos[[src.index("LeftArm"), src.index("LeftUpLeg")]]
        - src_pos[[src.index("RightArm"), src.index("RightUpLeg")]]
    ).sum(0)[[0, 2]]
    cos = torch.nn.functional.cosine_similarity(lateral, src_lat, dim=0)
    assert cos > 0.9  # 64 points, limbs mid-swing: within ~25 degrees


def test_without_canonical_yaw_the_untrained_network_stands_in_the_rest_pose(pcmrl_tiny) -> None:
    torch.manual_seed(0)
    with pytest.warns(ZeroLengthBoneWarning):
        model = PcmrlReconAligner(target="biped31", canonical_yaw=False, **pcmrl_tiny).eval()
    motion = procedural.generate("biped22", "walk", seconds=0.5)[0].convert_units("m")
    layout = sample_layout(motion.skeleton, 64, 0.05, batch=(1,))
    pts = layout.points(
        motion.global_rotations().float()[None],
        motion.global_positions().float()[None],
        motion.skeleton.offsets,
    )
    out = model.reconstruct(pts, layout.groups)
    rest = model.target_skeleton.rest_positions().float()
    centred = out["positions"][0, 0].detach() - out["root"][0, 0].detach()
    assert torch.allclose(centred, rest - rest[0], atol=0.1)


def test_canonical_yaw_makes_the_reconstruction_heading_equivariant(model, pcmrl_tiny) -> None:
    """Turning the source about the up axis turns the reconstruction by the same angle."""
    motion = procedural.generate("biped22", "walk", seconds=1.0)[0].convert_units("m")
    angle = torch.tensor(1.1)
    turn = torch.tensor([torch.cos(angle / 2), 0.0, torch.sin(angle / 2), 0.0])
    rot = motion.rotations.clone()
    rot[:, 0] = Q.mul(turn.to(rot), rot[:, 0])
    turned = sa.Motion(
        motion.skeleton, rot, Q.rotate(turn.to(rot), motion.root_positions), motion.fps, units="m"
    )
    a = model.retarget(motion, model.target_skeleton).global_positions().float()
    b = model.retarget(turned, model.target_skeleton).global_positions().float()
    expected = Q.rotate(turn, a)
    assert torch.allclose(b, expected, atol=1e-3)
    # without it the untrained network is not equivariant
    with pytest.warns(ZeroLengthBoneWarning):
        plain = PcmrlReconAligner(
            target="biped31", canonical_yaw=False, chunk=16, **pcmrl_tiny
        ).eval()
    plain.load_state_dict(model.state_dict())
    a = plain.retarget(motion, model.target_skeleton).global_positions().float()
    b = plain.retarget(turned, model.target_skeleton).global_positions().float()
    assert not torch.allclose(b, Q.rotate(turn, a), atol=1e-2)


def test_centre_up_makes_the_reconstruction_independent_of_the_floor_height(
    model, pcmrl_tiny
) -> None:
    """Raising the source by 0.7 m raises the reconstruction by 0.7 m and changes nothing else."""
    motion = procedural.generate("biped22", "walk", seconds=1.0)[0].convert_units("m")
    lift = torch.tensor([0.0, 0.7, 0.0])
    raised = sa.Motion(
        motion.skeleton,
        motion.rotations,
        motion.root_positions + lift.to(motion.root_positions),
        motion.fps,
        units="m",
    )
    a = model.retarget(motion, model.target_skeleton)
    b = model.retarget(raised, model.target_skeleton)
    assert torch.allclose(
        b.global_positions().float(), a.global_positions().float() + lift, atol=1e-4
    )
    assert torch.allclose(b.rotations, a.rotations, atol=1e-4)
    za, zb = model.encode(motion), model.encode(raised)
    assert torch.allclose(za.z, zb.z, atol=1e-4)
    assert torch.allclose(zb.extras["centre"], za.extras["centre"] + lift, atol=1e-4)
    # without it the encoder sees another cloud
    with pytest.warns(ZeroLengthBoneWarning):
        plain = PcmrlReconAligner(target="biped31", centre_up=False, chunk=16, **pcmrl_tiny).eval()
    plain.load_state_dict(model.state_dict())
    za, zb = plain.encode(motion), plain.encode(raised)
    assert not torch.allclose(za.z, zb.z, atol=1e-2)
    assert torch.allclose(zb.extras["centre"], za.extras["centre"])


def test_checkpoints_from_before_canonical_yaw_and_centre_up_load_without_them(
    model, tmp_path
) -> None:
    import lightning as L

    trainer = L.Trainer(logger=False, enable_checkpointing=False, enable_progress_bar=False)
    trainer.strategy.connect(model)
    path = tmp_path / "old.ckpt"
    trainer.save_checkpoint(path)
    ckpt = torch.load(path, weights_only=False)
    for option in ("canonical_yaw", "centre_up"):
        del ckpt["hyper_parameters"][option]
    torch.save(ckpt, path)
    with pytest.warns(ZeroLengthBoneWarning):
        old = PcmrlReconAligner.load_from_checkpoint(path)
    assert old.hparams.canonical_yaw is False and old.hparams.centre_up is False


def test_retarget_returns_a_valid_motion_on_the_target(model, tmp_path) -> None:
    source = procedural.generate("biped22", "run", seconds=2.0)[0]  # cm
    target = procedural.skeleton("biped31")  # cm
    result = model.retarget(source, target)
    assert result.skeleton.joint_names == target.joint_names
    assert result.num_frames == source.num_frames and result.fps == source.fps
    assert result.units == "cm"
    assert torch.isfinite(result.rotations).all()
    assert torch.allclose(result.rotations.norm(dim=-1), torch.ones(()), atol=1e-5)
    # unpredicted joints (no non-zero bone below them) keep an identity local rotation
    head = target.index("Head")
    assert torch.allclose(result.rotations[:, head, 0].abs(), torch.ones(()), atol=1e-6)
    sa.write_bvh(result, tmp_path / "out.bvh")
    back = sa.read_bvh(tmp_path / "out.bvh")
    assert back.num_frames == result.num_frames
    assert torch.allclose(
        back.global_positions().float(), result.global_positions().float(), atol=1e-3
    )


def test_retarget_between_real_skeletons(lafan_clip, shared_data, pcmrl_tiny) -> None:
    cmu = shared_data / "human" / "cmu" / "131_01.bvh"
    torch.manual_seed(0)
    with pytest.warns(ZeroLengthBoneWarning, match="lowerback"):
        model = PcmrlReconAligner(
            target=str(cmu), target_units="cmu", chunk=16, **pcmrl_tiny
        ).eval()
    source = sa.read_bvh(lafan_clip)[:40]
    target = sa.read_bvh(cmu).skeleton
    result = model.retarget(source, target)
    assert result.skeleton.joint_names == target.joint_names
    assert result.units == "cmu" and result.num_frames == 40
    # the root stays near the source's, in the target's units (untrained: centroid + ~0)
    src_root_m = source.root_positions[:, [0, 2]] * 0.01
    out_root_m = result.root_positions[:, [0, 2]] * (0.0254 / 0.45)
    assert float((src_root_m - out_root_m).norm(dim=-1).max()) < 0.5
    pairs = end_effector_pairs(source.skeleton, target)
    assert {target.body_groups[b] for _, b in pairs} == {
        "spine",
        "left_arm",
        "right_arm",
        "left_leg",
        "right_leg",
    }


def test_wrong_target_and_stage_are_clear_errors(model, pcmrl_tiny) -> None:
    latent = model.encode(procedural.generate("biped22", "walk", seconds=0.5)[0])
    with pytest.raises(SkelagnosticError, match="trained target"):
        model.decode(latent, procedural.skeleton("biped17"))
    with pytest.raises(SkelagnosticError, match="pcmrl_interp"):
        PcmrlReconAligner(stage="interpolation")
    with pytest.raises(SkelagnosticError, match="no target skeleton"):
        PcmrlReconAligner(**pcmrl_tiny).heads(torch.zeros(1, 2, 32))


@pytest.mark.parametrize("layout", ["skelagnostic", "authors"])
def test_a_few_steps_reduce_the_knn_loss(pcmrl_tiny, layout) -> None:
    """Unsupervised learning signal: the KNN loss of one batch drops when optimised."""
    from skelagnostic_pcmrl.recon.losses import temporal_knn_loss

    torch.manual_seed(0)
    if layout == "authors":  # its temporal width is the frame feature's + 16
        pcmrl_tiny["temporal_dim"] = None
    with pytest.warns(ZeroLengthBoneWarning):
        model = PcmrlReconAligner(target="biped31", chunk=16, layout=layout, **pcmrl_tiny)
    assert model.encoder.layout == model.temporal.layout == layout
    torch.manual_seed(1)
    motion = procedural.generate("biped22", "walk", seconds=0.4)[0].convert_units("m")
    src = sample_layout(motion.skeleton, 64, 0.05, batch=(2,))
    pts = src.points(
        motion.global_rotations().float().expand(2, -1, -1, -1),
        motion.global_positions().float().expand(2, -1, -1, -1),
        motion.skeleton.offsets,
    )
    tgt = sample_layout(model.target_skeleton, 128, 0.05, batch=(2,))
    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(40):
        out = model.reconstruct(pts, src.groups)
        cloud = tgt.points(out["rotations"], out["positions"], model._target_offsets)
        loss = temporal_knn_loss(cloud, pts, tgt.groups, src.groups, k=8)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.75 * losses[0], losses


def test_authors_knn_alpha_follows_their_schedule_during_training(pcmrl_tiny) -> None:
    from types import SimpleNamespace

    model = PcmrlReconAligner(**pcmrl_tiny, knn_variant="authors", knn_alpha_warmup=10)
    assert model._knn_alpha() == 1.0  # no trainer: evaluation weight
    model._trainer = SimpleNamespace(max_steps=110, global_step=4)
    model.train()
    assert model._knn_alpha() == pytest.approx(0.5)  # step 5 of a 10-step ramp
    model._trainer.global_step = 59
    assert model._knn_alpha() == pytest.approx(0.5)  # halfway down from step 10 to 110
    model.eval()
    assert model._knn_alpha() == 1.0
    model._trainer = None
