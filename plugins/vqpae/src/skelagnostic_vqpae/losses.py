"""VQ-PAE training terms beside the reconstruction: the phase-rate loss, the pivot MPJPE."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from torch import Tensor

from skelagnostic.errors import SkelagnosticError
from skelagnostic_vqpae.model import VQPAE, PhaseParameters, phase_advance_rate

__all__ = ["phase_rate_loss", "pivot_mpjpe"]


def phase_rate_loss(
    pae: VQPAE, name: str, batch: Mapping[str, Tensor], params: PhaseParameters, mode: str
) -> Tensor:
    """Mean L1 (Hz) between the two windows' frequencies and their phase advance rate.

    Args:
        pae: The dataset's VQ-PAE.
        name: The dataset's name (for the error).
        batch: Its training batch, with the partner windows (``shifted``, ``shift``).
        params: The VQ-PAE's output on ``batch["features"]``.
        mode: What the loss trains (``model.phase_rate_grad``).

    Raises:
        SkelagnosticError: The batch has no partner windows.
    """
    if "shifted" not in batch:
        raise SkelagnosticError(
            f"model.lambda_phase_rate > 0 needs partner windows, but the training batch of "
            f"dataset {name!r} has none: set data.pair_seconds > 0 (VqpaeDataModule)"
        )
    shift = batch["shift"].to(params.phase)
    valid = shift != 0
    if not bool(valid.any()):
        return params.phase.new_zeros(())
    freq1 = params.frequency
    if mode == "head":
        # only the frequency MLP learns from it: the encoder's signal is detached
        freq1 = pae.frequency_of(params.signal.detach())
        with torch.no_grad():
            phase2, _, signal2 = pae.phase_and_frequency(batch["shifted"])
        freq2 = pae.frequency_of(signal2)
    elif mode == "timing":
        # the timing branch (kernel-1 conv + frequency MLP) learns, the shared latent not
        with torch.no_grad():
            latents = pae.encoder(torch.cat([batch["features"], batch["shifted"]]))
        phases, freqs, _ = pae.timing(latents)
        freq1, freq2 = freqs.chunk(2)
        phase2 = phases.chunk(2)[1]
    else:
        phase2, freq2, _ = pae.phase_and_frequency(batch["shifted"])
    rate = phase_advance_rate(params.phase[valid], phase2[valid], shift[valid], pae.fps).detach()
    return 0.5 * ((freq1[valid] - rate).abs().mean() + (freq2[valid] - rate).abs().mean())


def pivot_mpjpe(char: Any, params: PhaseParameters, poses: Tensor) -> Tensor:
    """Mean joint error (the poses' units) of the average pose at the windows' pivot frames.

    Args:
        char: The dataset's networks (``pose`` MLP and ``pose_mean`` / ``pose_std``).
        params: The VQ-PAE's output.
        poses: ``[B, T, P]`` normalised target poses of the windows.
    """
    pivot = params.manifold.shape[-1] // 2
    pred = char.pose(params.manifold[..., pivot]) * char.pose_std + char.pose_mean
    true = poses[:, pivot] * char.pose_std + char.pose_mean
    return (pred - true).view(len(pred), -1, 3).norm(dim=-1).mean()
