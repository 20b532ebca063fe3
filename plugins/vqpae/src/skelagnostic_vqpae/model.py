"""The VQ-PAE network of one dataset (WalkTheDog, Li et al. 2024, Sec. 3.2 and supplement).

Shapes follow PyTorch's ``Conv1d`` layout: an input window is ``[B, C_in, T]``
(``C_in`` = joints x 3 velocity channels, ``T`` odd, the pivot frame at index
``T // 2``). The pieces map to the paper as follows:

* encoder: two ``Conv1d`` (kernel 23, "same" padding, ``C_in -> C_in // 3 -> d``),
  each followed by :class:`TemporalCentering` and ELU (Fig. 2, supplement 2.1);
* timing branch: ``Conv1d(d -> 1)`` (kernel 23 as the authors' code, option
  ``phase_kernel``; the paper's Fig. 3 draws kernel 1), the FFT power spectrum of that
  signal through an MLP (7 layers as the authors, 5 in the paper) for the frequency ``f`` and
  :func:`mason_phase` for the pivot phase ``phi`` (supplement Eq. 1);
* amplitude branch: temporal mean of the latent, a 5-layer MLP to the raw
  amplitude ``A~`` (size ``2d``), quantised by the shared codebook
  (:class:`~skelagnostic_vqpae.codebook.SharedCodebook`);
* manifold: :func:`phase_manifold` of Eq. 1 with ``Phi = phi + f * t``;
* decoder: two ``Conv1d`` (kernel 23, temporal centering and ELU between,
  ``d -> C_in // 3 -> C_in``).

The defaults compute what the authors' ``VQAE`` computes (zero "same" padding, raw
power spectrum); the options hold skelagnostic's variants (``experiment=vqpae_plus``).

:class:`AveragePoseMLP` is the per-dataset MLP of Sec. 5.2 (Eq. 10).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import torch
from torch import Tensor, nn

from skelagnostic.errors import SkelagnosticError

__all__ = [
    "VQPAE",
    "AveragePoseMLP",
    "Character",
    "PhaseParameters",
    "TemporalCentering",
    "mason_phase",
    "phase_advance_rate",
    "phase_manifold",
    "relative_times",
]

#: Padding modes of the encoder/decoder convolutions (``torch.nn.Conv1d``).
PADDING_MODES = ("zeros", "replicate", "reflect", "circular")

#: How :meth:`VQPAE.timing` turns the spectrum into a frequency.
FREQUENCY_HEADS = ("mlp", "centroid_residual")

#: ``quantize(raw [B, 2d]) -> (quantised [B, 2d] with straight-through gradient, codes [B], loss)``
Quantizer = Callable[[Tensor], tuple[Tensor, Tensor, Tensor]]


def relative_times(window: int, fps: float) -> Tensor:
    """Frame times relative to the pivot, ``t_i = (i - (T + 1) / 2) dt`` for ``i = 1..T``.

    Args:
        window: ``T``, odd.
        fps: Frame rate (``dt = 1 / fps``).

    Returns:
        ``[T]`` float32 times in seconds, 0 at the pivot ``T // 2``.

    Raises:
        SkelagnosticError: ``window`` is not a positive odd number or ``fps`` is not positive.

    Example:
        >>> [round(x, 3) for x in relative_times(5, 10.0).tolist()]
        [-0.2, -0.1, 0.0, 0.1, 0.2]
    """
    if window <= 0 or window % 2 == 0:
        raise SkelagnosticError(f"window must be a positive odd number of frames, got {window}")
    if not fps > 0:
        raise SkelagnosticError(f"fps must be positive, got {fps}")
    i = torch.arange(1, window + 1, dtype=torch.float64)
    return ((i - (window + 1) / 2) / fps).float()


def mason_phase(signal: Tensor, frequency: Tensor, times: Tensor) -> Tensor:
    r"""Phase of a 1-channel signal at the pivot (Mason 2022; supplement Eq. 1).

    With the signal centred (its temporal mean removed, as the authors' code
    does, so a constant offset does not bias the sums):
    $s_x = \sum_i y_i \cos(2\pi f t_i)$, $s_y = \sum_i y_i \sin(2\pi f t_i)$,
    $\phi = \operatorname{atan2}(-s_y, s_x) / 2\pi$. The minus sign (the
    authors' code has it; the supplement's formula drops it) makes
    $y = \cos(2\pi(f t + \phi_0))$ give $\phi = \phi_0$, so the pivot phase grows
    with time like the extrapolated phase $\Phi = \phi + f t$ the decoder sees.

    Args:
        signal: ``[..., T]`` the timing-branch signal ``y``.
        frequency: ``[...]`` frequency in Hz.
        times: ``[T]`` relative times in seconds (:func:`relative_times`).

    Returns:
        ``[...]`` phase in cycles, in ``(-1/2, 1/2]``.

    Example:
        >>> t = relative_times(61, 60.0)
        >>> y = torch.cos(2 * math.pi * (2.0 * t + 0.3))  # two whole cycles in the window
        >>> round(float(mason_phase(y, torch.tensor(2.0), t)), 2)
        0.3
    """
    y = signal - signal.mean(dim=-1, keepdim=True)
    angle = 2 * math.pi * frequency.unsqueeze(-1) * times.to(signal)
    sx = (y * torch.cos(angle)).sum(-1)
    sy = (y * torch.sin(angle)).sum(-1)
    return torch.atan2(-sy, sx) / (2 * math.pi)


def phase_advance_rate(phase: Tensor, later_phase: Tensor, shift: Tensor, fps: float) -> Tensor:
    """Rate (Hz) at which the pivot phase advances from one window to one ``shift`` frames on.

    The difference is wrapped to ``[-1/2, 1/2]`` cycles, so it is unambiguous while
    ``|f| * |shift| / fps < 1/2``.

    Args:
        phase: ``[B]`` pivot phase of the windows, in cycles.
        later_phase: ``[B]`` pivot phase of the partner windows.
        shift: ``[B]`` signed frames from a window's pivot to its partner's (non-zero).
        fps: Frame rate.

    Returns:
        ``[B]`` rate in Hz.

    Example:
        >>> rate = phase_advance_rate(torch.tensor([0.45, 0.45]), torch.tensor([-0.45, 0.35]),
        ...                           torch.tensor([2, -2]), 20.0)  # across the wrap; backwards
        >>> [round(r, 4) for r in rate.tolist()]
        [1.0, 1.0]
    """
    advance = later_phase - phase
    advance = advance - torch.round(advance)
    return advance * fps / shift.to(advance)


def phase_manifold(amplitude: Tensor, phase: Tensor) -> Tensor:
    r"""Points of the phase manifold, $\Psi(A, \phi) = A^0 \sin 2\pi\phi + A^1 \cos 2\pi\phi$.

    Eq. 1 of the paper.

    Args:
        amplitude: ``[..., 2d]``; ``A^0`` is the first half, ``A^1`` the second.
        phase: ``[..., T]`` phases in cycles (or ``[...]`` for a single point,
            then pass ``phase.unsqueeze(-1)``).

    Returns:
        ``[..., d, T]`` manifold points.

    Example:
        >>> a = torch.tensor([1.0, 0.0, 0.0, 2.0])  # d = 2
        >>> phase_manifold(a, torch.tensor([0.0, 0.25])).tolist()
        [[0.0, 1.0], [2.0, -8.742277657347586e-08]]
    """
    d = amplitude.shape[-1] // 2
    a0, a1 = amplitude[..., :d, None], amplitude[..., d:, None]
    angle = 2 * math.pi * phase.unsqueeze(-2)
    return a0 * torch.sin(angle) + a1 * torch.cos(angle)


class TemporalCentering(nn.Module):
    """Removes the temporal mean of every channel of ``[B, C, T]`` (the authors' ``LN_v3``)."""

    def forward(self, x: Tensor) -> Tensor:
        """``x - x.mean(-1)``."""
        return x - x.mean(dim=-1, keepdim=True)


def _mlp(sizes: list[int], slope: float = 0.2, hidden_elu: bool = False) -> nn.Sequential:
    """Linear layers with LeakyReLU between them (and ELU after it with ``hidden_elu``)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.LeakyReLU(slope))
            if hidden_elu:
                layers.append(nn.ELU())
    return nn.Sequential(*layers)


@dataclass
class PhaseParameters:
    """What :meth:`VQPAE.forward` returns besides the reconstruction.

    Attributes:
        phase: ``[B]`` pivot phase ``phi`` in cycles, ``(-1/2, 1/2]``.
        frequency: ``[B]`` frequency ``f`` in Hz.
        raw_amplitude: ``[B, 2d]`` the amplitude MLP's output ``A~``.
        amplitude: ``[B, 2d]`` the quantised amplitude ``A`` (straight-through gradient).
        code: ``[B]`` codebook index of ``A``.
        manifold: ``[B, d, T]`` ``P = Psi(A, phi + f t)``.
        signal: ``[B, T]`` the timing-branch signal ``y``.
        vq_loss: Scalar codebook + beta * commitment loss.
    """

    phase: Tensor
    frequency: Tensor
    raw_amplitude: Tensor
    amplitude: Tensor
    code: Tensor
    manifold: Tensor
    signal: Tensor
    vq_loss: Tensor


class VQPAE(nn.Module):
    """One dataset's vector-quantised periodic autoencoder (the codebook is shared, outside).

    Args:
        channels: ``C_in``, input channels per frame (joints x 3).
        window: ``T``, frames per window (odd; 1 s windows have ``fps + 1``).
        fps: Frame rate of the windows (``dt = 1 / fps``).
        latent: ``d``, latent channels (10 in the paper).
        kernel_size: Kernel of the encoder/decoder convolutions (23).
        intermediate: Channels between the two convolutions (default ``C_in // 3``).
        freq_layers: Layers of the frequency MLP (default 7, the authors' code; 5 in the paper).
        amp_layers: Layers of the amplitude MLP (5).
        decoder_centering: Also remove the temporal mean after the first decoder
            convolution (default ``True``, the authors' code; the paper only has ELU there).
        spectrum: Input of the frequency MLP. ``"power"`` (default): the raw powers
            of ``rfft(y) * 2 / T`` (the authors' code); the MLP is then driven by the
            signal's scale too, and on our data the frequency diverged to thousands
            of Hz within a few hundred steps (the decoder exploits aliased
            high-frequency sinusoids). ``"normalized"``: the power spectrum of the
            centred signal divided by its sum, so the frequency depends on the
            spectrum's shape only.
        padding_mode: Padding of the encoder and decoder convolutions ("same"
            length; default ``"zeros"``, the authors' code; the paper does not say).
            ``"zeros"`` (PyTorch's default) lets a kernel-23 convolution tell every
            frame's distance to the window edges, so the decoder can rebuild a
            window from its pivot manifold point without using the phase (a window
            constant in time comes out with edge-shaped profiles); on the
            procedural quadruped the timing branch then stopped learning (phase
            R^2 ~ 0). ``"replicate"`` maps a constant window to a constant output,
            so the temporal shape has to come from ``phi + f t``.
        frequency_head: How the frequency is read from the spectrum. ``"mlp"``
            (default, the paper, Fig. 3): ``f = ELU(MLP(power)) + 1``.
            ``"centroid_residual"``: the MLP (last layer zero-initialised) adds a
            correction to PAE's power-weighted mean frequency of the non-DC bins
            (Starke et al. 2022), ``f = ELU(centroid + MLP(power) - 1) + 1`` (equal
            to ``centroid + MLP(power)`` above 1 Hz). The paper's head starts at
            about 1 Hz for every window; trained by reconstruction only it can
            settle on a local optimum (the procedural gallop at half its rate) or,
            on a single quadruped, lose the phase. Starting from the centroid
            avoids both, but in our human + dog runs it slowed the sharing of
            codes between the characters (see docs/reports/vqpae.md), so it is
            not the default.
        phase_kernel: Kernel of the timing branch's ``Conv1d(d -> 1)`` (odd; default
            23, the authors' code, with "same" padding of ``padding_mode``; the
            paper's Fig. 3: 1).
        freq_hidden_elu: Apply ELU after the LeakyReLU of every hidden layer of the
            frequency MLP, as the authors' ``MLP(..., last_activation=True)`` does
            (default ``True``; ``False``: LeakyReLU only, the paper's description).

    Raises:
        SkelagnosticError: A size is not positive, ``window`` is even or ``kernel_size`` even.
    """

    def __init__(
        self,
        channels: int,
        window: int,
        fps: float,
        latent: int = 10,
        kernel_size: int = 23,
        intermediate: int | None = None,
        freq_layers: int = 7,
        amp_layers: int = 5,
        decoder_centering: bool = True,
        spectrum: str = "power",
        padding_mode: str = "zeros",
        frequency_head: str = "mlp",
        phase_kernel: int = 23,
        freq_hidden_elu: bool = True,
    ) -> None:
        super().__init__()
        if frequency_head not in FREQUENCY_HEADS:
            raise SkelagnosticError(
                f"VQPAE: frequency_head must be one of {FREQUENCY_HEADS}, got {frequency_head!r}"
            )
        self.frequency_head = frequency_head
        if padding_mode not in PADDING_MODES:
            raise SkelagnosticError(
                f"VQPAE: padding_mode must be one of {PADDING_MODES}, got {padding_mode!r}"
            )
        if spectrum not in ("normalized", "power"):
            raise SkelagnosticError(
                f"VQPAE: spectrum must be 'normalized' or 'power', got {spectrum!r}"
            )
        self.spectrum = spectrum
        for arg, value in (
            ("channels", channels),
            ("latent", latent),
            ("freq_layers", freq_layers),
            ("amp_layers", amp_layers),
        ):
            if value <= 0:
                raise SkelagnosticError(f"VQPAE: {arg} must be positive, got {value}")
        for arg, value in (("kernel_size", kernel_size), ("phase_kernel", phase_kernel)):
            if value <= 0 or value % 2 == 0:
                raise SkelagnosticError(f"VQPAE: {arg} must be positive and odd, got {value}")
        mid = intermediate if intermediate is not None else max(1, channels // 3)
        if mid <= 0:
            raise SkelagnosticError(f"VQPAE: intermediate must be positive, got {mid}")
        self.channels, self.window, self.fps, self.latent = channels, window, float(fps), latent
        self.register_buffer("times", relative_times(window, fps), persistent=False)

        def conv(c_in: int, c_out: int) -> nn.Conv1d:
            return nn.Conv1d(c_in, c_out, kernel_size, padding="same", padding_mode=padding_mode)

        self.encoder = nn.Sequential(
            conv(channels, mid),
            TemporalCentering(),
            nn.ELU(),
            conv(mid, latent),
            TemporalCentering(),
            nn.ELU(),
        )
        self.phase_conv = nn.Conv1d(
            latent, 1, phase_kernel, padding="same", padding_mode=padding_mode
        )
        bins = window // 2 + 1
        self.freq_mlp = _mlp([bins] * freq_layers + [1], hidden_elu=freq_hidden_elu)
        # frequency of every rfft bin (Hz): k / (T dt)
        self.register_buffer(
            "bin_hz", torch.arange(bins, dtype=torch.float32) * self.fps / window, persistent=False
        )
        if frequency_head == "centroid_residual":  # the untrained head is the centroid
            last = self.freq_mlp[-1]
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
        self.amp_mlp = _mlp([latent] + [2 * latent] * amp_layers)
        self.decoder = nn.Sequential(
            conv(latent, mid),
            *([TemporalCentering()] if decoder_centering else []),
            nn.ELU(),
            conv(mid, channels),
        )

    def timing(self, latent: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Timing branch: ``latent [B, d, T] -> (phase [B], frequency [B], signal [B, T])``.

        The frequency is ``ELU(MLP(power)) + 1`` (positive), with ``power`` the
        squared magnitudes of ``rfft(y) * 2 / T`` (``T // 2 + 1`` bins), of the
        centred ``y`` and summing to one with ``spectrum="normalized"``; with
        ``frequency_head="centroid_residual"`` the MLP's output is added to the
        spectral centroid first (:meth:`spectral_centroid`).
        """
        y = self.phase_conv(latent).squeeze(1)
        frequency = self.frequency_of(y)
        return mason_phase(y, frequency, self.times), frequency, y

    def frequency_of(self, y: Tensor) -> Tensor:
        """The frequency head alone: timing-branch signal ``y [B, T]`` -> ``f [B]`` in Hz."""
        if self.spectrum == "normalized":
            centred = y - y.mean(dim=-1, keepdim=True)
            power = torch.fft.rfft(centred, dim=-1).abs().square()
            power = power / power.sum(dim=-1, keepdim=True).clamp_min(1e-12)
        else:
            power = (torch.fft.rfft(y, dim=-1) * (2.0 / y.shape[-1])).abs().square()
        raw = self.freq_mlp(power).squeeze(-1)
        if self.frequency_head == "centroid_residual":
            raw = raw + self.spectral_centroid(power) - 1.0
        return nn.functional.elu(raw) + 1.0

    def spectral_centroid(self, power: Tensor) -> Tensor:
        r"""PAE's frequency: $\sum_{k \ge 1} f_k p_k / \sum_{k \ge 1} p_k$ over the non-DC bins.

        Args:
            power: ``[B, T // 2 + 1]`` powers of the rfft bins (any scale).

        Returns:
            ``[B]`` frequency in Hz (0 for a signal without power).
        """
        p = power[..., 1:]
        return (p * self.bin_hz[1:]).sum(-1) / p.sum(-1).clamp_min(1e-12)

    def _check(self, x: Tensor) -> None:
        if x.dim() != 3 or x.shape[1] != self.channels or x.shape[2] != self.window:
            raise SkelagnosticError(
                f"VQPAE: input must be [B, {self.channels}, {self.window}], got {list(x.shape)}"
            )

    def phase_and_frequency(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Encoder and timing branch only: ``x [B, C_in, T] -> (phase, frequency, signal)``."""
        self._check(x)
        return self.timing(self.encoder(x))

    def encode(self, x: Tensor, quantize: Quantizer) -> PhaseParameters:
        """Encoder, timing and amplitude branches and the manifold of ``x [B, C_in, T]``."""
        self._check(x)
        latent = self.encoder(x)
        phase, frequency, signal = self.timing(latent)
        raw = self.amp_mlp(latent.mean(dim=-1))
        amplitude, code, vq_loss = quantize(raw)
        big_phi = phase.unsqueeze(-1) + frequency.unsqueeze(-1) * self.times
        return PhaseParameters(
            phase,
            frequency,
            raw,
            amplitude,
            code,
            phase_manifold(amplitude, big_phi),
            signal,
            vq_loss,
        )

    def forward(self, x: Tensor, quantize: Quantizer) -> tuple[Tensor, PhaseParameters]:
        """Reconstruct ``x [B, C_in, T]``: ``(reconstruction [B, C_in, T], parameters)``."""
        params = self.encode(x, quantize)
        return self.decoder(params.manifold), params


class AveragePoseMLP(nn.Module):
    """Maps a manifold point to the average pose there (Sec. 5.2, Eq. 10).

    ``layers`` linear layers, hidden width = pose size, LeakyReLU 0.2 between
    (supplement 2.1: 8 layers).

    Args:
        latent: ``d``, size of a manifold point.
        pose: Size of the (normalised) pose vector.
        layers: Number of linear layers.
    """

    def __init__(self, latent: int, pose: int, layers: int = 8) -> None:
        super().__init__()
        if layers <= 0 or pose <= 0 or latent <= 0:
            raise SkelagnosticError(
                f"AveragePoseMLP: latent, pose and layers must be positive, got {latent}, {pose}, "
                f"{layers}"
            )
        self.net = _mlp([latent] + [pose] * layers)

    def forward(self, points: Tensor) -> Tensor:
        """``[..., d] -> [..., pose]``."""
        return self.net(points)


class Character(nn.Module):
    """One dataset's VQ-PAE, average-pose MLP and normalisation statistics."""

    def __init__(
        self, spec: Mapping[str, Any], latent: int, pose_layers: int, **pae_options: Any
    ) -> None:
        super().__init__()
        channels, window = int(spec["channels"]), int(spec["window"])
        pose = int(spec.get("pose_channels") or channels)  # an authors' phase decoder: more
        self.pae = VQPAE(channels, window, float(spec["fps"]), latent, **pae_options)
        self.pose = AveragePoseMLP(latent, pose, pose_layers)
        self.register_buffer("input_mean", torch.zeros(channels))
        self.register_buffer("input_std", torch.ones(channels))
        self.register_buffer("pose_mean", torch.zeros(pose))
        self.register_buffer("pose_std", torch.ones(pose))
        self.register_buffer("pose_fitted", torch.tensor(False))
