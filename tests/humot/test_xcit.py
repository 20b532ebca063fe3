import pytest
import torch
from skelagnostic_humot.xcit import XCA, LocalPatchInteraction, MaskedBatchNorm, XCiTBlock
from torch.utils.flop_counter import FlopCounterMode


class TestXCA:
    def test_shapes(self):
        attn = XCA(32, 4)
        for n in (1, 7, 50):
            assert attn(torch.randn(3, n, 32)).shape == (3, n, 32)

    def test_heads_must_divide_dim(self):
        with pytest.raises(ValueError, match="heads"):
            XCA(30, 4)

    def test_cost_is_linear_in_tokens(self):
        attn = XCA(32, 4)

        def flops(n):
            with FlopCounterMode(display=False) as counter:
                attn(torch.randn(1, n, 32))
            return counter.get_total_flops()

        assert flops(400) == pytest.approx(2 * flops(200), rel=1e-6)
        assert flops(800) == pytest.approx(4 * flops(200), rel=1e-6)

    def test_token_permutation_equivariance(self):
        torch.manual_seed(0)
        attn = XCA(32, 4)
        x = torch.randn(2, 20, 32)
        perm = torch.randperm(20)
        assert torch.allclose(attn(x)[:, perm], attn(x[:, perm]), atol=1e-5)

    def test_padding_does_not_change_valid_tokens(self):
        torch.manual_seed(0)
        attn = XCA(32, 4)
        x = torch.randn(1, 10, 32)
        padded = torch.cat([x, torch.randn(1, 5, 32)], dim=1)
        mask = torch.arange(15)[None] < 10
        out = attn(padded, mask)
        assert torch.allclose(out[:, :10], attn(x), atol=1e-5)
        assert out[:, 10:].abs().max() == 0


def test_masked_batchnorm_matches_batchnorm2d_with_full_mask():
    torch.manual_seed(0)
    ours, ref = MaskedBatchNorm(8), torch.nn.BatchNorm2d(8)
    x = torch.randn(4, 8, 5, 6)
    out = ours(x, torch.ones(4, 5, dtype=torch.bool))
    assert torch.allclose(out, ref(x), atol=1e-5)
    assert torch.allclose(ours.running_mean, ref.running_mean, atol=1e-6)
    assert torch.allclose(ours.running_var, ref.running_var, atol=1e-5)


def test_lpi_mixes_neighbours_only():
    lpi = LocalPatchInteraction(4).eval()
    x = torch.zeros(1, 9, 9, 4)
    x[0, 4, 4] = 1.0
    out = lpi(x) - lpi(torch.zeros_like(x))
    touched = out.abs().sum(-1)[0] > 0
    assert touched[2:7, 2:7].all() and touched.sum() == 25  # two 3x3 convs reach 2 cells


class TestBlock:
    def test_padded_sample_equals_unpadded(self):
        torch.manual_seed(0)
        block = XCiTBlock(32, 4)
        x = torch.randn(1, 6, 10, 32)
        padded = torch.cat([x, torch.randn(1, 3, 10, 32)], dim=1)
        mask = torch.arange(9)[None] < 6
        block.train()
        out = block(padded, mask)
        ref = block(x)
        assert torch.allclose(out[:, :6], ref, atol=1e-5)
        assert out[:, 6:].abs().max() == 0

    def test_mixed_batch_equals_per_sample(self):
        torch.manual_seed(0)
        block = XCiTBlock(32, 4).eval()
        a, b = torch.randn(1, 4, 8, 32), torch.randn(1, 7, 8, 32)
        batch = torch.cat([torch.cat([a, torch.zeros(1, 3, 8, 32)], 1), b])
        mask = torch.tensor([[True] * 4 + [False] * 3, [True] * 7])
        out = block(batch, mask)
        assert torch.allclose(out[0, :4], block(a)[0], atol=1e-5)
        assert torch.allclose(out[1], block(b)[0], atol=1e-5)
