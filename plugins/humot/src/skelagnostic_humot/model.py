"""The HuMoT network (Mourot et al., Sec. 3.3 and App. A.3) and its two training losses.

Shapes: motions are ``[B, F, J, 3]`` joint positions (frames first, like
:class:`skelagnostic.Motion`), templates ``[B, J, 3]``, latent codes
``[B, F, Z]``. Batches may mix joint counts: pass a ``mask`` ``[B, J]`` whose
valid joints come first (padding last); padded joints do not influence the
valid ones (see :mod:`skelagnostic_humot.xcit`).

With ``fast_path=True`` (the aligner's default) the XCiT blocks, and the decoder's
output layers, compute on the valid tokens only (packed, see
:class:`~skelagnostic_humot.xcit.TokenLayout`); ``fast_path=False`` keeps the
padded computation. Both give the same values and gradients (to float
rounding); the fast path does not spend time on the padding of mixed joint
counts, which stochastic joint subsampling makes about a fifth of the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import torch
from torch import nn

from skelagnostic_humot.xcit import TokenLayout, XCiTBlock

__all__ = [
    "HuMoT",
    "HuMoTConfig",
    "HuMoTDecoder",
    "HuMoTEncoder",
    "bone_length_consistency_loss",
    "reconstruction_loss",
    "temporal_positional_encoding",
]


def temporal_positional_encoding(
    frames: int, dim: int, device: torch.device | None = None, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """Sinusoidal encoding of the frame index (Vaswani et al. 2017), ``[frames, dim]``.

    Channel ``2i`` is ``sin(t / 10000^(2i/dim))``, channel ``2i+1`` the cosine.
    """
    t = torch.arange(frames, device=device, dtype=torch.float64)[:, None]
    freq = torch.exp(
        -math.log(10000.0) * torch.arange(0, dim, 2, device=device, dtype=torch.float64) / dim
    )
    pe = torch.zeros(frames, dim, device=device, dtype=torch.float64)
    pe[:, 0::2] = torch.sin(t * freq)
    pe[:, 1::2] = torch.cos(t * freq)[:, : dim // 2]
    return pe.to(dtype)


def _mlp(sizes: list[int], act: type[nn.Module], last_act: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if last_act or i < len(sizes) - 2:
            layers.append(act())
    return nn.Sequential(*layers)


def _conv_stack(sizes: list[int], kernel: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in pairwise(sizes):
        layers += [nn.Conv1d(a, b, kernel, padding=kernel // 2), nn.ELU()]
    return nn.Sequential(*layers)


def _check_mask(mask: torch.Tensor | None, batch: int, joints: int) -> torch.Tensor | None:
    if mask is None:
        return None
    if mask.shape != (batch, joints):
        raise ValueError(f"mask must have shape [{batch}, {joints}], got {list(mask.shape)}")
    mask = mask.bool()
    if bool((mask[:, 1:] & ~mask[:, :-1]).any()):
        raise ValueError("mask: valid joints must come first in every sample (padding last)")
    if bool((~mask[:, 0]).any()):
        raise ValueError("mask: every sample needs at least one joint")
    return mask


@dataclass(frozen=True)
class HuMoTConfig:
    """The sizes of a HuMoT network, all required.

    Their defaults are those of :class:`~skelagnostic_humot.aligner.HumotAligner`'s
    constructor, which are ``conf/humot.yaml``'s (the paper's, App. A.3): one place,
    checked by ``tests/framework/test_model_defaults.py``.

    Attributes:
        dim: Token channels.
        latent: Latent channels ``Z``.
        blocks: XCiT blocks in the encoder and in the decoder.
        heads: Attention heads.
        kernel_size: Temporal kernel of the Conv1d layers (not given by the paper).
        mlp_ratio: XCiT MLP width ratio.
        layer_scale: Initial XCiT layer scale.
        fast_path: Compute on the valid (unpadded) tokens only; ``False`` keeps the padded
            computation (same values, slower on batches of mixed joint counts).
        xca: The tokens each XCA map spans, ``"frame"`` or ``"sequence"``
            (:data:`~skelagnostic_humot.xcit.XCA_SCOPES`).
    """

    dim: int
    latent: int
    blocks: int
    heads: int
    kernel_size: int
    mlp_ratio: float
    layer_scale: float
    fast_path: bool
    xca: str


def _xcit_blocks(config: HuMoTConfig) -> list[XCiTBlock]:
    """The ``config.blocks`` XCiT blocks of an encoder or a decoder."""
    return [
        XCiTBlock(
            config.dim, config.heads, config.mlp_ratio, config.layer_scale, xca_scope=config.xca
        )
        for _ in range(config.blocks)
    ]


class HuMoTEncoder(nn.Module):
    """``E(X | T)``: motion + its skeleton template -> latent code ``[B, F, Z]``.

    Template: joint-wise MLP (16, 32, 64; ELU). Motion: joint-wise temporal CNN
    (4 Conv1d with 3, 16, 32, 64 outputs) then 3 linear layers (64), ELU after
    each. Per joint, the template features (replicated over time) and motion
    features are concatenated, projected to ``dim`` and the temporal
    positional encoding is added. A learned latent token, replicated over
    time, is appended after the joints; after the XCiT blocks only its slice
    is kept and projected to ``latent`` channels.

    Args:
        config: The network's sizes (:class:`HuMoTConfig`); ``fast_path`` computes the
            blocks on the valid tokens only (same values).
    """

    def __init__(self, config: HuMoTConfig) -> None:
        super().__init__()
        dim = config.dim
        self.dim = dim
        self.fast_path = config.fast_path
        self.template_mlp = _mlp([3, 16, 32, 64], nn.ELU, last_act=True)
        self.motion_cnn = _conv_stack([3, 3, 16, 32, 64], config.kernel_size)
        self.motion_mlp = _mlp([64, 64, 64, 64], nn.ELU, last_act=True)
        self.merge = nn.Linear(128, dim)
        self.latent_token = nn.Parameter(torch.randn(dim) * 0.02)
        self.blocks = nn.ModuleList(_xcit_blocks(config))
        self.to_latent = nn.Linear(dim, config.latent)

    def forward(
        self, motion: torch.Tensor, template: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Encode.

        Args:
            motion: ``[B, F, J, 3]`` joint positions.
            template: ``[B, J, 3]`` skeleton templates.
            mask: ``[B, J]`` valid joints, first in each sample (``None``: all).

        Returns:
            ``[B, F, Z]`` latent codes.
        """
        b, f, j, _ = motion.shape
        mask = _check_mask(mask, b, j)
        x = motion.permute(0, 2, 3, 1).reshape(b * j, 3, f)
        x = self.motion_cnn(x).transpose(1, 2)  # [B*J, F, 64]
        x = self.motion_mlp(x).reshape(b, j, f, 64)
        t = self.template_mlp(template)[:, :, None].expand(b, j, f, 64)
        tokens = self.merge(torch.cat([t, x], dim=-1))
        tokens = tokens + temporal_positional_encoding(f, self.dim, tokens.device, tokens.dtype)
        # append the latent token right after the last valid joint of each sample
        count = torch.full((b,), j, device=motion.device) if mask is None else mask.sum(1)
        slot = torch.arange(j + 1, device=motion.device)[None] == count[:, None]  # [B, J+1]
        tokens = torch.cat([tokens, tokens.new_zeros(b, 1, f, self.dim)], dim=1)
        tokens = torch.where(
            slot[:, :, None, None], self.latent_token.expand(b, j + 1, f, -1), tokens
        )
        full = None
        if mask is not None:
            full = torch.cat([mask, mask.new_zeros(b, 1)], dim=1) | slot
            tokens = tokens * full[:, :, None, None].to(tokens.dtype)
        if not self.fast_path:
            for block in self.blocks:
                tokens = block(tokens, full)
            return self.to_latent(tokens[torch.arange(b, device=motion.device), count])
        layout = TokenLayout.of(full, f, b, j + 1)
        x = layout.pack(tokens)
        # packed rows of the latent token: cells (b, count_b, 0..F-1); only those leave the
        # last block, so its MLP runs on them alone
        cell = (
            torch.arange(b, device=motion.device)[:, None] * (j + 1) + count[:, None]
        ) * f + torch.arange(f, device=motion.device)
        rows = cell if layout.index is None else torch.searchsorted(layout.index, cell)
        last = len(self.blocks) - 1
        for i, block in enumerate(self.blocks):
            x = block.forward_packed(x, layout, rows if i == last else None)
        return self.to_latent(x if self.blocks else x[rows])


class HuMoTDecoder(nn.Module):
    """``D(z | T)``: latent code + target template -> motion ``[B, F, J, 3]``.

    Template: joint-wise MLP (16, 32, 64, 128; ReLU between), replicated over
    time, plus the temporal positional encoding: the input tokens. Latent: a
    CNN (3 Conv1d + 1 linear, ``dim`` outputs, ELU) shared by the style
    modules; each of the XCiT blocks has its own 2-layer MLP (``dim``, ReLU
    between) turning those features into a per-frame style code that
    multiplies the block's input tokens. Output: joint-wise CNN (3 Conv1d,
    ``dim``) and 3 linear layers (``dim``, ``dim``, 3), ELU after each but the last.

    Args:
        config: The network's sizes (:class:`HuMoTConfig`; ``blocks`` style-modulated
            XCiT blocks); ``fast_path`` computes the blocks and output layers on the
            valid joints only (same values).
    """

    def __init__(self, config: HuMoTConfig) -> None:
        super().__init__()
        dim, kernel_size = config.dim, config.kernel_size
        self.dim = dim
        self.fast_path = config.fast_path
        self.template_mlp = _mlp([3, 16, 32, 64, dim], nn.ReLU, last_act=False)
        self.latent_cnn = _conv_stack([config.latent, dim, dim, dim], kernel_size)
        self.latent_linear = nn.Sequential(nn.Linear(dim, dim), nn.ELU())
        self.styles = nn.ModuleList(
            nn.Sequential(nn.Linear(dim, dim), nn.ReLU(), nn.Linear(dim, dim))
            for _ in range(config.blocks)
        )
        self.blocks = nn.ModuleList(_xcit_blocks(config))
        self.output_cnn = _conv_stack([dim, dim, dim, dim], kernel_size)
        self.output_mlp = _mlp([dim, dim, dim, 3], nn.ELU, last_act=False)

    def forward(
        self, z: torch.Tensor, template: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Decode.

        Args:
            z: ``[B, F, Z]`` latent codes.
            template: ``[B, J, 3]`` target skeleton templates.
            mask: ``[B, J]`` valid joints, first in each sample (``None``: all).

        Returns:
            ``[B, F, J, 3]`` joint positions (zero on padded joints).
        """
        b, f, _ = z.shape
        j = template.shape[1]
        mask = _check_mask(mask, b, j)
        tokens = self.template_mlp(template)[:, :, None].expand(b, j, f, self.dim)
        tokens = tokens + temporal_positional_encoding(f, self.dim, z.device, z.dtype)
        h = self.latent_linear(self.latent_cnn(z.transpose(1, 2)).transpose(1, 2))  # [B, F, D]
        if self.fast_path:
            return self._decode_packed(tokens, h, mask)
        if mask is not None:
            tokens = tokens * mask[:, :, None, None].to(tokens.dtype)
        for style, block in zip(self.styles, self.blocks, strict=True):
            tokens = block(tokens * style(h)[:, None], mask)
        x = self.output_cnn(tokens.reshape(b * j, f, self.dim).transpose(1, 2)).transpose(1, 2)
        out = self.output_mlp(x).reshape(b, j, f, 3).permute(0, 2, 1, 3)
        if mask is not None:
            out = out * mask[:, None, :, None].to(out.dtype)
        return out

    def _decode_packed(
        self, tokens: torch.Tensor, h: torch.Tensor, mask: torch.Tensor | None
    ) -> torch.Tensor:
        """The blocks and output layers of :meth:`forward` on the valid joints only.

        Args:
            tokens: ``[B, J, F, D]`` input tokens (template features + frame encoding).
            h: ``[B, F, D]`` latent features for the style modules.
            mask: ``[B, J]`` valid joints (``None``: all).

        Returns:
            ``[B, F, J, 3]`` (zero on padded joints).
        """
        b, j, f, d = tokens.shape
        layout = TokenLayout.of(mask, f, b, j)
        x = layout.pack(tokens)
        frame_rows = layout.frame_rows()
        for style, block in zip(self.styles, self.blocks, strict=True):
            s = style(h).reshape(b * f, d)  # per (sample, frame)
            if frame_rows is None:
                x = block.forward_packed(
                    (x.reshape(b, j, f, d) * s.reshape(b, 1, f, d)).reshape(-1, d), layout
                )
            else:
                x = block.forward_packed(x * s.index_select(0, frame_rows), layout)
        # every valid joint keeps its F frames: one output sequence per valid joint
        seq = x.reshape(-1, f, d).transpose(1, 2)
        out = self.output_mlp(self.output_cnn(seq).transpose(1, 2)).reshape(-1, 3)
        return layout.unpack(out).permute(0, 2, 1, 3)


class HuMoT(nn.Module):
    """The autoencoder: ``D(E(X | T_src) | T_dst)``.

    Args:
        config: The sizes of the encoder and of the decoder (:class:`HuMoTConfig`).

    Attributes:
        config: The sizes it was built with.

    Example:
        >>> import torch
        >>> from skelagnostic_humot.aligner import HumotAligner
        >>> net = HumotAligner().net  # the paper's sizes, conf/humot.yaml
        >>> z = net.encoder(torch.randn(2, 30, 22, 3), torch.randn(2, 22, 3))
        >>> tuple(z.shape), tuple(net.decoder(z, torch.randn(2, 31, 3)).shape)
        ((2, 30, 128), (2, 30, 31, 3))
    """

    def __init__(self, config: HuMoTConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = HuMoTEncoder(config)
        self.decoder = HuMoTDecoder(config)

    def forward(
        self,
        motion: torch.Tensor,
        source_template: torch.Tensor,
        target_template: torch.Tensor,
        source_mask: torch.Tensor | None = None,
        target_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Encode with the source template, decode with the target one: ``[B, F, J', 3]``."""
        z = self.encoder(motion, source_template, source_mask)
        return self.decoder(z, target_template, target_mask)


def reconstruction_loss(
    preds: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None
) -> torch.Tensor:
    """HuMoT Eq. 1: squared position error averaged over frames and (valid) joints.

    Args:
        preds: ``[B, F, J, 3]`` decoded positions.
        target: ``[B, F, J, 3]`` ground truth.
        mask: ``[B, J]`` valid joints (``None``: all).

    Returns:
        The mean over samples of each sample's Eq. 1 value.
    """
    err = ((preds - target) ** 2).sum(-1)  # [B, F, J]
    if mask is None:
        return err.mean()
    m = mask[:, None, :].to(err.dtype)
    per_sample = (err * m).sum(dim=(1, 2)) / (m.sum(dim=(1, 2)) * err.shape[1])
    return per_sample.mean()


def bone_length_consistency_loss(
    preds: torch.Tensor,
    target: torch.Tensor,
    bones: torch.Tensor,
    bone_mask: torch.Tensor | None = None,
    min_length: float = 1e-4,
) -> torch.Tensor:
    """HuMoT Eq. 2: per bone, temporal variance of predicted / true length; mean over bones.

    The same formula as :func:`skelagnostic.metrics.functional.bone_length_consistency`
    (population variance), with per-sample bone lists for batches of mixed topologies.

    Args:
        preds: ``[B, F, J, 3]`` decoded positions.
        target: ``[B, F, J, 3]`` ground truth.
        bones: ``[B, K, 2]`` (parent, child) joint indices per sample.
        bone_mask: ``[B, K]`` valid bones (``None``: all).
        min_length: Bones whose ground-truth length falls below this at any frame are
            left out (zero-length helper bones, e.g. CMU's ``LHipJoint``, have no ratio).

    Returns:
        The mean over samples of each sample's Eq. 2 value.
    """
    b = preds.shape[0]
    idx = torch.arange(b, device=preds.device)[:, None]

    def lengths(x: torch.Tensor) -> torch.Tensor:  # [B, F, K]
        xb = x.transpose(0, 1)  # [F, B, J, 3]
        return (xb[:, idx, bones[..., 1]] - xb[:, idx, bones[..., 0]]).norm(dim=-1).permute(1, 0, 2)

    true = lengths(target)
    valid = true.amin(dim=1) >= min_length  # [B, K]
    if bone_mask is not None:
        valid = valid & bone_mask.bool()
    ratio = lengths(preds) / true.clamp_min(min_length)
    var = ratio.var(dim=1, correction=0)  # [B, K]
    m = valid.to(var.dtype)
    return ((var * m).sum(1) / m.sum(1).clamp_min(1)).mean()
