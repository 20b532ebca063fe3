"""The VQ-PAE network: shapes, Mason phase, manifold, straight-through gradient, determinism."""

from __future__ import annotations

import itertools
import math

import pytest
import torch
from skelagnostic_vqpae.codebook import SharedCodebook
from skelagnostic_vqpae.model import (
    VQPAE,
    AveragePoseMLP,
    TemporalCentering,
    mason_phase,
    phase_manifold,
    relative_times,
)

from skelagnostic.errors import SkelagnosticError


def _net(channels: int = 12, window: int = 21, latent: int = 4, seed: int = 0) -> VQPAE:
    torch.manual_seed(seed)
    return VQPAE(channels, window, fps=20.0, latent=latent, kernel_size=5)


class TestRelativeTimes:
    def test_pivot_is_zero_and_spacing_is_dt(self) -> None:
        t = relative_times(61, 60.0)
        assert t.shape == (61,)
        assert float(t[30]) == 0.0
        assert torch.allclose(t.diff(), torch.full((60,), 1 / 60))
        assert math.isclose(float(t[0]), -0.5, abs_tol=1e-6)

    @pytest.mark.parametrize("window", [0, 4, -3])
    def test_rejects_even_or_non_positive_window(self, window: int) -> None:
        with pytest.raises(SkelagnosticError, match="window"):
            relative_times(window, 30.0)


class TestMasonPhase:
    @pytest.mark.parametrize("phi0", [-0.45, -0.2, 0.0, 0.13, 0.37, 0.49])
    @pytest.mark.parametrize(
        ("freq", "tol"), [(1.0, 0.005), (2.0, 0.005), (1.7, 0.02), (3.1, 0.01), (0.8, 0.04)]
    )
    def test_recovers_known_phase_of_a_sinusoid(self, phi0: float, freq: float, tol: float) -> None:
        # exact for whole cycles in the window; a fractional cycle leaves a small bias
        t = relative_times(61, 60.0)
        y = 0.7 * torch.cos(2 * math.pi * (freq * t + phi0)) + 0.3  # offset must not matter
        phi = float(mason_phase(y, torch.tensor(freq), t))
        err = (phi - phi0 + 0.5) % 1.0 - 0.5
        assert abs(err) < tol, (phi, phi0)

    def test_phase_advances_with_the_pivot(self) -> None:
        freq, fps = 2.0, 60.0
        t = relative_times(61, fps)
        phases = [
            float(mason_phase(torch.sin(2 * math.pi * freq * (t + k / fps)), torch.tensor(freq), t))
            for k in range(5)
        ]
        steps = [((b - a + 0.5) % 1.0) - 0.5 for a, b in itertools.pairwise(phases)]
        assert all(math.isclose(s, freq / fps, abs_tol=2e-3) for s in steps)

    def test_batched_shapes(self) -> None:
        t = relative_times(9, 10.0)
        assert mason_phase(torch.randn(3, 4, 9), torch.rand(3, 4) + 0.5, t).shape == (3, 4)


class TestManifold:
    def test_matches_equation_one(self) -> None:
        amp = torch.randn(2, 6)
        phase = torch.rand(2, 5)
        got = phase_manifold(amp, phase)
        assert got.shape == (2, 3, 5)
        want = amp[:, :3, None] * torch.sin(2 * math.pi * phase[:, None]) + amp[
            :, 3:, None
        ] * torch.cos(2 * math.pi * phase[:, None])
        assert torch.allclose(got, want)

    def test_is_periodic_in_phase(self) -> None:
        amp = torch.randn(6)
        phase = torch.rand(7)
        assert torch.allclose(
            phase_manifold(amp, phase), phase_manifold(amp, phase + 1.0), atol=1e-5
        )


class TestVQPAE:
    def test_shapes(self) -> None:
        net = _net()
        book = SharedCodebook(8, 8, 1)
        rec, p = net(torch.randn(5, 12, 21), book.quantizer(0))
        assert rec.shape == (5, 12, 21)
        assert p.manifold.shape == (5, 4, 21)
        assert p.phase.shape == p.frequency.shape == p.code.shape == (5,)
        assert p.raw_amplitude.shape == p.amplitude.shape == (5, 8)
        assert p.signal.shape == (5, 21)
        assert bool((p.frequency > 0).all())
        assert bool((p.phase > -0.5).all() and (p.phase <= 0.5).all())

    def test_layer_layout_follows_the_paper(self) -> None:
        net = VQPAE(66, 61, 60.0, freq_layers=5, phase_kernel=1)  # the paper's (not the defaults)
        convs = [m for m in net.encoder if isinstance(m, torch.nn.Conv1d)]
        assert [(c.in_channels, c.out_channels, c.kernel_size[0]) for c in convs] == [
            (66, 22, 23),
            (22, 10, 23),
        ]
        assert net.phase_conv.kernel_size == (1,) and net.phase_conv.out_channels == 1
        freq = [m for m in net.freq_mlp if isinstance(m, torch.nn.Linear)]
        assert len(freq) == 5 and freq[0].in_features == 31 and freq[-1].out_features == 1
        amp = [m for m in net.amp_mlp if isinstance(m, torch.nn.Linear)]
        assert len(amp) == 5 and amp[0].in_features == 10 and amp[-1].out_features == 20
        dec = [m for m in net.decoder if isinstance(m, torch.nn.Conv1d)]
        assert [(c.in_channels, c.out_channels) for c in dec] == [(10, 22), (22, 66)]

    def test_encoder_removes_the_temporal_mean(self) -> None:
        net = _net()
        latent = net.encoder[:2](torch.randn(3, 12, 21))
        assert torch.allclose(latent.mean(-1), torch.zeros(3, 4), atol=1e-6)

    def test_straight_through_gradient_reaches_the_encoder(self) -> None:
        net = _net()
        book = SharedCodebook(8, 8, 1)
        x = torch.randn(4, 12, 21)
        rec, p = net(x, book.quantizer(0))
        assert torch.allclose(p.amplitude.detach(), book.weight.detach()[p.code], atol=1e-7)
        p.amplitude.sum().backward(retain_graph=True)
        # d(sum A)/d(A~) is exactly one through the straight-through estimator
        grads = torch.autograd.grad(p.amplitude.sum(), p.raw_amplitude, retain_graph=True)[0]
        assert torch.equal(grads, torch.ones_like(grads))
        net.zero_grad()
        torch.nn.functional.mse_loss(rec, x).backward()
        assert net.amp_mlp[0].weight.grad is not None
        assert float(net.amp_mlp[0].weight.grad.abs().sum()) > 0
        assert float(net.encoder[0].weight.grad.abs().sum()) > 0

    def test_vq_loss_trains_the_codebook_and_commits_the_encoder(self) -> None:
        book = SharedCodebook(4, 2, 1, beta=0.25)
        raw = torch.randn(6, 2, requires_grad=True)
        _, codes, loss = book.quantize(raw)
        loss.backward()
        diff = book.weight.detach()[codes] - raw.detach()
        want = (2 * 0.25 / diff.numel()) * (-diff)
        assert torch.allclose(raw.grad, want, atol=1e-6)
        assert book.weight.grad is not None

    def test_deterministic(self) -> None:
        x = torch.randn(3, 12, 21)
        outs = []
        for _ in range(2):
            torch.manual_seed(1)
            net, book = _net(seed=1), SharedCodebook(8, 8, 1, seed=3)
            net.eval()
            outs.append(net(x, book.quantizer(0)))
        assert torch.equal(outs[0][0], outs[1][0])
        assert torch.equal(outs[0][1].phase, outs[1][1].phase)
        assert torch.equal(outs[0][1].code, outs[1][1].code)

    def test_rejects_wrong_input_shape(self) -> None:
        net = _net()
        with pytest.raises(SkelagnosticError, match=r"\[B, 12, 21\]"):
            net(torch.randn(2, 12, 20), SharedCodebook(8, 8, 1).quantizer(0))

    @pytest.mark.parametrize("kwargs", [{"kernel_size": 4}, {"latent": 0}, {"channels": -1}])
    def test_rejects_bad_sizes(self, kwargs: dict[str, int]) -> None:
        args = {"channels": 12, "window": 21, "fps": 20.0, **kwargs}
        with pytest.raises(SkelagnosticError, match=next(iter(kwargs))):
            VQPAE(**args)


def test_average_pose_mlp_has_eight_layers() -> None:
    mlp = AveragePoseMLP(10, 63)
    linears = [m for m in mlp.net if isinstance(m, torch.nn.Linear)]
    assert len(linears) == 8
    assert all(
        isinstance(m, torch.nn.LeakyReLU) and m.negative_slope == 0.2
        for m in mlp.net
        if not isinstance(m, torch.nn.Linear)
    )
    assert mlp(torch.randn(5, 7, 10)).shape == (5, 7, 63)


class TestFrequencyHead:
    """``frequency_head``: the paper's MLP, or an MLP correcting PAE's spectral centroid."""

    @staticmethod
    def _latent_for(net: VQPAE, y: torch.Tensor) -> torch.Tensor:
        # a latent whose timing signal is exactly ``y``: channel 0 carries it, the conv reads it
        with torch.no_grad():
            net.phase_conv.weight.zero_()
            net.phase_conv.weight[0, 0, net.phase_conv.kernel_size[0] // 2] = 1.0  # centre tap
            net.phase_conv.bias.zero_()
        latent = torch.zeros(len(y), net.latent, net.window)
        latent[:, 0] = y
        return latent

    def test_centroid_matches_a_numpy_reference(self) -> None:
        import numpy as np

        net = VQPAE(9, 61, 60.0, latent=4, kernel_size=5, frequency_head="centroid_residual")
        power = torch.rand(3, 31, dtype=torch.float64).float()
        hz = np.fft.rfftfreq(61, d=1 / 60.0)  # independent bin frequencies
        p = power.double().numpy()[:, 1:]
        want = (p * hz[1:]).sum(1) / p.sum(1)
        assert np.allclose(net.spectral_centroid(power).double().numpy(), want, rtol=1e-5)

    @pytest.mark.parametrize("cycles", [2, 3, 5])
    def test_untrained_head_reads_an_on_bin_sinusoid_exactly(self, cycles: int) -> None:
        # a whole number of cycles in the window puts all power in one bin: centroid = its Hz
        net = VQPAE(9, 61, 60.0, latent=4, kernel_size=5, frequency_head="centroid_residual")
        t = torch.arange(61) / 60.0
        freq = cycles * 60.0 / 61
        y = torch.stack([torch.cos(2 * math.pi * (freq * t + phi)) for phi in (0.0, 0.3)])
        _, f, _ = net.timing(self._latent_for(net, y))
        assert torch.allclose(f, torch.full((2,), freq), rtol=1e-4)

    def test_paper_head_starts_near_one_hertz_whatever_the_signal(self) -> None:
        torch.manual_seed(0)
        net = VQPAE(9, 61, 60.0, latent=4, kernel_size=5, frequency_head="mlp")
        t = torch.arange(61) / 60.0
        y = torch.stack([torch.cos(2 * math.pi * c * 60.0 / 61 * t) for c in (2, 5)])
        _, f, _ = net.timing(self._latent_for(net, y))
        # an untrained MLP barely tells 2 Hz from 5 Hz: the reason for the residual head
        assert float((f[1] - f[0]).abs()) < 0.5

    def test_residual_is_trainable_and_frequency_stays_positive(self) -> None:
        net = VQPAE(9, 61, 60.0, latent=4, kernel_size=5, frequency_head="centroid_residual")
        y = torch.randn(4, 61)
        _, f, _ = net.timing(self._latent_for(net, y))
        f.sum().backward()
        assert float(net.freq_mlp[-1].weight.grad.abs().sum()) > 0
        centroid = f.detach()
        with torch.no_grad():
            net.freq_mlp[-1].bias.fill_(-8.0)  # a correction far below the centroid
        _, f, _ = net.timing(self._latent_for(net, y))
        assert bool((f > 0).all()) and bool((f < centroid).all())

    def test_rejects_unknown_head(self) -> None:
        with pytest.raises(SkelagnosticError, match="frequency_head"):
            VQPAE(9, 61, 60.0, frequency_head="peak")


class TestAuthorsOptions:
    """``phase_kernel`` and ``freq_hidden_elu``: the authors' timing branch by default."""

    def test_defaults_are_the_authors_network(self) -> None:
        net = VQPAE(9, 61, 60.0)
        assert net.phase_conv.kernel_size == (23,) and net.phase_conv.padding_mode == "zeros"
        assert net.encoder[0].padding_mode == "zeros" and net.spectrum == "power"
        kinds = [type(m).__name__ for m in net.freq_mlp]
        assert kinds == ["Linear", "LeakyReLU", "ELU"] * 6 + ["Linear"]  # n_layers_fft 7
        assert any(isinstance(m, TemporalCentering) for m in net.decoder)

    def test_paper_options_keep_the_kernel_1_conv_and_leaky_relu_mlp(self) -> None:
        net = VQPAE(9, 61, 60.0, phase_kernel=1, freq_hidden_elu=False)
        assert net.phase_conv.kernel_size == (1,)
        assert not any(isinstance(m, torch.nn.ELU) for m in net.freq_mlp)

    def test_authors_timing_branch(self) -> None:
        torch.manual_seed(0)
        net = VQPAE(
            12,
            21,
            20.0,
            latent=4,
            kernel_size=5,
            freq_layers=3,
            phase_kernel=5,
            freq_hidden_elu=True,
            padding_mode="zeros",
        )
        assert net.phase_conv.kernel_size == (5,) and net.phase_conv.padding_mode == "zeros"
        kinds = [type(m).__name__ for m in net.freq_mlp]
        assert kinds == ["Linear", "LeakyReLU", "ELU"] * 2 + ["Linear"]
        phase, frequency, signal = net.phase_and_frequency(torch.randn(3, 12, 21))
        assert phase.shape == frequency.shape == (3,) and signal.shape == (3, 21)

    def test_rejects_even_phase_kernel(self) -> None:
        with pytest.raises(SkelagnosticError, match="phase_kernel must be positive and odd"):
            VQPAE(9, 61, 60.0, phase_kernel=4)
