"""Temporal transformer over per-frame features (PC-MRL Sec. 3.2, Fig. 3 I).

A standard pre-norm transformer encoder over the frames of a sequence: 6
blocks with 4 heads in the paper's configuration, RMSNorm as in the authors'
implementation (METHODS.md), sinusoidal frame positions. The output heads are
"two linear layers with ReLU" (Sec. 4.2) to the root position and the raw
(not yet normalised) global quaternions of the target skeleton.

``layout="authors"`` computes what the authors' code does (the layout their
checkpoints hold, :mod:`skelagnostic_pcmrl.authors`): no input projection, 16
sinusoidal channels concatenated to the frame features (not added),
post-norm blocks (RMSNorm after each residual sum), no final norm and a single
linear output layer.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.layouts import AUTHORS_RMS_EPS, LAYOUTS

__all__ = ["TemporalTransformer", "sinusoidal_positions"]

#: Sinusoidal channels concatenated to the frame features by ``layout="authors"``.
AUTHORS_POSITION_DIM = 16


def sinusoidal_positions(frames: int, dim: int, device: torch.device | None = None) -> torch.Tensor:
    """``[frames, dim]`` sinusoidal position encodings (Vaswani et al.)."""
    pos = torch.arange(frames, dtype=torch.float32, device=device).unsqueeze(1)
    freq = torch.exp(
        torch.arange(0, dim, 2, dtype=torch.float32, device=device) * (-math.log(10000.0) / dim)
    )
    out = torch.zeros(frames, dim, device=device)
    out[:, 0::2] = torch.sin(pos * freq)
    out[:, 1::2] = torch.cos(pos * freq[: dim // 2])
    return out


class _Block(nn.Module):
    """Transformer block: pre-norm, or post-norm (``post_norm``, the authors')."""

    def __init__(self, dim: int, heads: int, dropout: float, post_norm: bool = False) -> None:
        super().__init__()
        eps = AUTHORS_RMS_EPS if post_norm else None
        self.post_norm = post_norm
        self.norm1 = nn.RMSNorm(dim, eps=eps)
        self.attn = nn.MultiheadAttention(dim, heads, dropout=dropout, batch_first=True)
        self.norm2 = nn.RMSNorm(dim, eps=eps)
        self.ff = nn.Sequential(
            nn.Linear(dim, 4 * dim), nn.GELU(), nn.Dropout(dropout), nn.Linear(4 * dim, dim)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.post_norm:
            x = self.norm1(x + self.attn(x, x, x, need_weights=False)[0])
            return self.norm2(x + self.ff(x))
        h = self.norm1(x)
        x = x + self.attn(h, h, h, need_weights=False)[0]
        return x + self.ff(self.norm2(x))


class TemporalTransformer(nn.Module):
    """``[B, T, in_dim]`` frame features -> ``[B, T, out_dim]`` per-frame outputs.

    Args:
        in_dim: Width of the frame features.
        dim: Transformer width.
        layers: Transformer blocks (6 in the paper).
        heads: Attention heads (4 in the paper).
        out_dim: Output width (3 + 4 x predicted joints).
        dropout: Dropout in attention and feed-forward layers.
        layout: ``"skelagnostic"`` or ``"authors"`` (see the module docstring; there
            ``dim`` must be ``in_dim + 16``).

    Raises:
        SkelagnosticError: The width does not suit the heads or the layout, or the
            layout is unknown.
    """

    def __init__(
        self,
        in_dim: int,
        dim: int,
        layers: int,
        heads: int,
        out_dim: int,
        dropout: float = 0.0,
        layout: str = "skelagnostic",
    ) -> None:
        super().__init__()
        if layout not in LAYOUTS:
            raise SkelagnosticError(
                f"temporal transformer: layout={layout!r} is not one of {', '.join(LAYOUTS)}"
            )
        if dim % heads or dim % 2:
            raise SkelagnosticError(
                f"temporal transformer: width {dim} must be even and divisible by {heads} heads"
            )
        self.dim = dim
        self.layout = layout
        if layout == "authors":
            if dim != in_dim + AUTHORS_POSITION_DIM:
                raise SkelagnosticError(
                    f"temporal transformer: layout='authors' needs width "
                    f"in_dim + {AUTHORS_POSITION_DIM} = "
                    f"{in_dim + AUTHORS_POSITION_DIM}, got {dim}"
                )
            self.blocks = nn.ModuleList(
                _Block(dim, heads, dropout, post_norm=True) for _ in range(layers)
            )
            self.out = nn.Linear(dim, out_dim)
            return
        self.proj = nn.Linear(in_dim, dim)
        self.blocks = nn.ModuleList(_Block(dim, heads, dropout) for _ in range(layers))
        self.norm = nn.RMSNorm(dim)
        self.out = nn.Sequential(nn.Linear(dim, dim), nn.ReLU(), nn.Linear(dim, out_dim))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Apply the blocks and the output layers."""
        if self.layout == "authors":
            pos = sinusoidal_positions(features.shape[-2], AUTHORS_POSITION_DIM, features.device)
            x = torch.cat(
                [features, pos.to(features.dtype).expand(*features.shape[:-1], -1)], dim=-1
            )
            for block in self.blocks:
                x = block(x)
            return self.out(x)
        x = self.proj(features) + sinusoidal_positions(
            features.shape[-2], self.dim, features.device
        )
        for block in self.blocks:
            x = block(x)
        return self.out(self.norm(x))
