"""Receptive field of HuMoT's encoder (issue #45, item 5): the latent at frame f sees frame f."""

from __future__ import annotations

import math

import pytest
import torch
from omegaconf import OmegaConf
from skelagnostic_humot import HumotAligner, receptive_field
from skelagnostic_humot.data import Topology, prepare_chunks
from skelagnostic_humot.template import major_joints
from torch import nn

import skelagnostic as sa
from skelagnostic.cli.app import compose
from skelagnostic.errors import SkelagnosticError


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def skeleton() -> sa.Skeleton:
    """The 22-joint procedural human (LaFAN1's joint set)."""
    return sa.procedural.skeleton("biped22")


class _Mix(nn.Module):
    """``z[f] = W (near * x[f] + far * sum_g x[g])`` per joint group: known Jacobians.

    ``d z[f] / d x[f, j] = (near_j + far_j) W_j`` and ``d z[f] / d x[g, j] = far_j W_j``
    for ``g != f``, so the ratio of joint ``j`` is ``(near_j + far_j) / far_j`` whatever
    ``W`` is.
    """

    def __init__(self, near: torch.Tensor, far: torch.Tensor, latent: int = 5) -> None:
        super().__init__()
        gen = torch.Generator().manual_seed(3)
        self.near, self.far = near, far
        self.weight = nn.Parameter(torch.randn(latent, len(near) * 3, generator=gen))

    def forward(self, motion: torch.Tensor, template: torch.Tensor) -> torch.Tensor:
        del template
        near, far = self.near[:, None], self.far[:, None]
        mixed = near * motion + far * motion.sum(dim=1, keepdim=True)  # [B, F, J, 3]
        return mixed.flatten(2) @ self.weight.T


def test_ratios_of_hand_built_networks_are_the_known_ones(skeleton):
    num = skeleton.num_joints
    ones = torch.ones(num)
    # a temporal sum: every frame counts the same, ratio 1, every major joint fails
    flat = receptive_field(_Mix(torch.zeros(num), ones), skeleton)
    assert all(r == pytest.approx(1.0, rel=1e-9) for r in flat.ratios.values())
    assert flat.failing() == list(flat.major) and not flat.passed
    # a per-frame linear map: far frames have no influence at all
    local = receptive_field(_Mix(ones, torch.zeros(num)), skeleton)
    assert all(math.isinf(r) for r in local.ratios.values()) and local.passed
    # per joint: joint j gets near j, far 1, ratio j + 1
    near = torch.arange(num, dtype=torch.float32)
    graded = receptive_field(_Mix(near, ones), skeleton, frames=20, frame=4, distance=3)
    for j, name in enumerate(skeleton.joint_names):
        assert graded.ratios[name] == pytest.approx(j + 1.0, rel=1e-6)
    expected = [n for n in graded.major if skeleton.joint_names.index(n) + 1 <= 5]
    assert graded.failing() == expected and expected


def test_major_joints_are_humot_major_joints(skeleton):
    rf = receptive_field(_Mix(torch.ones(skeleton.num_joints), torch.zeros(22)), skeleton)
    names = [skeleton.joint_names[j] for j in sorted(major_joints(skeleton).values())]
    assert list(rf.major) == names and len(names) == 12
    assert list(rf.ratios) == list(skeleton.joint_names)
    chosen = receptive_field(_Mix(torch.ones(22), torch.zeros(22)), skeleton, major=[0, 21])
    assert chosen.major == ("Hips", "RightHand")


def test_humot_ratios_match_an_independent_jacobian(skeleton):
    """On a small HuMoT encoder, the full Jacobian by torch.autograd.functional gives the ratios."""
    torch.manual_seed(0)
    net = HumotAligner(dim=16, latent=8, blocks=1, heads=2, kernel_size=3).net
    net.train()
    frames, frame = 16, 7
    gen = torch.Generator().manual_seed(1)
    world = skeleton.template() / 100 + 0.03 * torch.randn(frames, 22, 3, generator=gen)
    rf = receptive_field(net, skeleton, frames=frames, frame=frame, positions=world)
    assert net.training and all(m.training for m in net.modules())  # the mode is restored

    pos, tmpl = prepare_chunks(world[None].float(), Topology.of(skeleton), skeleton.up_axis)
    net.eval()
    jac = torch.autograd.functional.jacobian(lambda x: net.encoder(x, tmpl)[0, frame], pos)
    norms = jac[:, 0].pow(2).sum(dim=(0, -1)).sqrt()  # [Z, F, J, 3] -> [F, J]
    far = [g for g in range(frames) if abs(g - frame) > 5]
    expected = norms[frame] / norms[far].mean(0)
    got = torch.tensor([rf.ratios[n] for n in skeleton.joint_names], dtype=expected.dtype)
    torch.testing.assert_close(got, expected, rtol=1e-4, atol=0)


def test_an_aligner_is_measured_through_its_encoder(skeleton):
    torch.manual_seed(0)
    aligner = HumotAligner(dim=16, latent=8, blocks=1, heads=2, kernel_size=3)
    direct = receptive_field(aligner.net.encoder, skeleton, frames=14)
    assert receptive_field(aligner, skeleton, frames=14).ratios == direct.ratios


def test_bad_arguments_are_refused(skeleton):
    net = _Mix(torch.ones(22), torch.ones(22))
    with pytest.raises(SkelagnosticError, match="more than 5 frames away"):
        receptive_field(net, skeleton, frames=10)
    with pytest.raises(SkelagnosticError, match=r"frame 30 is not in 0\.\.29"):
        receptive_field(net, skeleton, frame=30)
    with pytest.raises(SkelagnosticError, match="positions must have shape"):
        receptive_field(net, skeleton, positions=torch.zeros(20, 22, 3))
    with pytest.raises(SkelagnosticError, match="no callable encoder"):
        receptive_field(object(), skeleton)


_PRESETS = [
    pytest.param([], id="default", marks=pytest.mark.slow),
    *(pytest.param([f"experiment={e}"], id=e) for e in ("humot_cpu2h", "humot_quick", "humot_cmu")),
]


@pytest.mark.parametrize("overrides", _PRESETS)
def test_every_major_joint_reaches_the_latent_of_its_frame(overrides, humot_pm, tmp_path, skeleton):
    """At initialisation (seed 0), 30 frames of the 22-joint human: every ratio > 5."""
    cfg = compose(["model=humot", *overrides, f"run_dir={tmp_path}"], plugin_manager=humot_pm)
    config = OmegaConf.to_container(cfg.model, resolve=True)
    kwargs = {k: v for k, v in config.items() if k not in ("name", "_target_")}  # as `fit`
    torch.manual_seed(0)
    aligner = HumotAligner(**kwargs)
    rf = receptive_field(aligner, skeleton, frames=cfg.model.chunk)
    assert rf.passed, {name: round(rf.ratios[name], 2) for name in rf.major}


def test_a_map_over_the_whole_chunk_does_not_reach_the_latent(skeleton):
    """``xca=sequence`` (one XCA map over all frames): most joints miss their frame's latent."""
    torch.manual_seed(0)
    aligner = HumotAligner(dim=64, latent=64, blocks=1, heads=8, kernel_size=3, xca="sequence")
    rf = receptive_field(aligner, skeleton, frames=30)
    failing = [name for name in rf.major if rf.ratios[name] <= 5]
    assert len(failing) >= 9, {name: round(rf.ratios[name], 2) for name in rf.major}
