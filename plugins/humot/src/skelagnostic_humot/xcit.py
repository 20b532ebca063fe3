"""Cross-covariance transformer blocks (XCiT, El-Nouby et al. 2021) over a joint x time grid.

HuMoT (Sec. 3.3) builds its encoder and decoder from XCiT blocks. Tokens are
laid out on a 2D grid ``[B, G, F, C]``: ``G`` skeleton tokens (joints, plus the
latent token in the encoder) by ``F`` frames, ``C`` channels. A block is, with
pre-normalisation and learnable per-channel layer scales ``gamma``::

    x = x + gamma1 * XCA(LN(x))          # attention between channels, per frame (see below)
    x = x + gamma3 * LPI(LN(x))          # depthwise 3x3 convs over the G x F grid
    x = x + gamma2 * MLP(LN(x))

**The span of XCA's map** (``scope``). XCA computes one ``d x d`` channel map
from the covariance of a set of tokens. With ``scope="frame"`` (the default)
the set is one frame's ``G`` tokens: the map of frame ``f`` is built from that
frame's joints, so what the latent token reads at frame ``f`` depends on every
joint at frame ``f``. This is how we read the paper (Sec. 3.3: the transformer
keeps "the sequence-to-sequence paradigm ... along the temporal dimension" and
acts as a "sequence-to-item" function over the joints; the token sequence is
the ``J + 1`` joints, frames are carried along). ``scope="sequence"`` computes
one map over all ``G x F`` tokens of a sample (XCiT's image reading applied to
the grid): the map then averages over the frames, and only the LPI convolutions
carry a joint's frame-local features towards the latent token, one or two rows
per block, so most joints cannot reach the latent of their frame
(``docs/reports/humot.md``, "Receptive field").

Variable joint counts in one batch are handled with a token mask ``[B, G]``
(valid tokens first, padding last): padded tokens are zeroed before every
operation that mixes tokens (the q/k/v of XCA, the LPI convolutions, the
LPI batch norm statistics) and after every sub-layer, so a padded sample gives
exactly the output of the same sample without padding.

**Packed tokens.** The same blocks also run on the valid tokens alone
(:meth:`XCiTBlock.forward_packed`): a :class:`TokenLayout` lists the valid
cells of the grid, the token-wise layers (layer norms, q/k/v and output
projections, MLP, batch norm) see only those ``N`` rows ``[N, C]``, and the grid
is rebuilt (zeros on padding) only where tokens mix: the ``d x d`` attention
of XCA and the LPI convolutions. The values are those of the padded
computation (the padded cells it computes are zeros or discarded), at the
cost of the valid tokens instead of the worst case of the batch. The layer
scales ``gamma`` are folded into the weights of the layer before them (the
output projection, the second LPI convolution, the MLP's second linear):
``gamma * (W x + b) = (gamma W) x + gamma b``, one pass over the tokens less
per sub-layer, forward and backward.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

__all__ = [
    "XCA",
    "XCA_SCOPES",
    "LocalPatchInteraction",
    "MaskedBatchNorm",
    "TokenLayout",
    "XCiTBlock",
]

#: The token sets XCA's channel map may span on the joint x time grid (see the module text).
XCA_SCOPES = ("frame", "sequence")


def _scaled_linear(x: torch.Tensor, linear: nn.Linear, scale: torch.Tensor | None) -> torch.Tensor:
    """``scale * linear(x)`` with the per-channel ``scale`` folded into the weights and bias."""
    if scale is None:
        return linear(x)
    bias = None if linear.bias is None else linear.bias * scale
    return F.linear(x, linear.weight * scale[:, None], bias)


class _Pack(torch.autograd.Function):
    """``rows.index_select(0, index)`` for unique ``index``, with a scatter-free backward.

    The gradient goes back with :meth:`torch.Tensor.index_copy_` (each row
    receives one value) instead of ``index_select``'s accumulating
    ``index_add``, which is several times slower on CPU with two threads.
    """

    @staticmethod
    def forward(ctx: Any, rows: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(index)
        ctx.num_rows = rows.shape[0]
        return rows.index_select(0, index)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (index,) = ctx.saved_tensors
        out = grad.new_zeros(ctx.num_rows, *grad.shape[1:])
        return out.index_copy_(0, index, grad), None


@dataclass(frozen=True)
class TokenLayout:
    """The valid cells of a ``[B, G, F]`` token grid, to compute on them alone.

    Build it with :meth:`of`. ``index`` lists the flat indices (in ``B, G, F``
    order) of the cells of the valid rows ``G``; ``None`` means every cell is
    valid, and :meth:`pack` / :meth:`unpack` are then reshapes. Because a valid
    row keeps all its frames, the packed tokens ``[N, C]`` reshape to
    ``[N / F, F, C]``: one sequence per valid (sample, row).

    Attributes:
        batch: ``B``.
        rows: ``G``.
        frames: ``F``.
        index: ``[N]`` flat indices of the valid cells, ascending (``None``: all).
    """

    batch: int
    rows: int
    frames: int
    index: torch.Tensor | None

    @classmethod
    def of(
        cls,
        mask: torch.Tensor | None,
        frames: int,
        batch: int | None = None,
        rows: int | None = None,
    ) -> TokenLayout:
        """The layout of the rows ``mask`` ``[B, G]`` marks valid, each with ``frames`` frames.

        Args:
            mask: ``[B, G]`` valid rows (``None``: all, then ``batch`` and ``rows`` are needed).
            frames: ``F``.
            batch: ``B`` when ``mask`` is ``None``.
            rows: ``G`` when ``mask`` is ``None``.

        Raises:
            ValueError: Neither a mask nor both sizes are given.
        """
        if mask is None:
            if batch is None or rows is None:
                raise ValueError("TokenLayout.of: give a mask or both batch and rows")
            return cls(batch, rows, frames, None)
        b, g = mask.shape
        if bool(mask.all()):
            return cls(b, g, frames, None)
        cells = mask.bool()[:, :, None].expand(b, g, frames)
        return cls(b, g, frames, cells.reshape(-1).nonzero().flatten())

    @property
    def cells(self) -> int:
        """``B * G * F``."""
        return self.batch * self.rows * self.frames

    def pack(self, grid: torch.Tensor) -> torch.Tensor:
        """``[B, G, F, C]`` -> ``[N, C]``: the valid cells."""
        flat = grid.reshape(self.cells, grid.shape[-1])
        return flat if self.index is None else _Pack.apply(flat, self.index)

    def unpack(self, tokens: torch.Tensor) -> torch.Tensor:
        """``[N, C]`` -> ``[B, G, F, C]``, zero on padded cells."""
        c = tokens.shape[-1]
        if self.index is not None:
            tokens = tokens.new_zeros(self.cells, c).index_copy_(0, self.index, tokens)
        return tokens.reshape(self.batch, self.rows, self.frames, c)

    def frame_rows(self) -> torch.Tensor | None:
        """``[N]`` index ``b * F + f`` of each valid cell into ``[B * F]`` (``None``: all cells)."""
        if self.index is None:
            return None
        sample = self.index // (self.rows * self.frames)
        return sample * self.frames + self.index % self.frames


class XCA(nn.Module):
    """Cross-covariance attention: attention between feature channels instead of tokens.

    Queries, keys and values are split in ``heads`` groups of ``dim // heads``
    channels. Per head, q and k are L2-normalised along the token axis, the
    ``d x d`` channel attention is ``softmax(temperature * q k^T)`` with a
    learnable temperature per head, and the output is ``attention @ v``. The
    cost is linear in the number of tokens.

    :meth:`forward` attends over each set ``[N, C]`` it is given; on the joint x
    time grid (:meth:`forward_grid`, :meth:`forward_packed`) ``scope`` says which
    tokens form a set: one frame's (``"frame"``) or a whole sample's (``"sequence"``).

    Args:
        dim: Channels.
        heads: Attention heads (must divide ``dim``).
        qkv_bias: Bias of the q/k/v projection.
        scope: ``"frame"`` or ``"sequence"`` (:data:`XCA_SCOPES`).
    """

    def __init__(self, dim: int, heads: int, qkv_bias: bool = True, scope: str = "frame") -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"heads ({heads}) must divide dim ({dim})")
        if scope not in XCA_SCOPES:
            raise ValueError(f"scope must be one of {XCA_SCOPES}, got {scope!r}")
        self.scope = scope
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
        qkv = self.qkv(x)
        if mask is not None:
            qkv = qkv * mask[..., None].to(qkv.dtype)
        out = self.proj(self._attend(qkv))
        if mask is not None:
            out = out * mask[..., None].to(out.dtype)
        return out

    def forward_grid(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`forward` on the joint x time grid, one map per ``scope`` set.

        Args:
            x: ``[B, G, F, C]`` tokens.
            mask: ``[B, G]`` valid rows (``None``: all).

        Returns:
            ``[B, G, F, C]``, zero on padded rows.
        """
        b, g, f, c = x.shape
        if self.scope == "sequence":
            flat = None if mask is None else mask[:, :, None].expand(b, g, f).reshape(b, g * f)
            return self(x.reshape(b, g * f, c), flat).reshape(b, g, f, c)
        frames = x.transpose(1, 2).reshape(b * f, g, c)
        per_frame = None if mask is None else mask[:, None].expand(b, f, g).reshape(b * f, g)
        return self(frames, per_frame).reshape(b, f, g, c).transpose(1, 2)

    def forward_packed(
        self, x: torch.Tensor, layout: TokenLayout, scale: torch.Tensor | None = None
    ) -> torch.Tensor:
        """:meth:`forward_grid` on the valid tokens ``x`` ``[N, C]`` of ``layout``: ``[N, C]``.

        The q/k/v and output projections see the ``N`` valid tokens only; the
        channel attention runs on the grid rebuilt with zeros on padded cells,
        exactly as :meth:`forward_grid` with the layout's mask.

        Args:
            x: ``[N, C]`` valid tokens.
            layout: Where they sit on the grid.
            scale: ``[C]`` per-channel factor of the output (a layer scale), folded
                into the output projection's weights (``None``: 1).
        """
        qkv = layout.unpack(self.qkv(x))
        b, g, f, c3 = qkv.shape
        if self.scope == "sequence":
            out = self._attend(qkv.reshape(b, g * f, c3)).reshape(b, g, f, c3 // 3)
        else:
            out = self._attend(qkv.transpose(1, 2).reshape(b * f, g, c3))
            out = out.reshape(b, f, g, c3 // 3).transpose(1, 2)
        return _scaled_linear(layout.pack(out), self.proj, scale)

    def _attend(self, qkv: torch.Tensor) -> torch.Tensor:
        """``[B, N, 3C]`` queries, keys, values (zero on padded tokens) -> ``[B, N, C]``."""
        b, n, c3 = qkv.shape
        c = c3 // 3
        q, k, v = qkv.reshape(b, n, 3, self.heads, c // self.heads).permute(2, 0, 3, 1, 4)
        # F.normalize(q, dim=tokens) == q / max(|q|, eps)
        q_norm = torch.linalg.vector_norm(q, dim=-2).clamp_min(1e-12)  # [B, H, d]
        k_norm = torch.linalg.vector_norm(k, dim=-2).clamp_min(1e-12)
        attn = (q.transpose(-2, -1) @ k) / (q_norm[..., :, None] * k_norm[..., None, :])
        attn = (attn * self.temperature).softmax(dim=-1)  # [B, H, d, d]
        out = v @ attn.transpose(-2, -1)  # [B, H, N, d]: out[n, i] = sum_j attn[i, j] v[n, j]
        return out.transpose(1, 2).reshape(b, n, c)


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
        grid = x.permute(0, 2, 3, 1)  # [B, G, F, C]: contiguous for channels-last input
        valid = grid[mask]  # [N, F, C]
        normed = self.normalize_tokens(valid.reshape(-1, c))
        out = grid.new_zeros(b, g, f, c)
        out[mask] = normed.reshape(valid.shape)
        return out.permute(0, 3, 1, 2)

    def normalize_tokens(self, tokens: torch.Tensor) -> torch.Tensor:
        """Batch-normalise ``[N, C]`` valid cells (batch statistics in training, running in eval).

        In training, updates the running statistics as :class:`torch.nn.BatchNorm2d`
        would on these cells alone.
        """
        factor = 0.0
        if self.training and self.track_running_stats and self.num_batches_tracked is not None:
            self.num_batches_tracked.add_(1)
            factor = (
                self.momentum
                if self.momentum is not None
                else 1.0 / float(self.num_batches_tracked)
            )
        return F.batch_norm(
            tokens,
            self.running_mean,
            self.running_var,
            self.weight,
            self.bias,
            self.training or not self.track_running_stats,
            factor,
            self.eps,
        )


class LocalPatchInteraction(nn.Module):
    """Two depthwise 3x3 convolutions over the token grid, GELU and batch norm in between.

    Args:
        dim: Channels.
        kernel_size: Size of the (square) depthwise kernels.
    """

    def __init__(self, dim: int, kernel_size: int = 3) -> None:
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

    def forward_packed(
        self, x: torch.Tensor, layout: TokenLayout, scale: torch.Tensor | None = None
    ) -> torch.Tensor:
        """:meth:`forward` on the valid tokens ``x`` ``[N, C]`` of ``layout``: ``[N, C]``.

        The convolutions run on the grid rebuilt with zeros on padded cells; the
        GELU and the batch norm (plain batch statistics of the valid cells) on
        the valid tokens only.

        Args:
            x: ``[N, C]`` valid tokens.
            layout: Where they sit on the grid.
            scale: ``[C]`` per-channel factor of the output, folded into the second
                (depthwise) convolution's weights (``None``: 1).
        """
        h = self.conv1(layout.unpack(x).permute(0, 3, 1, 2)).permute(0, 2, 3, 1)
        h = self.bn.normalize_tokens(self.act(layout.pack(h)))
        conv = self.conv2
        weight, bias = conv.weight, conv.bias
        if scale is not None:
            weight = weight * scale[:, None, None, None]
            bias = None if bias is None else bias * scale
        out = F.conv2d(
            layout.unpack(h).permute(0, 3, 1, 2), weight, bias, conv.stride, conv.padding,
            conv.dilation, conv.groups,
        )  # fmt: skip
        return layout.pack(out.permute(0, 2, 3, 1))


class XCiTBlock(nn.Module):
    """Pre-norm XCiT block: XCA, local patch interaction and MLP, each with a layer scale.

    Args:
        dim: Channels.
        heads: Attention heads.
        mlp_ratio: Hidden width of the MLP relative to ``dim``.
        layer_scale: Initial value of the per-channel residual scales (XCiT's ``eta``).
        lpi_kernel: Kernel size of the local patch interaction.
        xca_scope: The tokens each XCA map spans: ``"frame"`` or ``"sequence"``
            (:data:`XCA_SCOPES`, the module text).
    """

    def __init__(
        self,
        dim: int,
        heads: int,
        mlp_ratio: float,
        layer_scale: float,
        lpi_kernel: int = 3,
        xca_scope: str = "frame",
    ) -> None:
        super().__init__()
        hidden = int(dim * mlp_ratio)
        self.norm1 = nn.LayerNorm(dim)
        self.attn = XCA(dim, heads, scope=xca_scope)
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
        cells = None if mask is None else mask[:, :, None, None].to(x.dtype)
        x = x + self.gamma1 * self.attn.forward_grid(self.norm1(x), mask)
        x = x + self.gamma3 * self.local_mp(self.norm3(x), mask)
        x = x + self.gamma2 * self.mlp(self.norm2(x))
        if cells is not None:
            x = x * cells
        return x

    def forward_packed(
        self, x: torch.Tensor, layout: TokenLayout, rows: torch.Tensor | None = None
    ) -> torch.Tensor:
        """:meth:`forward` on the valid tokens ``x`` ``[N, C]`` of ``layout``.

        Gives the valid cells of ``forward(layout.unpack(x), mask)`` at the cost
        of the ``N`` valid tokens (see :class:`TokenLayout`).

        Args:
            x: ``[N, C]`` valid tokens.
            layout: Where they sit on the grid.
            rows: ``[...]`` packed rows whose output is wanted (``None``: all). The
                attention and the local interaction still see every token (they mix
                tokens and their batch statistics span the batch); the MLP, the
                largest part, runs on these rows only.

        Returns:
            ``[N, C]``, or ``[..., C]`` for ``rows``.
        """
        x = x + self.attn.forward_packed(self.norm1(x), layout, self.gamma1)
        x = x + self.local_mp.forward_packed(self.norm3(x), layout, self.gamma3)
        if rows is not None:
            x = x[rows]
        hidden = self.mlp[1](self.mlp[0](self.norm2(x)))
        return x + _scaled_linear(hidden, self.mlp[2], self.gamma2)
