"""Per-frame point-cloud encoder (PC-MRL Sec. 3.2 and 4.2, Point Transformer [52]).

Layout, following the paper and the authors' encoder (METHODS.md "PC-MRL"):

1. every point's input is its position and one-hot body group, lifted to
   ``dim`` channels (64 in the paper) by a point-wise MLP;
2. full self-attention over all the points of the frame (no kNN attention),
   with a learned encoding of the positions added to the queries and keys;
3. ``stages`` pooling stages (4 in the paper): farthest point sampling down
   to a quarter of the points, each kept point grouped with its ``k <= 8``
   nearest points (features and relative positions), a point-wise MLP that
   doubles the channels, max-pooling over the group, then self-attention at
   the new width; 256 points end as one point of ``dim * 2**stages``
   channels (64 -> 1024);
4. a residual MLP gives the frame feature.
"""

from __future__ import annotations

import torch
from torch import nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.fps import farthest_point_sampling, gather_points, knn_indices

__all__ = ["PointAttention", "PointTransformerEncoder", "TransitionDown"]


class PointAttention(nn.Module):
    """Pre-norm multi-head self-attention over the points of a frame, plus a feed-forward block.

    Args:
        channels: Feature width.
        heads: Attention heads.
    """

    def __init__(self, channels: int, heads: int) -> None:
        super().__init__()
        if channels % heads:
            raise SkelagnosticError(f"point attention: {channels} channels are not divisible "
                                    f"by {heads} heads")
        self.position = nn.Sequential(nn.Linear(3, channels), nn.ReLU(), nn.Linear(channels,
                                                                                  channels))
        self.norm1 = nn.LayerNorm(channels)
        self.attn = nn.MultiheadAttention(channels, heads, batch_first=True)
        self.norm2 = nn.LayerNorm(channels)
        self.ff = nn.Sequential(nn.Linear(channels, 2 * channels), nn.ReLU(),
                                nn.Linear(2 * channels, channels))

    def forward(self, features: torch.Tensor, xyz: torch.Tensor) -> torch.Tensor:
        """``[B, N, C]`` features updated from all points (positions ``[B, N, 3]``)."""
        h = self.norm1(features)
        qk = h + self.position(xyz)
        features = features + self.attn(qk, qk, h, need_weights=False)[0]
        return features + self.ff(self.norm2(features))


class TransitionDown(nn.Module):
    """Pooling stage: FPS to ``ceil(N / ratio)`` points, kNN grouping, MLP, max-pool.

    Args:
        in_channels: Input feature width.
        out_channels: Output feature width.
        ratio: Down-sampling factor (4 in the paper).
        k: Neighbours per group (at most the number of input points is used).
    """

    def __init__(self, in_channels: int, out_channels: int, ratio: int = 4, k: int = 8) -> None:
        super().__init__()
        self.ratio = int(ratio)
        self.k = int(k)
        self.mlp = nn.Sequential(
            nn.Linear(in_channels + 3, out_channels), nn.LayerNorm(out_channels), nn.ReLU(),
            nn.Linear(out_channels, out_channels), nn.ReLU(),
        )

    def forward(self, features: torch.Tensor, xyz: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """``([B, M, C_out], [B, M, 3])`` with ``M = ceil(N / ratio)``."""
        num = xyz.shape[-2]
        keep = max(1, -(-num // self.ratio))
        centres = gather_points(xyz, farthest_point_sampling(xyz, keep))
        groups = knn_indices(centres, xyz, min(self.k, num))  # [B, M, k]
        rel = gather_points(xyz, groups) - centres.unsqueeze(-2)
        grouped = torch.cat([gather_points(features, groups), rel], dim=-1)
        return self.mlp(grouped).amax(dim=-2), centres


class PointTransformerEncoder(nn.Module):
    """Point cloud ``[B, N, 3 + groups]`` -> frame feature ``[B, dim * 2**stages]``.

    Args:
        in_channels: Extra per-point channels besides xyz (5 one-hot body groups).
        dim: Width after the input MLP (64 in the paper); doubled at every stage.
        stages: Pooling stages (4 in the paper: 256 -> 64 -> 16 -> 4 -> 1 points).
        heads: Attention heads of the point self-attention.
        k: Neighbours of the kNN grouping (8).
        ratio: Down-sampling factor per stage (4).
    """

    def __init__(self, in_channels: int = 5, dim: int = 64, stages: int = 4, heads: int = 4,
                 k: int = 8, ratio: int = 4) -> None:
        super().__init__()
        if dim < 1 or stages < 0:
            raise SkelagnosticError(f"point encoder: dim={dim} and stages={stages} must be "
                                    "positive / non-negative")
        self.embed = nn.Sequential(nn.Linear(3 + in_channels, dim), nn.ReLU(), nn.Linear(dim, dim))
        self.attn0 = PointAttention(dim, heads)
        widths = [dim * 2**i for i in range(stages + 1)]
        self.down = nn.ModuleList(TransitionDown(widths[i], widths[i + 1], ratio, k)
                                  for i in range(stages))
        self.attn = nn.ModuleList(PointAttention(widths[i + 1], heads) for i in range(stages))
        self.out_channels = widths[-1]
        self.head = nn.Sequential(nn.LayerNorm(widths[-1]), nn.Linear(widths[-1], widths[-1]),
                                  nn.ReLU(), nn.Linear(widths[-1], widths[-1]))

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Encode ``[..., N, 3 + in_channels]`` clouds into ``[..., out_channels]``."""
        lead = points.shape[:-2]
        x = points.reshape(-1, *points.shape[-2:])
        xyz = x[..., :3].contiguous()
        h = self.attn0(self.embed(x), xyz)
        for down, attn in zip(self.down, self.attn, strict=True):
            h, xyz = down(h, xyz)
            h = attn(h, xyz)
        h = h.amax(dim=-2)
        h = h + self.head(h)
        return h.reshape(*lead, -1)
