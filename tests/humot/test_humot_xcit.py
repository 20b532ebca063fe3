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
        block = XCiTBlock(32, 4, mlp_ratio=4.0, layer_scale=1.0)
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
        block = XCiTBlock(32, 4, mlp_ratio=4.0, layer_scale=1.0).eval()
        a, b = torch.randn(1, 4, 8, 32), torch.randn(1, 7, 8, 32)
        batch = torch.cat([torch.cat([a, torch.zeros(1, 3, 8, 32)], 1), b])
        mask = torch.tensor([[True] * 4 + [False] * 3, [True] * 7])
        out = block(batch, mask)
        assert torch.allclose(out[0, :4], block(a)[0], atol=1e-5)
        assert torch.allclose(out[1], block(b)[0], atol=1e-5)


# --------------------------------------------------------------------------------------------
# The optimised layers against a direct transcription of the definitions (the first version of
# this module): q, k normalised along the tokens before q k^T; batch-norm statistics as masked
# sums over the grid.


def _reference_xca(attn: XCA, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    b, n, c = x.shape
    qkv = attn.qkv(x).reshape(b, n, 3, attn.heads, c // attn.heads).permute(2, 0, 3, 4, 1)
    q, k, v = qkv[0], qkv[1], qkv[2]  # [B, H, d, N]
    if mask is not None:
        keep = mask[:, None, None, :].to(x.dtype)
        q, k, v = q * keep, k * keep, v * keep
    normalize = torch.nn.functional.normalize
    a = normalize(q, dim=-1) @ normalize(k, dim=-1).transpose(-2, -1)
    out = (a * attn.temperature).softmax(dim=-1) @ v
    out = attn.proj(out.permute(0, 3, 1, 2).reshape(b, n, c))
    return out if mask is None else out * mask[..., None].to(out.dtype)


def _reference_lpi(lpi: LocalPatchInteraction, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    cells = mask[:, None, :, None].to(x.dtype)
    h = lpi.conv1(x.permute(0, 3, 1, 2) * cells)
    h = lpi.act(h)
    count = cells.expand(h.shape[0], 1, h.shape[2], h.shape[3]).sum()
    mean = (h * cells).sum(dim=(0, 2, 3)) / count
    var = (((h - mean[None, :, None, None]) ** 2) * cells).sum(dim=(0, 2, 3)) / count
    h = (h - mean[None, :, None, None]) / torch.sqrt(var[None, :, None, None] + lpi.bn.eps)
    h = (h * lpi.bn.weight[None, :, None, None] + lpi.bn.bias[None, :, None, None]) * cells
    return (lpi.conv2(h) * cells).permute(0, 2, 3, 1)


def _values_and_grads(fn, module: torch.nn.Module, x: torch.Tensor, seed: torch.Tensor):
    module.zero_grad()
    xi = x.detach().clone().requires_grad_()
    out = fn(xi)
    (out * seed).sum().backward()
    return [out.detach(), xi.grad, *(p.grad.clone() for p in module.parameters())]


def _assert_close(ours, ref, rtol=1e-4):
    for a, b in zip(ours, ref, strict=True):
        scale = b.abs().max().clamp_min(1e-6)
        assert (a - b).abs().max() / scale < rtol


@pytest.mark.parametrize("masked", [False, True])
def test_xca_equals_reference_values_and_gradients(masked):
    torch.manual_seed(0)
    attn = XCA(32, 4)
    x = torch.randn(3, 40, 32)
    mask = (torch.arange(40)[None] < torch.tensor([[40], [25], [7]])) if masked else None
    seed = torch.randn(3, 40, 32)
    ours = _values_and_grads(lambda t: attn(t, mask), attn, x, seed)
    ref = _values_and_grads(lambda t: _reference_xca(attn, t, mask), attn, x, seed)
    _assert_close(ours, ref)


def test_lpi_equals_reference_values_gradients_and_running_stats():
    torch.manual_seed(0)
    lpi, twin = LocalPatchInteraction(16), LocalPatchInteraction(16)
    twin.load_state_dict(lpi.state_dict())
    x = torch.randn(3, 7, 10, 16)
    mask = torch.arange(7)[None] < torch.tensor([[7], [4], [2]])
    seed = torch.randn(3, 7, 10, 16)
    ours = _values_and_grads(lambda t: lpi(t, mask), lpi, x, seed)
    ref = _values_and_grads(lambda t: _reference_lpi(twin, t, mask), twin, x, seed)
    _assert_close(ours, ref)
    # running statistics: as BatchNorm2d on the valid cells only (unbiased running variance)
    h = twin.act(twin.conv1(x.permute(0, 3, 1, 2) * mask[:, None, :, None]))
    cells = h.permute(0, 2, 3, 1)[mask].reshape(-1, 16)
    expected_mean = 0.1 * cells.mean(0).detach()
    expected_var = 0.9 + 0.1 * cells.var(0, correction=1).detach()
    assert torch.allclose(lpi.bn.running_mean, expected_mean, atol=1e-6)
    assert torch.allclose(lpi.bn.running_var, expected_var, atol=1e-5)
    assert int(lpi.bn.num_batches_tracked) == 1


def test_masked_batchnorm_eval_zeroes_padded_cells():
    bn = MaskedBatchNorm(4).eval()
    x = torch.randn(2, 4, 5, 3)
    mask = torch.tensor([[True] * 5, [True] * 2 + [False] * 3])
    out = bn(x, mask)
    assert out[1, :, 2:].abs().max() == 0
    assert torch.allclose(out[0], torch.nn.BatchNorm2d(4).eval()(x)[0])
