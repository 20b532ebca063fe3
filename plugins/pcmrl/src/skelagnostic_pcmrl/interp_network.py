"""PC-MRL stage 2: the CITL-style interpolation transformer (Sec. 3.4).

Shaw-style relative attention, the transformer block and
:class:`CITLInterpolator` (keyframe encoder, intermediate tokens, decoder).
See :mod:`~skelagnostic_pcmrl.interp` for the model as a whole.

``layout="authors"`` computes what the authors' code does (the layout their
checkpoints hold, :mod:`skelagnostic_pcmrl.authors`): post-norm blocks whose
RMSNorms apply only to the keyframes in the encoder and only to the other
frames in the intermediate module (the rest pass un-normalised), keys and
values of the cross-attention taken from the encoder output as it is, and every
frame allowed to attend to itself besides the keyframes.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.point_transformer import AUTHORS_RMS_EPS, LAYOUTS


class RelativeAttention(nn.Module):
    """Multi-head attention with Shaw et al. relative position embeddings (zero initialised).

    Keys and values get a learned embedding of the clipped frame distance
    ``clip(j - i, -K, K)`` shared by all heads.
    """

    def __init__(self, dim: int, heads: int, max_relative: int) -> None:
        super().__init__()
        if dim % heads:
            raise SkelagnosticError(f"model.dim ({dim}) must be divisible by model.heads ({heads})")
        self.heads, self.head_dim, self.max_relative = heads, dim // heads, max_relative
        self.q = nn.Linear(dim, dim)
        self.kv = nn.Linear(dim, 2 * dim)
        self.out = nn.Linear(dim, dim)
        self.rel_k = nn.Parameter(torch.zeros(2 * max_relative + 1, self.head_dim))
        self.rel_v = nn.Parameter(torch.zeros(2 * max_relative + 1, self.head_dim))

    def forward(self, x: Tensor, memory: Tensor, key_mask: Tensor | None = None) -> Tensor:
        """Attend from ``x [B, T, D]`` to ``memory [B, T, D]`` (same frames).

        Args:
            x: Queries.
            memory: Keys/values.
            key_mask: ``[B, T]`` True where a frame may be attended to, or ``[B, T, T]``
                per query frame.
        """
        num_b, num_t, dim = x.shape
        h, d = self.heads, self.head_dim
        q = self.q(x).view(num_b, num_t, h, d).transpose(1, 2)
        k, v = self.kv(memory).view(num_b, num_t, 2, h, d).permute(2, 0, 3, 1, 4)
        frames = torch.arange(num_t, device=x.device)
        rel = (frames[None, :] - frames[:, None]).clamp(-self.max_relative, self.max_relative)
        rel = rel + self.max_relative
        rk, rv = self.rel_k[rel], self.rel_v[rel]  # [T, T, d]
        logits = (q @ k.transpose(-1, -2) + torch.einsum("bhid,ijd->bhij", q, rk)) / math.sqrt(d)
        if key_mask is not None:
            allowed = key_mask[:, None] if key_mask.dim() == 3 else key_mask[:, None, None, :]
            logits = logits.masked_fill(~allowed, float("-inf"))
        attn = logits.softmax(dim=-1)
        out = attn @ v + torch.einsum("bhij,ijd->bhid", attn, rv)
        return self.out(out.transpose(1, 2).reshape(num_b, num_t, dim))


def _masked_norm(norm: nn.Module, x: Tensor, where: Tensor | None) -> Tensor:
    """``norm(x)`` on the frames where ``where [B, T]`` is True (all when ``None``)."""
    return norm(x) if where is None else torch.where(where[..., None], norm(x), x)


class Block(nn.Module):
    """Transformer block: relative attention then a GELU feed-forward, with RMSNorm.

    Pre-norm by default; ``post_norm`` (the authors') normalises after each
    residual sum, and then only the frames of ``norm_mask`` when it is given.
    ``cross=False`` marks a self-attention block: its memory norm ``norm_m``
    is never used, so it is frozen (kept only so checkpoints keep their keys and
    optimiser states their sizes); a trainable parameter without a gradient
    stops Lightning's plain ``ddp`` strategy at the first step.
    """

    def __init__(
        self,
        dim: int,
        heads: int,
        ff_mult: int,
        max_relative: int,
        post_norm: bool = False,
        cross: bool = True,
    ) -> None:
        super().__init__()
        eps = AUTHORS_RMS_EPS if post_norm else None
        self.post_norm = post_norm
        self.norm_q = nn.RMSNorm(dim, eps=eps)
        if not post_norm:
            self.norm_m = nn.RMSNorm(dim)
            self.norm_m.requires_grad_(cross)
        self.attn = RelativeAttention(dim, heads, max_relative)
        self.norm_ff = nn.RMSNorm(dim, eps=eps)
        self.ff = nn.Sequential(
            nn.Linear(dim, dim * ff_mult), nn.GELU(), nn.Linear(dim * ff_mult, dim)
        )

    def forward(
        self,
        x: Tensor,
        memory: Tensor | None = None,
        key_mask: Tensor | None = None,
        norm_mask: Tensor | None = None,
    ) -> Tensor:
        """Self-attention (``memory=None``) or cross-attention, then feed-forward.

        Args:
            x: ``[B, T, D]`` queries.
            memory: ``[B, T, D]`` keys and values (``None``: ``x``).
            key_mask: See :meth:`RelativeAttention.forward`.
            norm_mask: ``[B, T]`` frames the post-norms apply to (``None``: all).
        """
        if self.post_norm:
            x = x + self.attn(x, x if memory is None else memory, key_mask)
            x = _masked_norm(self.norm_q, x, norm_mask)
            return _masked_norm(self.norm_ff, x + self.ff(x), norm_mask)
        q = self.norm_q(x)
        m = q if memory is None else self.norm_m(memory)
        x = x + self.attn(q, m, key_mask)
        return x + self.ff(self.norm_ff(x))


class CITLInterpolator(nn.Module):
    """CITL's keyframe encoder, intermediate-token module and decoder.

    Args:
        in_features: Per-frame input size (``10 J + 1``).
        out_features: Per-frame output size (``4 J + 3``).
        dim: Width.
        heads: Attention heads.
        layers: Blocks in each of the three stages.
        ff_mult: Feed-forward expansion.
        max_relative: Largest distinguished frame distance of the relative positions.
        zero_output: Initialise the output layer to zero (for residual outputs).
        interm_features: Size of the per-frame input of the intermediate tokens
            (``interm_tokens="lerp"``); 0: the tokens start at zero, as in CITL.
        layout: ``"skelagnostic"`` or ``"authors"`` (see the module docstring).
    """

    def __init__(
        self,
        in_features: int,
        out_features: int,
        dim: int,
        heads: int,
        layers: int,
        ff_mult: int = 4,
        max_relative: int = 128,
        zero_output: bool = False,
        interm_features: int = 0,
        layout: str = "skelagnostic",
    ) -> None:
        super().__init__()
        if layout not in LAYOUTS:
            raise SkelagnosticError(
                f"CITLInterpolator: layout={layout!r} is not one of {', '.join(LAYOUTS)}"
            )
        self.layout = layout
        post = layout == "authors"
        self.embed = nn.Linear(in_features, dim)
        self.interm_embed = nn.Linear(interm_features, dim) if interm_features > 0 else None
        self.encoder = nn.ModuleList(
            Block(dim, heads, ff_mult, max_relative, post, cross=False) for _ in range(layers)
        )
        self.interm = nn.ModuleList(
            Block(dim, heads, ff_mult, max_relative, post, cross=True) for _ in range(layers)
        )
        eps = AUTHORS_RMS_EPS if post else None
        self.key_ff = nn.Sequential(
            nn.Linear(dim, dim * ff_mult),
            nn.GELU(),
            nn.Linear(dim * ff_mult, dim),
            nn.RMSNorm(dim, eps=eps),
        )
        self.interm_ff = nn.Sequential(
            nn.Linear(dim, dim * ff_mult),
            nn.GELU(),
            nn.Linear(dim * ff_mult, dim),
            nn.RMSNorm(dim, eps=eps),
        )
        self.decoder = nn.ModuleList(
            Block(dim, heads, ff_mult, max_relative, post, cross=False) for _ in range(layers)
        )
        self.head = nn.Linear(dim, out_features)
        if zero_output:
            nn.init.zeros_(self.head.weight)
            nn.init.zeros_(self.head.bias)

    def forward(self, inputs: Tensor, keys: Tensor, interm_inputs: Tensor | None = None) -> Tensor:
        """``[B, T, in] -> [B, T, out]``.

        Args:
            inputs: Keyframe features (zeros on the other frames).
            keys: ``[B, T]`` boolean keyframe mask.
            interm_inputs: ``[B, T, interm_features]`` start of the intermediate tokens
                (required when the network was built with ``interm_features``).
        """
        key_mask: Tensor = keys
        enc_norm = interm_norm = None
        if self.layout == "authors":  # every frame also sees itself; masked post-norms
            eye = torch.eye(keys.shape[-1], dtype=torch.bool, device=keys.device)
            key_mask = keys[:, None, :] | eye
            enc_norm, interm_norm = keys, ~keys
        enc = self.embed(inputs)
        for block in self.encoder:
            enc = block(enc, key_mask=key_mask, norm_mask=enc_norm)
        if self.interm_embed is None:
            interm = torch.zeros_like(enc)
        else:
            if interm_inputs is None:
                raise SkelagnosticError("CITLInterpolator: interm_inputs are required")
            interm = self.interm_embed(interm_inputs)
        for block in self.interm:
            interm = block(interm, memory=enc, key_mask=key_mask, norm_mask=interm_norm)
        manifold = torch.where(keys[..., None], self.key_ff(enc), self.interm_ff(interm))
        for block in self.decoder:
            manifold = block(manifold)
        return self.head(manifold)
