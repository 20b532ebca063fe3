from dataclasses import MISSING, fields
from importlib.resources import files

import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.model import (
    HuMoT,
    HuMoTConfig,
    bone_length_consistency_loss,
    reconstruction_loss,
    temporal_positional_encoding,
)

from skelagnostic.metrics.functional import bone_length_consistency
from skelagnostic.plugins import read_aligner_config

PAPER_PARAMETERS = 2_475_511


def test_parameter_count_matches_the_paper_within_ten_percent():
    count = sum(p.numel() for p in HumotAligner().net.parameters())
    assert abs(count - PAPER_PARAMETERS) / PAPER_PARAMETERS < 0.10


@pytest.mark.parametrize(("src", "dst"), [(22, 31), (31, 17), (17, 17)])
def test_shapes_with_different_joint_counts(src, dst, humot_small):
    net = HumotAligner(**humot_small).net
    z = net.encoder(torch.randn(2, 30, src, 3), torch.randn(2, src, 3))
    assert z.shape == (2, 30, humot_small["latent"])
    assert net.decoder(z, torch.randn(2, dst, 3)).shape == (2, 30, dst, 3)


def test_latent_is_independent_of_padding(humot_small):
    torch.manual_seed(0)
    net = HumotAligner(**humot_small).net.eval()
    x, t = torch.randn(1, 12, 5, 3), torch.randn(1, 5, 3)
    xp = torch.cat([x, torch.randn(1, 12, 2, 3)], dim=2)
    tp = torch.cat([t, torch.randn(1, 2, 3)], dim=1)
    mask = torch.tensor([[True] * 5 + [False] * 2])
    assert torch.allclose(net.encoder(xp, tp, mask), net.encoder(x, t), atol=1e-5)
    z = net.encoder(x, t)
    out = net.decoder(z, tp, mask)
    assert torch.allclose(out[:, :, :5], net.decoder(z, t), atol=1e-5)
    assert out[:, :, 5:].abs().max() == 0


def test_mask_must_put_valid_joints_first(humot_small):
    net = HumotAligner(**humot_small).net
    with pytest.raises(ValueError, match="first"):
        net.encoder(torch.randn(1, 4, 3, 3), torch.randn(1, 3, 3), torch.tensor([[1, 0, 1]]))


def test_joint_order_matters_only_through_local_interaction(humot_small):
    """XCA and the joint-wise layers are order-free; the LPI convs see joint neighbours."""
    torch.manual_seed(0)
    net = HumotAligner(**humot_small).net.eval()
    x, t = torch.randn(1, 10, 6, 3), torch.randn(1, 6, 3)
    perm = torch.tensor([5, 4, 3, 2, 1, 0])
    z = net.encoder(x, t)
    assert not torch.allclose(net.encoder(x[:, :, perm], t[:, perm]), z, atol=1e-4)
    for block in (*net.encoder.blocks, *net.decoder.blocks):
        torch.nn.init.zeros_(block.gamma3)  # switch the local patch interaction off
    z = net.encoder(x, t)
    assert torch.allclose(net.encoder(x[:, :, perm], t[:, perm]), z, atol=1e-5)
    out = net.decoder(z, t)
    assert torch.allclose(net.decoder(z, t[:, perm]), out[:, :, perm], atol=1e-5)


def test_gradients_reach_every_parameter(humot_small):
    torch.manual_seed(0)
    net = HumotAligner(**humot_small).net
    x, t = torch.randn(2, 8, 5, 3), torch.randn(2, 5, 3)
    mask = torch.tensor([[True] * 5, [True] * 3 + [False] * 2])
    pred = net(x, t, t[:, :4], mask, torch.tensor([[True] * 4, [True] * 2 + [False] * 2]))
    reconstruction_loss(pred, x[:, :, :4]).backward()
    missing = [n for n, p in net.named_parameters() if p.grad is None or p.grad.abs().sum() == 0]
    assert not missing


def test_positional_encoding():
    pe = temporal_positional_encoding(30, 8)
    assert pe.shape == (30, 8)
    assert torch.allclose(pe[0], torch.tensor([0.0, 1.0] * 4))
    assert torch.allclose(pe[5, 0], torch.sin(torch.tensor(5.0)))


class TestLosses:
    def test_reconstruction_is_eq1(self):
        target = torch.zeros(1, 2, 2, 3)
        preds = torch.zeros(1, 2, 2, 3)
        preds[0, 0, 0] = torch.tensor([1.0, 2.0, 2.0])  # squared norm 9
        assert reconstruction_loss(preds, target).item() == pytest.approx(9 / 4)

    def test_reconstruction_with_mask_is_per_sample(self):
        torch.manual_seed(0)
        p, t = torch.randn(2, 4, 3, 3), torch.randn(2, 4, 3, 3)
        mask = torch.tensor([[True, True, False], [True, True, True]])
        expected = (
            reconstruction_loss(p[:1, :, :2], t[:1, :, :2]) + reconstruction_loss(p[1:], t[1:])
        ) / 2
        assert reconstruction_loss(p, t, mask).item() == pytest.approx(expected.item())

    def test_blc_by_hand(self):
        # one bone of true length 2; predicted lengths 2, 4, 6 -> ratios 1, 2, 3 -> variance 2/3
        target = torch.zeros(1, 3, 2, 3)
        target[0, :, 1, 1] = 2.0
        preds = torch.zeros(1, 3, 2, 3)
        preds[0, :, 1, 1] = torch.tensor([2.0, 4.0, 6.0])
        loss = bone_length_consistency_loss(preds, target, torch.tensor([[[0, 1]]]))
        assert loss.item() == pytest.approx(2 / 3)

    def test_blc_matches_the_metric(self):
        torch.manual_seed(0)
        target, preds = torch.randn(3, 10, 4, 3), torch.randn(3, 10, 4, 3)
        bones = [(0, 1), (1, 2), (1, 3)]
        ours = bone_length_consistency_loss(preds, target, torch.tensor(bones).expand(3, -1, -1))
        assert ours.item() == pytest.approx(
            bone_length_consistency(preds, target, bones).item(), rel=1e-5
        )

    def test_blc_skips_zero_length_and_padded_bones(self):
        target = torch.zeros(1, 3, 3, 3)
        target[0, :, 2, 0] = 1.0  # bone (0, 1) has zero length, bone (0, 2) length 1
        preds = target.clone()
        preds[0, :, 1, 0] = torch.tensor([0.0, 1.0, 2.0])
        bones = torch.tensor([[[0, 1], [0, 2], [0, 0]]])
        loss = bone_length_consistency_loss(
            preds, target, bones, torch.tensor([[True, True, False]])
        )
        assert loss.item() == 0.0


def test_the_network_sizes_have_one_source():
    """``HuMoTConfig`` lists the sizes without defaults; the aligner fills them from its YAML."""
    assert all(f.default is MISSING for f in fields(HuMoTConfig))
    yaml = read_aligner_config(files("skelagnostic_humot.conf") / "humot.yaml")["model"]
    config = HumotAligner().net.config
    assert {f.name: getattr(config, f.name) for f in fields(config)} == {
        f.name: yaml[f.name] for f in fields(config)
    }
    with pytest.raises(TypeError):
        HuMoT()
