"""Convolution padding: the zero-padding shortcut that erased the quadruped's phase, and its fix.

With zero "same" padding, a kernel-23 convolution turns a window that is constant
in time into an output that varies with the distance to the window edges; the
decoder can then rebuild a window from its pivot manifold point alone and the
timing branch stops mattering (the procedural quadruped's phase collapsed that
way). Replicate padding maps a constant window to a constant output, so the
temporal shape must come from the phase ``phi + f t``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from skelagnostic_vqpae.codebook import SharedCodebook
from skelagnostic_vqpae.model import VQPAE

from skelagnostic import procedural
from skelagnostic.errors import SkelagnosticError
from skelagnostic.representations import RootLocalVelocities


def _decoder_output(padding_mode: str) -> torch.Tensor:
    torch.manual_seed(0)
    net = VQPAE(12, 31, fps=30.0, latent=4, kernel_size=23, padding_mode=padding_mode)
    constant = torch.randn(2, 4, 1).expand(2, 4, 31)  # f = 0: the same point at every frame
    with torch.no_grad():
        return net.decoder(constant)


def test_replicate_padding_keeps_a_constant_window_constant() -> None:
    out = _decoder_output("replicate")
    assert float((out - out[..., :1]).abs().max()) < 1e-5


def test_zero_padding_creates_edge_profiles() -> None:
    out = _decoder_output("zeros")
    spread = (out - out.mean(-1, keepdim=True)).abs().amax(-1)
    assert float(spread.min()) > 1e-3  # every channel varies along the window


def test_rejects_unknown_padding_mode() -> None:
    with pytest.raises(SkelagnosticError, match="padding_mode"):
        VQPAE(12, 31, fps=30.0, padding_mode="mirror")


def _phase_r2(phase: torch.Tensor) -> float:
    unwrapped = torch.from_numpy(np.unwrap(phase.double().numpy() * 2 * math.pi)) / (2 * math.pi)
    t = torch.arange(len(unwrapped), dtype=torch.float64)
    a = torch.stack([t, torch.ones_like(t)], 1)
    fit = torch.linalg.lstsq(a, unwrapped[:, None]).solution
    residual = unwrapped - (a @ fit)[:, 0]
    return float(1 - residual.var() / unwrapped.var())


def _train_quadruped(steps: int, **options: str) -> tuple[float, float, dict[str, tuple]]:
    """Train one quadruped VQ-PAE with the aligner's objective (centred windows).

    Returns the mean loss of the first and last 20 steps and, per held-out gait,
    ``(phase R^2, median predicted frequency, true frequency)``.
    """
    fps, window = 30.0, 31
    rep = RootLocalVelocities()
    clips = [
        rep.encode(procedural.generate("quadruped", g, seconds=6.0, fps=fps, seed=s)[0])
        .float()
        .flatten(1)
        for g in ("walk", "trot", "gallop")
        for s in range(2)
    ]
    frames = torch.cat(clips)
    mean, std = frames.mean(0), frames.std(0).clamp_min(0.01 * frames.std(0).mean())
    windows = torch.cat([((c - mean) / std).unfold(0, window, 1) for c in clips])
    torch.manual_seed(0)
    net = VQPAE(frames.shape[1], window, fps, latent=10, kernel_size=23, **options)
    book = SharedCodebook(8, 20, 1)
    opt = torch.optim.AdamW([*net.parameters(), book.weight], lr=1e-3)
    gen = torch.Generator().manual_seed(0)
    losses = []
    for _ in range(steps):
        x = windows[torch.randint(len(windows), (32,), generator=gen)]
        rec, params = net(x, book.quantizer(0))
        centred = x - x.mean(-1, keepdim=True)  # VqpaeAligner(center_windows=True)
        loss = torch.nn.functional.mse_loss(rec - rec.mean(-1, keepdim=True), centred)
        loss = loss + params.vq_loss
        opt.zero_grad()
        loss.backward()
        book.reinitialize()
        opt.step()
        losses.append(float(loss.detach()))
    held_out = {}
    for gait in ("trot", "gallop"):
        motion, info = procedural.generate("quadruped", gait, seconds=5.0, fps=fps, seed=1000)
        test = rep.encode(motion).float().flatten(1)
        with torch.no_grad():
            params = net.encode(((test - mean) / std).unfold(0, window, 1), book.quantizer(0))
        held_out[gait] = (
            _phase_r2(params.phase),
            float(params.frequency.median()),
            float(info["frequency"]),
        )
    return sum(losses[:20]) / 20, sum(losses[-20:]) / 20, held_out


@pytest.mark.slow
def test_quadruped_keeps_a_linear_phase_with_replicate_padding() -> None:
    """Regression: with zero padding the trained quadruped's phase was flat (R^2 ~ 0).

    The aligner's defaults (replicate padding, centred windows, the paper's
    frequency head): the phase of held-out trot and gallop stays linear.
    """
    first, last, held_out = _train_quadruped(400)
    assert last < 0.5 * first
    for gait, (r2, _, _) in held_out.items():
        assert r2 > 0.98, gait


@pytest.mark.slow
def test_centroid_residual_head_reads_the_trot_and_gallop_frequency() -> None:
    """The paper's head, started at ~1 Hz, read this gallop at about half its rate;
    the head that corrects the spectral centroid starts near the right optimum."""
    first, last, held_out = _train_quadruped(250, frequency_head="centroid_residual")
    assert last < 0.2 * first
    for gait, (r2, predicted, truth) in held_out.items():
        assert r2 > 0.98, gait
        assert abs(predicted - truth) < 0.08 * truth, (gait, predicted, truth)
