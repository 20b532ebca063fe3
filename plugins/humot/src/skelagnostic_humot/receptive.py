"""Receptive field of HuMoT's encoder: does the latent at frame f see each joint at frame f?

A latent code ``z[f]`` that is to reconstruct every joint at frame ``f`` must
depend on the input of every joint at that frame more than on the input at
frames far away. :func:`receptive_field` measures it, per joint ``j``, as the
ratio::

    ||d z[f] / d x[f, j]||  /  mean over |g - f| > distance of ||d z[f] / d x[g, j]||

where ``x`` is the encoder's input ``[F, J, 3]`` (positions in the model
frame, centred as :func:`~skelagnostic_humot.data.prepare_chunks` centres a
chunk), ``z`` its output ``[F, Z]`` and ``||.||`` the Frobenius norm of the
``Z x 3`` Jacobian block. The check (issue #45, item 5) asks for a ratio above
5 at every **major joint**: the ankles, knees, hips, shoulders, elbows and
wrists of :func:`~skelagnostic_humot.template.major_joints`, the joints the
paper's subsampling keeps with the higher probability; the ratios of the other
joints are reported too.

The gradients are taken with the network in eval mode (the batch norm of the
local patch interaction uses its running statistics, as at inference), on one
chunk: the template pose of the skeleton scaled to 1.7 m with Gaussian jitter
(2 cm, fixed seed) unless ``positions`` gives a real chunk. The measurement
works on any checkpoint (pass the aligner) and on any callable encoder
``(motion [B, F, J, 3], template [B, J, 3]) -> [B, F, Z]``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from skelagnostic.core.skeleton import Skeleton
from skelagnostic.errors import SkelagnosticError
from skelagnostic_humot.data import Topology, prepare_chunks
from skelagnostic_humot.template import major_joints

__all__ = ["ReceptiveField", "receptive_field"]

Encoder = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class ReceptiveField:
    """Per-joint ratios of :func:`receptive_field`.

    Attributes:
        ratios: Joint name -> near / far gradient ratio, in skeleton order (``inf`` when
            the far frames have no influence at all).
        major: The names of the major joints the check is made on.
        frame: The latent frame ``f``.
        distance: Frames further than this from ``f`` are "far".
        threshold: A joint passes when its ratio exceeds this.
    """

    ratios: dict[str, float]
    major: tuple[str, ...]
    frame: int
    distance: int
    threshold: float

    def failing(self) -> list[str]:
        """The major joints whose ratio does not exceed the threshold, in skeleton order."""
        return [name for name in self.major if not self.ratios[name] > self.threshold]

    @property
    def passed(self) -> bool:
        """Whether every major joint passes."""
        return not self.failing()


def _encoder(model: Any) -> Encoder:
    """The encoder of an aligner (``.net.encoder``), a network (``.encoder``) or itself."""
    net = getattr(model, "net", model)
    encoder = getattr(net, "encoder", net)
    if not callable(encoder):
        raise SkelagnosticError(f"receptive_field: {type(model).__name__} has no callable encoder")
    return encoder


def _default_positions(skeleton: Skeleton, frames: int, seed: int) -> torch.Tensor:
    """``[frames, J, 3]``: the template pose (skeleton axes) scaled to 1.7 m, with 2 cm jitter."""
    pose = skeleton.template().double()
    up = {"x": 0, "y": 1, "z": 2}[skeleton.up_axis]
    height = float(pose[:, up].max() - pose[:, up].min())
    pose = pose * (1.7 / height if height > 0 else 1.0)
    gen = torch.Generator().manual_seed(seed)
    jitter = torch.randn(frames, *pose.shape, generator=gen, dtype=torch.float64) * 0.02
    return pose + jitter


def receptive_field(
    model: Any,
    skeleton: Skeleton,
    frames: int = 30,
    frame: int | None = None,
    distance: int = 5,
    positions: torch.Tensor | None = None,
    seed: int = 0,
    threshold: float = 5.0,
    major: Sequence[int] | None = None,
) -> ReceptiveField:
    """Per joint, how much more the latent at frame ``f`` depends on that frame than on far ones.

    Args:
        model: A :class:`~skelagnostic_humot.aligner.HumotAligner` (e.g. loaded from a
            checkpoint), a :class:`~skelagnostic_humot.model.HuMoT`, its encoder, or any
            callable ``(motion [B, F, J, 3], template [B, J, 3]) -> [B, F, Z]``.
        skeleton: The skeleton whose joints are measured.
        frames: Frames of the chunk (HuMoT's chunk: 30).
        frame: The latent frame ``f`` (default: the middle one, ``frames // 2``).
        distance: Input frames ``g`` with ``|g - f| > distance`` are the far ones.
        positions: ``[>= frames, J, 3]`` world positions in metres in the skeleton's axes
            (a real chunk, e.g. ``evaluation.chunks_of(motion)[0]``); default: the
            template pose scaled to 1.7 m with 2 cm Gaussian jitter (``seed``).
        seed: Seed of the default positions' jitter.
        threshold: The ratio a major joint must exceed (issue #45: 5).
        major: Indices of the joints the check is made on (default: HuMoT's major
            joints, :func:`~skelagnostic_humot.template.major_joints`; all joints if the
            skeleton has none).

    Returns:
        The ratios of every joint and the verdict on the major ones.

    Raises:
        SkelagnosticError: ``frame`` has no far frames, ``positions`` has too few frames
            or the wrong joint count, or ``model`` has no encoder.

    Example:
        >>> import torch, skelagnostic as sa
        >>> from skelagnostic_humot import HumotAligner, receptive_field
        >>> _ = torch.manual_seed(0)
        >>> net = HumotAligner(dim=16, latent=16, blocks=1, heads=2, kernel_size=3).net
        >>> rf = receptive_field(net, sa.procedural.skeleton("biped22"), frames=14)
        >>> len(rf.ratios), len(rf.major)
        (22, 12)
    """
    num = skeleton.num_joints
    frame = frames // 2 if frame is None else frame
    far = [g for g in range(frames) if abs(g - frame) > distance]
    if not 0 <= frame < frames:
        raise SkelagnosticError(f"receptive_field: frame {frame} is not in 0..{frames - 1}")
    if not far:
        raise SkelagnosticError(
            f"receptive_field: frame {frame} of {frames} has no input frame more than "
            f"{distance} frames away"
        )
    if positions is None:
        positions = _default_positions(skeleton, frames, seed)
    if positions.dim() != 3 or positions.shape[0] < frames or positions.shape[1:] != (num, 3):
        raise SkelagnosticError(
            f"receptive_field: positions must have shape [>= {frames}, {num}, 3], "
            f"got {list(positions.shape)}"
        )
    encoder = _encoder(model)
    dtype = torch.float32
    if isinstance(encoder, nn.Module):
        param = next(encoder.parameters(), None)
        dtype = param.dtype if param is not None else dtype
    pos, tmpl = prepare_chunks(
        positions[None, :frames].to(dtype), Topology.of(skeleton), skeleton.up_axis
    )
    if isinstance(encoder, nn.Module):
        device = next(encoder.parameters(), torch.empty(0)).device
        pos, tmpl = pos.to(device), tmpl.to(device)
    x = pos.detach().to(dtype).requires_grad_(True)
    modes = [(m, m.training) for m in encoder.modules()] if isinstance(encoder, nn.Module) else []
    for m, _ in modes:
        m.training = False
    try:
        with torch.enable_grad():
            z = encoder(x, tmpl.detach().to(dtype))[0, frame]  # [Z]
            squared = torch.zeros(frames, num, dtype=torch.float64, device=x.device)
            for c in range(z.shape[0] if z.requires_grad else 0):  # one Jacobian row each
                (grad,) = torch.autograd.grad(
                    z[c], x, retain_graph=c + 1 < z.shape[0], allow_unused=True
                )
                if grad is not None:
                    squared += grad[0].double().pow(2).sum(-1)
    finally:
        for m, mode in modes:
            m.training = mode
    norms = squared.sqrt().cpu()  # [F, J]: ||d z[f] / d x[g, j]||
    near, far_mean = norms[frame], norms[far].mean(0)
    ratios = {}
    for j, name in enumerate(skeleton.joint_names):
        a, b = float(near[j]), float(far_mean[j])
        ratios[name] = a / b if b > 0 else (float("inf") if a > 0 else float("nan"))
    if major is None:
        major = sorted(major_joints(skeleton).values()) or list(range(num))
    return ReceptiveField(
        ratios=ratios,
        major=tuple(skeleton.joint_names[j] for j in major),
        frame=frame,
        distance=distance,
        threshold=threshold,
    )
