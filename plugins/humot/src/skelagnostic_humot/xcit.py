"""Cross-covariance transformer blocks (XCiT, El-Nouby et al. 2021) over a joint x time grid.

HuMoT (Sec. 3.3) builds its encoder and decoder from XCiT blocks. Tokens are
laid out on a 2D grid ``[B, G, F, C]``: ``G`` skeleton tokens (joints, plus the
latent token in the encoder) by ``F`` frames, ``C`` channels. A block is, with
pre-normalisation and learnable per-channel layer scales ``gamma``::

    x = x + gamma1 * XCA(LN(x))          # attention between channels, over all G*F tokens
    x = x + gamma3 * LPI(LN(x))          # depthwise 3x3 convs over the G x F grid
    x = x + gamma2 * MLP(LN(x))

Variable joint counts in one batch are handled with a token mask ``[B, G]``
(valid tokens first, padding last): padded tokens are zeroed before every
operation that mixes tokens (the q/k/v of XCA, the LPI convolutions, the
LPI batch norm statistics) and after every sub-layer, so a padded sample gives
exactly the output of the same sample without padding.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

__all__ = ["XCA", "LocalPatchInteraction", "MaskedBatchNorm", "XCiTBlock"]


class XCA(nn.Module):
    """Cross-covariance attention: attention between feature channels instead of tokens.

    Queries, keys and values are split in ``heads`` groups of ``dim // heads``
    channels. Per head, q and k are L2-normalised along the token axis, the
    ``d x d`` channel attention is ``softmax(temperature * q k^T)`` with a
    learnable temperature per head, and the output is ``attention @ v``. The
    cost is linear in the number of tokens.

    Args:
        dim: Channels.
        heads: Attention heads (must divide ``dim``).
        qkv_bias: Bias of the q/k/v projection.
    """

    def __init__(self, dim: int = 128, heads: int = 8, qkv_bias: bool = True) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"heads ({heads}) must divide dim ({dim})")
        self.heads = heads
        self.temperature = nn.Parameter(torch.ones(heads, 1, 1))
        self.qkv = nn.Linear(dim, 3 * dim, bias=qkv_bias)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Apply the attention.

        The L2 normalisation of q and k along the tokens is applied to the small
        ``d x d`` product ``q^T k`` (divided by the outer product of the norms)
        instead of to the ``N x d`` tensors: the same value, without two passes
        over all tokens in the forward and backward passes. Tokens stay in
        ``[B, H, N, d]`` layout throughout (no transposed copies).

        Args:
            x: ``[B, N, C]`` tokens.
            mask: ``[B, N]`` valid tokens (``None``: all).

        Returns:
            ``[B, N, C]``, zero on padded tokens.
        """
        b, n, c = x.shape
        qkv = self.qkv(x)
        if mask is not None:
            qkv = qkv * mask[..., None].to(qkv.dtype)
        q, k, v = qkv.reshape(b, n, 3, self.heads, c // self.heads).permute(2, 0, 3, 1, 4)
        # F.normalize(q, dim=tokens) == q / max(|q|, eps)
        q_norm = torch.linalg.vector_norm(q, dim=-2).clamp_min(1e-12)  # [B, H, d]
        k_norm = torch.linalg.vector_norm(k, dim=-2).clamp_min(1e-12)
        attn = (q.transpose(-2, -1) @ k) / (q_norm[..., :, None] * k_norm[..., None, :])
        attn = (attn * self.temperature).softmax(dim=-1)  # [B, H, d, d]
        out = v @ attn.transpose(-2, -1)  # [B, H, N, d]: out[n, i] = sum_j attn[i, j] v[n, j]
        out = self.proj(out.transpose(1, 2).reshape(b, n, c))
        if mask is not None:
            out = out * mask[..., None].to(out.dtype)
        return out


class MaskedBatchNorm(nn.BatchNorm2d):
    """``BatchNorm2d`` whose training statistics ignore padded grid cells.

    In training with a mask, the valid cells are gathered and normalised by
    :func:`torch.nn.functional.batch_norm` (same statistics, running-statistics
    update and unbiased running variance as :class:`torch.nn.BatchNorm2d` on
    those cells alone). In eval mode the running statistics are used as usual.
    With a mask, padded cells of the output are zero; without one it is
    :class:`torch.nn.BatchNorm2d`.
    """

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Normalise ``x`` ``[B, C, G, F]``; training statistics use the rows ``G`` of ``mask``."""
        if mask is None:
            return super().forward(x)
        if not self.training:
            return super().forward(x) * mask[:, None, :, None].to(x.dtype)
        b, c, g, f = x.shape
        factor = 0.0
        if self.track_running_stats and self.num_batches_tracked is not None:
            self.num_batches_tracked.add_(1)
            factor = (self.momentum if self.momentum is not None
                      else 1.0 / float(self.num_batches_tracked))
        grid = x.permute(0, 2, 3, 1)  # [B, G, F, C]: contiguous for channels-last input
        valid = grid[mask]  # [N, F, C]
        normed = F.batch_norm(valid.reshape(-1, c), self.running_mean, self.running_var,
                              self.weight, self.bias, True, factor, self.eps)
        out = grid.new_zeros(b, g, f, c)
        out[mask] = normed.reshape(valid.shape)
        return out.permute(0, 3, 1, 2)


class LocalPatchInteraction(nn.Module):
    """Two depthwise 3x3 convolutions over the token grid, GELU and batch norm in between.

    Args:
        dim: Channels.
        kernel_size: Size of the (square) depthwise kernels.
    """

    def __init__(self, dim: int = 128, kernel_size: int = 3) -> None:
        super().__init__()
        pad = kernel_size // 2
        self.conv1 = nn.Conv2d(dim, dim, kernel_size, padding=pad, groups=dim)
        self.act = nn.GELU()
        self.bn = MaskedBatchNorm(dim)
        self.conv2 = nn.Conv2d(dim, dim, kernel_size, padding=pad, groups=dim)

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """``[B, G, F, C]`` tokens (mask ``[B, G]``) -> ``[B, G, F, C]``.

        The convolutions run on a channels-last view of the tokens (no copies);
        padded cells are zeroed before each convolution and in the output.
        """
        cells = None if mask is None else mask[:, :, None, None].to(x.dtype)
        if cells is not None:
            x = x * cells
        h = self.bn(self.act(self.conv1(x.permute(0, 3, 1, 2))), mask)  # padded cells: 0
        h = self.conv2(h).permute(0, 2, 3, 1)
        if cells is not None:
            h = h * cells
        return h


class XCiTBlock(nn.Module):
    """Pre-norm XCiT block: XCA, local patch interaction and MLP, each with a layer scale.

    Args:
        dim: Channels.
        heads: Attention heads.
        mlp_ratio: Hidden width of the MLP relative to ``dim``.
        layer_scale: Initial value of the per-channel residual scales (XCiT's ``eta``).
        lpi_kernel: Kernel size of the local patch interaction.
    """

    def __init__(self, dim: int = 128, heads: int = 8, mlp_ratio: float = 4.0,
                 layer_scale: float = 1.0, lpi_kernel: int = 3) -> None:
        super().__init__()
        hidden = int(dim * mlp_ratio)
        self.norm1 = nn.LayerNorm(dim)
        self.attn = XCA(dim, heads)
        self.norm3 = nn.LayerNorm(dim)
        self.local_mp = LocalPatchInteraction(dim, lpi_kernel)
        self.norm2 = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(nn.Linear(dim, hidden), nn.GELU(), nn.Linear(hidden, dim))
        self.gamma1 = nn.Parameter(layer_scale * torch.ones(dim))
        self.gamma3 = nn.Parameter(layer_scale * torch.ones(dim))
        self.gamma2 = nn.Parameter(layer_scale * torch.ones(dim))

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Apply the block.

        Args:
            x: ``[B, G, F, C]`` tokens on the joint x time grid.
            mask: ``[B, G]`` valid skeleton tokens (``None``: all).

        Returns:
            ``[B, G, F, C]``; padded tokens are zero.
        """
        b, g, f, c = x.shape
        cells = None if mask is None else mask[:, :, None, None].to(x.dtype)
        flat_mask = None if mask is None else mask[:, :, None].expand(b, g, f).reshape(b, g * f)
        x = x + self.gamma1 * self.attn(self.norm1(x).reshape(b, g * f, c), flat_mask).reshape(
            b, g, f, c)
        x = x + self.gamma3 * self.local_mp(self.norm3(x), mask)
        x = x + self.gamma2 * self.mlp(self.norm2(x))
        if cells is not None:
            x = x * cells
        return x
