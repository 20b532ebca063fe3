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
from skelagnostic_pcmrl.layouts import AUTHORS_RMS_EPS, LAYOUTS


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

    def forward(
        self,
        x: Tensor,
        memory: Tensor,
        key_mask: Tensor | None = None,
        frames: tuple[Tensor, Tensor] | None = None,
    ) -> Tensor:
        """Attend from ``x [B, T, D]`` to ``memory [B, S, D]``.

        Args:
            x: Queries.
            memory: Keys/values.
            key_mask: ``[B, S]`` True where a token may be attended to, or ``[B, T, S]``
                per query.
            frames: ``([B, T], [B, S])`` frame indices of the queries and of the keys, for
                the relative positions; ``None``: both are the frames ``0 .. T - 1``
                (``S == T``).
        """
        num_b, num_t, dim = x.shape
        num_s = memory.shape[1]
        h, d = self.heads, self.head_dim
        q = self.q(x).view(num_b, num_t, h, d).transpose(1, 2)
        k, v = self.kv(memory).view(num_b, num_s, 2, h, d).permute(2, 0, 3, 1, 4)
        if frames is None:
            pos = torch.arange(num_t, device=x.device)
            rel = pos[None, :] - pos[:, None]  # [T, T], shared by the batch
            pattern_k, pattern_v = "bhid,ijd->bhij", "bhij,ijd->bhid"
        else:
            rel = frames[1][:, None, :] - frames[0][:, :, None]  # [B, T, S]
            pattern_k, pattern_v = "bhid,bijd->bhij", "bhij,bijd->bhid"
        rel = rel.clamp(-self.max_relative, self.max_relative) + self.max_relative
        rk, rv = self.rel_k[rel], self.rel_v[rel]  # [(B,) T, S, d]
        logits = (q @ k.transpose(-1, -2) + torch.einsum(pattern_k, q, rk)) / math.sqrt(d)
        if key_mask is not None:
            allowed = key_mask[:, None] if key_mask.dim() == 3 else key_mask[:, None, None, :]
            logits = logits.masked_fill(~allowed, float("-inf"))
        attn = logits.softmax(dim=-1)
        out = attn @ v + torch.einsum(pattern_v, attn, rv)
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
        frames: tuple[Tensor, Tensor] | None = None,
    ) -> Tensor:
        """Self-attention (``memory=None``) or cross-attention, then feed-forward.

        Args:
            x: ``[B, T, D]`` queries.
            memory: ``[B, S, D]`` keys and values (``None``: ``x``).
            key_mask: See :meth:`RelativeAttention.forward`.
            norm_mask: ``[B, T]`` frames the post-norms apply to (``None``: all).
            frames: See :meth:`RelativeAttention.forward`.
        """
        if self.post_norm:
            x = x + self.attn(x, x if memory is None else memory, key_mask, frames)
            x = _masked_norm(self.norm_q, x, norm_mask)
            return _masked_norm(self.norm_ff, x + self.ff(x), norm_mask)
        q = self.norm_q(x)
        m = q if memory is None else self.norm_m(memory)
        x = x + self.attn(q, m, key_mask, frames)
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
        fast_path: Run the encoder and the intermediate blocks' keys and values on the
            keyframe tokens only (same values; see the module docstring).
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
        fast_path: bool = True,
    ) -> None:
        super().__init__()
        if layout not in LAYOUTS:
            raise SkelagnosticError(
                f"CITLInterpolator: layout={layout!r} is not one of {', '.join(LAYOUTS)}"
            )
        self.layout = layout
        self.fast_path = fast_path
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
        if self.fast_path and self.layout == "skelagnostic" and not _tracing():
            return self._forward_packed(inputs, keys, interm_inputs)
        key_mask: Tensor = keys
        enc_norm = interm_norm = None
        if self.layout == "authors":  # every frame also sees itself; masked post-norms
            eye = torch.eye(keys.shape[-1], dtype=torch.bool, device=keys.device)
            key_mask = keys[:, None, :] | eye
            enc_norm, interm_norm = keys, ~keys
        enc = self.embed(inputs)
        for block in self.encoder:
            enc = block(enc, key_mask=key_mask, norm_mask=enc_norm)
        interm = self._interm_start(enc, interm_inputs)
        for block in self.interm:
            interm = block(interm, memory=enc, key_mask=key_mask, norm_mask=interm_norm)
        manifold = torch.where(keys[..., None], self.key_ff(enc), self.interm_ff(interm))
        return self._decode(manifold)

    def _interm_start(self, like: Tensor, interm_inputs: Tensor | None) -> Tensor:
        """The intermediate tokens before the first block.

        Args:
            like: ``[B, T, D]``: the shape, type and device of zero tokens.
            interm_inputs: What ``interm_embed`` embeds (when the network has it).
        """
        if self.interm_embed is None:
            return like.new_zeros(like.shape)
        if interm_inputs is None:
            raise SkelagnosticError("CITLInterpolator: interm_inputs are required")
        return self.interm_embed(interm_inputs)

    def _decode(self, manifold: Tensor) -> Tensor:
        """The decoder blocks and the output layer."""
        for block in self.decoder:
            manifold = block(manifold)
        return self.head(manifold)

    def _forward_packed(self, inputs: Tensor, keys: Tensor, interm_inputs: Tensor | None) -> Tensor:
        """:meth:`forward` of the ``"skelagnostic"`` layout with the encoder on the keyframes only.

        The keyframes of each window are packed in frame order into ``K`` tokens
        (``K``: the batch's largest keyframe count; padding tokens are masked out as
        keys and dropped from the output), attended with their own frame indices.
        """
        num_b, num_t = keys.shape
        count = keys.sum(dim=-1)
        width = int(count.max())
        # stable sort of ~keys: each window's key frames first, in frame order
        order = torch.argsort((~keys).to(torch.uint8), dim=-1, stable=True)[:, :width]
        valid = torch.arange(width, device=keys.device)[None, :] < count[:, None]  # [B, K]
        all_frames = torch.arange(num_t, device=keys.device).expand(num_b, -1)
        gather = order[..., None].expand(-1, -1, inputs.shape[-1])
        enc = self.embed(torch.gather(inputs, 1, gather))  # [B, K, D]
        for block in self.encoder:
            enc = block(enc, key_mask=valid, frames=(order, order))
        interm = self._interm_start(enc[:, :1].expand(-1, num_t, -1), interm_inputs)
        for block in self.interm:
            interm = block(interm, memory=enc, key_mask=valid, frames=(all_frames, order))
        # key tokens back to their frames; the padding tokens land on non-key frames,
        # which take the intermediate tokens
        index = order[..., None].expand(-1, -1, enc.shape[-1])
        key_tokens = torch.zeros_like(interm).scatter(1, index, self.key_ff(enc))
        manifold = torch.where(keys[..., None], key_tokens, self.interm_ff(interm))
        return self._decode(manifold)


def _tracing() -> bool:
    """Whether the module is being traced or exported (shapes must not depend on values)."""
    return bool(torch.jit.is_tracing() or torch.compiler.is_compiling())
