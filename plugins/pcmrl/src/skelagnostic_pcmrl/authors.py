"""Run the PC-MRL authors' trained networks inside skelagnostic (issue #26, item 6).

The authors' training scripts (github.com/MiniEval/PC-MRL) save plain state
dicts: ``train_pointcloud.py`` writes ``ckpt_pc-mrl/PCMRL{step}.pt`` (their
``PointCloudDecoder``: point encoder and temporal transformer) and
``train_inpainter.py`` writes ``ckpt_citl/CITL{step}.pt`` (their ``CITL``
interpolation network). :func:`load_stage1` and :func:`load_stage2` read such
files into skelagnostic's own modules, built with ``layout="authors"`` so that
they compute what the authors' networks compute
(:class:`~skelagnostic_pcmrl.recon.point_transformer.PointTransformerEncoder`,
:class:`~skelagnostic_pcmrl.recon.temporal.TemporalTransformer`,
:class:`~skelagnostic_pcmrl.interp.network.CITLInterpolator`). Every tensor is
moved by an explicit key mapping; a missing, unexpected or misshapen key is an
error naming the file and the key.

The sizes are read from the weights. What the weights do not tell takes the
paper's value and can be given: the attention heads (4 in stage 1, 8 in stage
2) and the pooling neighbours ``k`` (8).

The networks take what the authors' networks take: stage 1 a
``[B, T, N, 3 + groups]`` cloud (centred on the mean of all its points, as
their training does) and returns ``[B, T, 3 + 4 J]`` (root position, then raw
``w, x, y, z`` global quaternions of the target joints with a non-zero bone);
stage 2 their ``[B, T, 10 J]`` keyframe features and ``[B, T]`` keyframe mask
and returns ``[B, T, 3 + 4 J]`` (root, raw FOQ quaternions).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

import torch
from torch import Tensor, nn

from skelagnostic.errors import SkelagnosticError
from skelagnostic_pcmrl.interp.network import CITLInterpolator
from skelagnostic_pcmrl.recon.point_transformer import PointTransformerEncoder
from skelagnostic_pcmrl.recon.temporal import (
    AUTHORS_POSITION_DIM,
    TemporalTransformer,
    sinusoidal_positions,
)

__all__ = ["Stage1Network", "load_stage1", "load_stage2", "read_state"]

#: Their attention heads, pooling neighbours and down-sampling factor (config.json).
STAGE1_HEADS, STAGE1_K, STAGE1_RATIO = 4, 8, 4
STAGE2_HEADS = 8


class Stage1Network(nn.Module):
    """Point encoder then temporal transformer: ``[B, T, N, C] -> [B, T, out]``.

    Args:
        encoder: The per-frame point encoder.
        temporal: The temporal transformer over the frame features.
    """

    def __init__(self, encoder: PointTransformerEncoder, temporal: TemporalTransformer) -> None:
        super().__init__()
        self.encoder = encoder
        self.temporal = temporal

    def forward(self, clouds: Tensor) -> Tensor:
        """Encode every frame's cloud, then the sequence of frame features."""
        return self.temporal(self.encoder(clouds))


def read_state(source: str | Path | Mapping[str, Tensor]) -> tuple[dict[str, Tensor], str]:
    """A state dict and its name for messages, from a file written by ``torch.save`` or a dict.

    Raises:
        SkelagnosticError: The file is missing, unreadable or holds no state dict.
    """
    if isinstance(source, Mapping):
        return dict(source), "<state dict>"
    path = Path(source)
    if not path.is_file():
        raise SkelagnosticError(f"{path}: no such checkpoint file")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a bad file
        raise SkelagnosticError(f"{path}: not a readable torch checkpoint ({exc})") from exc
    if not isinstance(state, Mapping) or not all(isinstance(v, Tensor) for v in state.values()):
        raise SkelagnosticError(
            f"{path}: expected a state dict of tensors (as the authors' "
            "training saves), got something else"
        )
    return dict(state), str(path)


class _Mapper:
    """Collects ``ours <- f(theirs...)`` tensors and checks every key of theirs is used."""

    def __init__(self, state: dict[str, Tensor], name: str) -> None:
        self.state, self.name = state, name
        self.used: set[str] = set()
        self.out: dict[str, Tensor] = {}

    def get(self, key: str) -> Tensor:
        if key not in self.state:
            raise SkelagnosticError(f"{self.name}: missing key {key!r} in the authors' checkpoint")
        self.used.add(key)
        return self.state[key]

    def put(self, ours: str, *theirs: str, join: Callable[..., Tensor] | None = None) -> None:
        tensors = [self.get(k) for k in theirs]
        self.out[ours] = tensors[0] if join is None else join(*tensors)

    def count(self, prefix: str) -> int:
        """How many ``prefix{i}.`` blocks the checkpoint has."""
        pattern = re.compile(re.escape(prefix) + r"(\d+)\.")
        found = {int(m.group(1)) for k in self.state if (m := pattern.match(k))}
        if found != set(range(len(found))):
            raise SkelagnosticError(
                f"{self.name}: blocks {prefix}* are not numbered 0..n-1: {sorted(found)}"
            )
        return len(found)

    def load_into(self, module: nn.Module) -> None:
        unused = sorted(set(self.state) - self.used)
        if unused:
            raise SkelagnosticError(
                f"{self.name}: unexpected key {unused[0]!r} in the authors' "
                f"checkpoint ({len(unused)} not mapped)"
            )
        own = module.state_dict()
        for key, value in self.out.items():
            if key not in own:  # a mapping error of this module, not of the file
                raise SkelagnosticError(f"{self.name}: mapped to unknown parameter {key!r}")
            if own[key].shape != value.shape:
                raise SkelagnosticError(
                    f"{self.name}: key for {key!r} has shape "
                    f"{tuple(value.shape)}, expected {tuple(own[key].shape)}"
                )
        missing = sorted(set(own) - set(self.out))
        if missing:
            raise SkelagnosticError(
                f"{self.name}: nothing in the checkpoint maps to {missing[0]!r}"
            )
        module.load_state_dict(self.out)


def _shape(m: _Mapper, key: str, dims: int) -> tuple[int, ...]:
    shape = tuple(m.get(key).shape)
    if len(shape) != dims:
        raise SkelagnosticError(
            f"{m.name}: key {key!r} has shape {shape}, expected {dims} dimensions"
        )
    return shape


def _concat(*tensors: Tensor) -> Tensor:
    return torch.cat(tensors, dim=0)


def load_stage1(
    source: str | Path | Mapping[str, Tensor], heads: int = STAGE1_HEADS, k: int = STAGE1_K
) -> Stage1Network:
    """The authors' stage-1 network (their ``PointCloudDecoder``) from its checkpoint.

    Args:
        source: ``PCMRL{step}.pt`` as their ``train_pointcloud.py`` saves it, or its state dict.
        heads: Heads of the temporal attention (``temporal_n_heads``, 4).
        k: Neighbours of the pooling stages (``k_farthest_first``, 8).

    Returns:
        A :class:`Stage1Network` in eval mode.

    Raises:
        SkelagnosticError: The file or one of its keys is missing, unexpected or misshapen.
    """
    state, name = read_state(source)
    m = _Mapper(state, name)
    dim, in_features = _shape(m, "cloud_encoder.p_in.weight", 2)
    stage_sizes = sorted(
        (
            int(g)
            for key in state
            if (g := _match(r"cloud_encoder\.attn_(\d+)\.attn_norm\.scale$", key))
        ),
        reverse=True,
    )
    layers = m.count("motion_enc.")
    out_dim, width = _shape(m, "motion_out.weight", 2)
    if width % heads:
        raise SkelagnosticError(f"{name}: temporal width {width} is not divisible by {heads} heads")
    encoder = PointTransformerEncoder(
        in_features - 3, dim, len(stage_sizes), k=k, ratio=STAGE1_RATIO, layout="authors"
    )
    if width != encoder.out_channels + AUTHORS_POSITION_DIM:
        raise SkelagnosticError(
            f"{name}: key 'motion_out.weight' has width {width}, expected the "
            f"point feature {encoder.out_channels} + {AUTHORS_POSITION_DIM}"
        )
    net = Stage1Network(
        encoder,
        TemporalTransformer(encoder.out_channels, width, layers, heads, out_dim, layout="authors"),
    )
    m.put("encoder.embed.weight", "cloud_encoder.p_in.weight")
    m.put("encoder.embed.bias", "cloud_encoder.p_in.bias")
    for i, size in enumerate(stage_sizes):
        theirs, ours = f"cloud_encoder.attn_{size}.", f"encoder.stages.{i}."
        m.put(ours + "norm1.weight", theirs + "attn_norm.scale")
        m.put(ours + "norm2.weight", theirs + "ff_norm.scale")
        for mine, their in (
            ("q", "attn.fc_q"),
            ("k_proj", "attn.fc_k"),
            ("v", "attn.fc_v"),
            ("o", "attn.fc_o"),
            ("ff.0", "ff_in"),
            ("ff.2", "ff_out"),
        ):
            for p in ("weight", "bias"):
                m.put(f"{ours}{mine}.{p}", f"{theirs}{their}.{p}")
        m.put(ours + "pool_in.weight", theirs + "pool.mlp_in.weight")
        m.put(ours + "pool_out.weight", theirs + "pool.mlp_out.weight")
    for mine, their in (("head_in", "mlp_in"), ("head_out", "mlp_out")):
        for p in ("weight", "bias"):
            m.put(f"encoder.{mine}.{p}", f"cloud_encoder.{their}.{p}")
    pe = m.get("pe.pe")
    own_pe = sinusoidal_positions(pe.shape[0], AUTHORS_POSITION_DIM)
    if pe.shape != own_pe.shape or not torch.allclose(pe.float(), own_pe, atol=1e-6):
        raise SkelagnosticError(
            f"{name}: key 'pe.pe' is not the {AUTHORS_POSITION_DIM}-channel "
            "sinusoidal encoding this loader computes"
        )
    for i in range(layers):
        theirs, ours = f"motion_enc.{i}.", f"temporal.blocks.{i}."
        m.put(ours + "norm1.weight", theirs + "attn_norm.scale")
        m.put(ours + "norm2.weight", theirs + "ff_norm.scale")
        for p in ("in_proj_weight", "in_proj_bias", "out_proj.weight", "out_proj.bias"):
            m.put(f"{ours}attn.{p}", f"{theirs}attn.{p}")
        for mine, their in (("ff.0", "ff_in"), ("ff.3", "ff_out")):
            for p in ("weight", "bias"):
                m.put(f"{ours}{mine}.{p}", f"{theirs}{their}.{p}")
    m.put("temporal.out.weight", "motion_out.weight")
    m.put("temporal.out.bias", "motion_out.bias")
    m.load_into(net)
    return net.eval()


def load_stage2(
    source: str | Path | Mapping[str, Tensor], heads: int = STAGE2_HEADS
) -> CITLInterpolator:
    """The authors' stage-2 network (their ``CITL``) from its checkpoint.

    Args:
        source: ``CITL{step}.pt`` as their ``train_inpainter.py`` saves it, or its state dict.
        heads: Attention heads (``n_heads``, 8).

    Returns:
        A :class:`~skelagnostic_pcmrl.interp.network.CITLInterpolator` with
        ``layout="authors"``, in eval mode.

    Raises:
        SkelagnosticError: The file or one of its keys is missing, unexpected or misshapen.
    """
    state, name = read_state(source)
    m = _Mapper(state, name)
    dim, in_features = _shape(m, "encoder.embed_in.weight", 2)
    out_features, _ = _shape(m, "decoder.output.weight", 2)
    hidden, _ = _shape(m, "decoder.key_ff_in.weight", 2)
    table, head_dim = _shape(m, "encoder.encoder.0.attn.relative_position_k.embeddings_table", 2)
    if dim % heads or dim // heads != head_dim or hidden % dim:
        raise SkelagnosticError(
            f"{name}: width {dim}, relative table width {head_dim} and "
            f"feed-forward width {hidden} do not fit {heads} heads"
        )
    stacks = {
        "encoder": "encoder.encoder.",
        "interm": "interm.encoder.",
        "decoder": "decoder.decoder.",
    }
    layers = {ours: m.count(theirs) for ours, theirs in stacks.items()}
    if len(set(layers.values())) != 1:
        raise SkelagnosticError(
            f"{name}: the encoder, intermediate and decoder stacks have different depths {layers}"
        )
    net = CITLInterpolator(
        in_features,
        out_features,
        dim,
        heads,
        layers["encoder"],
        hidden // dim,
        (table - 1) // 2,
        layout="authors",
    )
    m.put("embed.weight", "encoder.embed_in.weight")
    m.put("embed.bias", "encoder.embed_in.bias")
    for ours_stack, theirs_stack in stacks.items():
        for i in range(layers[ours_stack]):
            theirs, ours = f"{theirs_stack}{i}.", f"{ours_stack}.{i}."
            m.put(ours + "norm_q.weight", theirs + "attn_norm.scale")
            m.put(ours + "norm_ff.weight", theirs + "ff_norm.scale")
            for p in ("weight", "bias"):
                m.put(f"{ours}attn.q.{p}", f"{theirs}attn.fc_q.{p}")
                m.put(
                    f"{ours}attn.kv.{p}",
                    f"{theirs}attn.fc_k.{p}",
                    f"{theirs}attn.fc_v.{p}",
                    join=_concat,
                )
                m.put(f"{ours}attn.out.{p}", f"{theirs}attn.fc_o.{p}")
                m.put(f"{ours}ff.0.{p}", f"{theirs}ff_in.{p}")
                m.put(f"{ours}ff.2.{p}", f"{theirs}ff_out.{p}")
            m.put(ours + "attn.rel_k", theirs + "attn.relative_position_k.embeddings_table")
            m.put(ours + "attn.rel_v", theirs + "attn.relative_position_v.embeddings_table")
    for branch in ("key", "interm"):
        for p in ("weight", "bias"):
            m.put(f"{branch}_ff.0.{p}", f"decoder.{branch}_ff_in.{p}")
            m.put(f"{branch}_ff.2.{p}", f"decoder.{branch}_ff_out.{p}")
        m.put(f"{branch}_ff.3.weight", f"decoder.{branch}_ff_norm.scale")
    m.put("head.weight", "decoder.output.weight")
    m.put("head.bias", "decoder.output.bias")
    m.load_into(net)
    return net.eval()


def _match(pattern: str, key: str) -> str | None:
    found = re.match(pattern, key)
    return found.group(1) if found else None
