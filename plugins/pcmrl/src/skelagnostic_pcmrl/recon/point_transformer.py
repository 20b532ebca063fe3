"""Per-frame point-cloud encoder (PC-MRL Sec. 3.2 and 4.2, Point Transformer [52]).

Layout, following the paper and the authors' encoder (METHODS.md "PC-MRL"):

1. every point's input is its position and one-hot body group, lifted to
   ``dim`` channels (64 in the paper) by a point-wise MLP;
2. self-attention over the points of the frame, one of (``attention``):
   ``"full"``, multi-head attention over all points with a learned encoding of
   the positions added to the queries and keys (the authors' encoder);
   ``"vector"``, the Point Transformer layer of Zhao et al. [52]: vector
   attention over each point's ``attention_k`` nearest points,
   ``sum_j softmax_j(gamma(phi(x_i) - psi(x_j) + delta)) * (alpha(x_j) + delta)``
   with ``delta = theta(p_i - p_j)``; or ``"none"`` (a PointNet++-style
   hierarchy, for ablations);
3. ``stages`` pooling stages (4 in the paper): farthest point sampling down
   to a quarter of the points, each kept point grouped with its ``k <= 8``
   nearest points (features and relative positions), a point-wise MLP that
   doubles the channels, max-pooling over the group, then self-attention at
   the new width; 256 points end as one point of ``dim * 2**stages``
   channels (64 -> 1024);
4. a residual MLP gives the frame feature.

``layout="authors"`` builds the encoder of the authors' code instead (the layout
their checkpoints hold, :mod:`skelagnostic_pcmrl.authors`): a single linear
input layer; per stage, RMSNorm, single-head dot-product attention over all the
points (no residual), RMSNorm and a LeakyReLU feed-forward block added to the
normalised input, then the pooling (FPS to ``N // 4`` points from point 0, the
``k`` nearest points' features next to the kept point's absolute position,
bias-free linear layers with a LeakyReLU, max-pool); the first remaining point
through a residual LeakyReLU MLP.
"""

from __future__ import annotations

import torch
from torch import nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.layouts import AUTHORS_RMS_EPS, LAYOUTS
from skelagnostic_pcmrl.recon.fps import farthest_point_sampling, gather_points, knn_indices

__all__ = [
    "ATTENTIONS",
    "AuthorsPointStage",
    "PointAttention",
    "PointTransformerEncoder",
    "TransitionDown",
    "VectorAttention",
]

#: Values of the encoder's ``attention`` option.
ATTENTIONS = ("full", "vector", "none")


class _Scale(nn.Module):
    """Learned per-channel residual scale (LayerScale, Touvron et al. 2021); ``None``: identity."""

    def __init__(self, channels: int, init: float | None) -> None:
        super().__init__()
        self.gamma = None if init is None else nn.Parameter(torch.full((channels,), float(init)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x if self.gamma is None else x * self.gamma


class _NoAttention(nn.Module):
    """``attention="none"``: the features pass unchanged."""

    def forward(self, features: torch.Tensor, xyz: torch.Tensor) -> torch.Tensor:
        return features


class _AttentionBlock(nn.Module):
    """The parts both point attentions share: residual scales and the feed-forward block."""

    def __init__(self, channels: int, layer_scale: float | None) -> None:
        super().__init__()
        self.norm2 = nn.LayerNorm(channels)
        self.ff = nn.Sequential(
            nn.Linear(channels, 2 * channels), nn.ReLU(), nn.Linear(2 * channels, channels)
        )
        self.scale1 = _Scale(channels, layer_scale)
        self.scale2 = _Scale(channels, layer_scale)

    def feed_forward(self, features: torch.Tensor) -> torch.Tensor:
        """``features`` plus the pre-norm feed-forward block."""
        return features + self.scale2(self.ff(self.norm2(features)))


class PointAttention(_AttentionBlock):
    """Pre-norm multi-head self-attention over the points of a frame, plus a feed-forward block.

    Args:
        channels: Feature width.
        heads: Attention heads.
        layer_scale: Initial residual scale of both blocks (``None``: no scale).
    """

    def __init__(self, channels: int, heads: int, layer_scale: float | None = None) -> None:
        super().__init__(channels, layer_scale)
        if channels % heads:
            raise SkelagnosticError(
                f"point attention: {channels} channels are not divisible by {heads} heads"
            )
        self.position = nn.Sequential(
            nn.Linear(3, channels), nn.ReLU(), nn.Linear(channels, channels)
        )
        self.norm1 = nn.LayerNorm(channels)
        self.attn = nn.MultiheadAttention(channels, heads, batch_first=True)

    def forward(self, features: torch.Tensor, xyz: torch.Tensor) -> torch.Tensor:
        """``[B, N, C]`` features updated from all points (positions ``[B, N, 3]``)."""
        h = self.norm1(features)
        qk = h + self.position(xyz)
        features = features + self.scale1(self.attn(qk, qk, h, need_weights=False)[0])
        return self.feed_forward(features)


class VectorAttention(_AttentionBlock):
    """Point Transformer layer (Zhao et al. 2021, Eq. 3-4) in a pre-norm residual block.

    Every point attends to its ``k`` nearest points (itself included) with
    channel-wise (vector) attention weights
    ``softmax_j(gamma(phi(x_i) - psi(x_j) + delta_ij))`` on the values
    ``alpha(x_j) + delta_ij``, where ``delta_ij = theta(p_i - p_j)`` is a learned
    encoding of the relative position (two linear layers with a ReLU, as are
    ``gamma`` and ``theta``). A feed-forward block follows.

    Args:
        channels: Feature width.
        k: Neighbours per point (16 in [52]; at most the number of points is used).
        layer_scale: Initial residual scale of both blocks (``None``: no scale).
    """

    def __init__(self, channels: int, k: int = 16, layer_scale: float | None = None) -> None:
        super().__init__(channels, layer_scale)
        if k < 1:
            raise SkelagnosticError(f"vector attention: k={k} must be positive")
        self.k = int(k)
        self.norm1 = nn.LayerNorm(channels)
        self.qkv = nn.Linear(channels, 3 * channels)
        self.theta = nn.Sequential(nn.Linear(3, channels), nn.ReLU(), nn.Linear(channels, channels))
        self.gamma = nn.Sequential(
            nn.Linear(channels, channels), nn.ReLU(), nn.Linear(channels, channels)
        )
        self.proj = nn.Linear(channels, channels)

    def forward(self, features: torch.Tensor, xyz: torch.Tensor) -> torch.Tensor:
        """``[B, N, C]`` features updated from each point's neighbours (positions ``[B, N, 3]``)."""
        q, k, v = self.qkv(self.norm1(features)).chunk(3, dim=-1)
        nbr = knn_indices(xyz, xyz, min(self.k, xyz.shape[-2]))  # [B, N, k]
        delta = self.theta(xyz.unsqueeze(-2) - gather_points(xyz, nbr))  # [B, N, k, C]
        weights = self.gamma(q.unsqueeze(-2) - gather_points(k, nbr) + delta).softmax(dim=-2)
        out = (weights * (gather_points(v, nbr) + delta)).sum(dim=-2)
        features = features + self.scale1(self.proj(out))
        return self.feed_forward(features)


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
            nn.Linear(in_channels + 3, out_channels),
            nn.LayerNorm(out_channels),
            nn.ReLU(),
            nn.Linear(out_channels, out_channels),
            nn.ReLU(),
        )

    def forward(
        self, features: torch.Tensor, xyz: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``([B, M, C_out], [B, M, 3])`` with ``M = ceil(N / ratio)``."""
        num = xyz.shape[-2]
        keep = max(1, -(-num // self.ratio))
        centres = gather_points(xyz, farthest_point_sampling(xyz, keep))
        groups = knn_indices(centres, xyz, min(self.k, num))  # [B, M, k]
        rel = gather_points(xyz, groups) - centres.unsqueeze(-2)
        grouped = torch.cat([gather_points(features, groups), rel], dim=-1)
        return self.mlp(grouped).amax(dim=-2), centres


class AuthorsPointStage(nn.Module):
    """One stage of the authors' encoder: point attention, feed-forward block, pooling.

    ``h = n1(x)``, ``a = o(softmax(q(h) k(h)^T / sqrt(C)) v(h))``,
    ``h = h + ff(n2(a))``; then FPS keeps ``N // ratio`` points (the first is
    point 0), each is grouped with its ``min(k, N)`` nearest points, and
    ``pool_out(max_k LeakyReLU(pool_in([p_centre, h_neighbour])))`` gives
    ``2 C`` channels.

    Args:
        channels: Input width ``C``.
        ratio: Down-sampling factor (4).
        k: Neighbours per group (8).
    """

    def __init__(self, channels: int, ratio: int = 4, k: int = 8) -> None:
        super().__init__()
        self.ratio, self.k = int(ratio), int(k)
        self.norm1 = nn.RMSNorm(channels, eps=AUTHORS_RMS_EPS)
        self.q = nn.Linear(channels, channels)
        self.k_proj = nn.Linear(channels, channels)
        self.v = nn.Linear(channels, channels)
        self.o = nn.Linear(channels, channels)
        self.norm2 = nn.RMSNorm(channels, eps=AUTHORS_RMS_EPS)
        self.ff = nn.Sequential(
            nn.Linear(channels, 4 * channels), nn.LeakyReLU(), nn.Linear(4 * channels, channels)
        )
        self.pool_in = nn.Linear(3 + channels, 2 * channels, bias=False)
        self.pool_out = nn.Linear(2 * channels, 2 * channels, bias=False)

    def forward(
        self, features: torch.Tensor, xyz: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``([B, N // ratio, 2 C], [B, N // ratio, 3])`` from ``[B, N, C]``, ``[B, N, 3]``."""
        num, channels = xyz.shape[-2], features.shape[-1]
        keep = num // self.ratio
        if keep < 1:
            raise SkelagnosticError(
                f"authors' point encoder: {num} points cannot be pooled by {self.ratio}"
            )
        h = self.norm1(features)
        weights = (self.q(h) @ self.k_proj(h).transpose(-1, -2) / channels**0.5).softmax(-1)
        h = h + self.ff(self.norm2(self.o(weights @ self.v(h))))
        centres = gather_points(xyz, farthest_point_sampling(xyz, keep))
        groups = knn_indices(centres, xyz, min(self.k, num))  # [B, M, k]
        grouped = torch.cat(
            [centres.unsqueeze(-2).expand(*groups.shape, 3), gather_points(h, groups)], dim=-1
        )
        pooled = nn.functional.leaky_relu(self.pool_in(grouped)).amax(dim=-2)
        return self.pool_out(pooled), centres


class PointTransformerEncoder(nn.Module):
    """Point cloud ``[B, N, 3 + groups]`` -> frame feature ``[B, dim * 2**stages]``.

    Args:
        in_channels: Extra per-point channels besides xyz (5 one-hot body groups).
        dim: Width after the input MLP (64 in the paper); doubled at every stage.
        stages: Pooling stages (4 in the paper: 256 -> 64 -> 16 -> 4 -> 1 points).
        heads: Attention heads of the point self-attention.
        k: Neighbours of the kNN grouping (8).
        ratio: Down-sampling factor per stage (4).
        attention: ``"full"`` (the authors'), ``"vector"`` ([52]) or ``"none"``
            (:data:`ATTENTIONS`).
        attention_k: Neighbours of the ``"vector"`` attention (16, as in [52]).
        layer_scale: Initial residual scale of the attention blocks (``None``: no scale).
        layout: ``"skelagnostic"`` (the blocks above) or ``"authors"`` (the authors'
            encoder, see the module docstring; ``heads``, ``attention``,
            ``attention_k`` and ``layer_scale`` do not apply to it).

    Raises:
        SkelagnosticError: A size is not positive, or ``attention`` or ``layout``
            is unknown.
    """

    def __init__(
        self,
        in_channels: int = 5,
        dim: int = 64,
        stages: int = 4,
        heads: int = 4,
        k: int = 8,
        ratio: int = 4,
        attention: str = "full",
        attention_k: int = 16,
        layer_scale: float | None = None,
        layout: str = "skelagnostic",
    ) -> None:
        super().__init__()
        if layout not in LAYOUTS:
            raise SkelagnosticError(
                f"point encoder: layout={layout!r} is not one of {', '.join(LAYOUTS)}"
            )
        self.layout = layout
        if dim < 1 or stages < 0:
            raise SkelagnosticError(
                f"point encoder: dim={dim} and stages={stages} must be positive / non-negative"
            )
        if attention not in ATTENTIONS:
            raise SkelagnosticError(
                f"point encoder: attention={attention!r} is not one of {', '.join(ATTENTIONS)}"
            )
        widths = [dim * 2**i for i in range(stages + 1)]
        self.out_channels = widths[-1]
        if layout == "authors":
            self.embed = nn.Linear(3 + in_channels, dim)
            self.stages = nn.ModuleList(
                AuthorsPointStage(widths[i], ratio, k) for i in range(stages)
            )
            self.head_in = nn.Linear(widths[-1], widths[-1])
            self.head_out = nn.Linear(widths[-1], widths[-1])
            return
        self.embed = nn.Sequential(nn.Linear(3 + in_channels, dim), nn.ReLU(), nn.Linear(dim, dim))

        def block(channels: int) -> nn.Module:
            if attention == "full":
                return PointAttention(channels, heads, layer_scale)
            if attention == "vector":
                return VectorAttention(channels, attention_k, layer_scale)
            return _NoAttention()

        self.attn0 = block(dim)
        self.down = nn.ModuleList(
            TransitionDown(widths[i], widths[i + 1], ratio, k) for i in range(stages)
        )
        self.attn = nn.ModuleList(block(widths[i + 1]) for i in range(stages))
        self.head = nn.Sequential(
            nn.LayerNorm(widths[-1]),
            nn.Linear(widths[-1], widths[-1]),
            nn.ReLU(),
            nn.Linear(widths[-1], widths[-1]),
        )

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Encode ``[..., N, 3 + in_channels]`` clouds into ``[..., out_channels]``."""
        lead = points.shape[:-2]
        x = points.reshape(-1, *points.shape[-2:])
        xyz = x[..., :3].contiguous()
        if self.layout == "authors":
            h = self.embed(x)
            for stage in self.stages:
                h, xyz = stage(h, xyz)
            h = self.head_in(h[:, 0])  # the first remaining point, as the authors take it
            h = h + self.head_out(nn.functional.leaky_relu(h))
            return h.reshape(*lead, -1)
        h = self.attn0(self.embed(x), xyz)
        for down, attn in zip(self.down, self.attn, strict=True):
            h, xyz = down(h, xyz)
            h = attn(h, xyz)
        h = h.amax(dim=-2)
        h = h + self.head(h)
        return h.reshape(*lead, -1)
