"""The packed (fast-path) HuMoT network against the padded one and a per-sample loop.

Both paths share the weights; on batches of mixed joint counts, as stochastic
joint subsampling makes them, the outputs, every parameter's gradient, the
input gradients and the batch-norm running statistics must agree: within
1e-10 in float64 (the two paths compute the same function; only the order of
float sums differs) and 1e-4 in float32 (relative to the largest value; sums
over tens of thousands of tokens round differently). In eval mode, the batch
must also equal a slow loop that runs every sample alone, without padding.
"""

from __future__ import annotations

import pytest
import torch
from skelagnostic_humot.aligner import HumotAligner
from skelagnostic_humot.data import Topology, gather_subset, sample_keep
from skelagnostic_humot.model import HuMoT
from skelagnostic_humot.xcit import TokenLayout

import skelagnostic as sa

TOPOLOGIES = ["biped17", "biped22", "biped31"]


#: Relative tolerance per dtype.
TOLERANCE = {torch.float64: 1e-10, torch.float32: 1e-4}


def _twins(small: dict[str, int], dtype: torch.dtype = torch.float32) -> tuple[HuMoT, HuMoT]:
    torch.manual_seed(0)
    fast = HumotAligner(**small, fast_path=True).net.to(dtype)
    slow = HumotAligner(**small, fast_path=False).net.to(dtype)
    slow.load_state_dict(fast.state_dict())
    return fast, slow


def _subsets(kind: str, batch: int, seed: int):
    skeleton = sa.procedural.generate(kind, "walk", seconds=0.1)[0].skeleton
    topology = Topology.of(skeleton)
    gen = torch.Generator().manual_seed(seed)
    s1 = gather_subset(sample_keep(topology.major, batch, generator=gen), skeleton.parents)
    s2 = gather_subset(sample_keep(topology.major, batch, generator=gen), skeleton.parents)
    return skeleton.num_joints, s1, s2


def _run(net: HuMoT, motion, t_src, t_dst, m_src, m_dst, seed):
    net.zero_grad()
    motion = motion.detach().clone().requires_grad_()
    t_dst = t_dst.detach().clone().requires_grad_()
    out = net(motion, t_src, t_dst, m_src, m_dst)
    (out * seed).sum().backward()
    grads = {n: p.grad.clone() for n, p in net.named_parameters()}
    stats = {n: b.clone() for n, b in net.named_buffers()}
    return out.detach(), motion.grad, t_dst.grad, grads, stats


def _close(a: torch.Tensor, b: torch.Tensor, what: str, tol: float) -> None:
    a, b = a.detach(), b.detach()
    scale = float(b.abs().max().clamp_min(1e-8))
    err = float((a - b).abs().max()) / scale
    assert err < tol, f"{what}: relative difference {err:.2e}"


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("kind", TOPOLOGIES)
def test_fast_path_equals_padded_values_gradients_and_statistics(kind, dtype, humot_small):
    fast, slow = _twins(humot_small, dtype)
    j, s1, s2 = _subsets(kind, batch=6, seed=TOPOLOGIES.index(kind))
    assert not bool(s1.mask.all()) and not bool(s2.mask.all())  # the batch really is padded
    torch.manual_seed(1)
    pos, tmpl = torch.randn(6, 12, j, 3, dtype=dtype), torch.randn(6, j, 3, dtype=dtype)
    args = (s1.take(pos, 2), s1.take(tmpl, 1), s2.take(tmpl, 1), s1.mask, s2.mask)
    seed = torch.randn(6, 12, s2.mask.shape[1], 3, dtype=dtype)
    ours = _run(fast.train(), *args, seed)
    ref = _run(slow.train(), *args, seed)
    tol = TOLERANCE[dtype]
    for name, a, b in zip(
        ["output", "motion grad", "template grad"], ours[:3], ref[:3], strict=True
    ):
        _close(a, b, name, tol)
    assert ours[0][~s2.mask[:, None, :].expand(6, 12, -1)].abs().max() == 0  # padding: zero
    for name in ref[3]:
        _close(ours[3][name], ref[3][name], f"grad of {name}", tol)
    for name in ref[4]:
        _close(ours[4][name].double(), ref[4][name].double(), f"buffer {name}", tol)


def test_fast_path_batch_equals_a_loop_over_samples(humot_small):
    fast, _ = _twins(humot_small, torch.float64)
    fast.eval()
    j, s1, s2 = _subsets("biped31", batch=5, seed=7)
    torch.manual_seed(2)
    pos = torch.randn(5, 10, j, 3, dtype=torch.float64)
    tmpl = torch.randn(5, j, 3, dtype=torch.float64)
    batch = fast(s1.take(pos, 2), s1.take(tmpl, 1), s2.take(tmpl, 1), s1.mask, s2.mask)
    for i in range(5):
        src, dst = s1.index[i, s1.mask[i]], s2.index[i, s2.mask[i]]
        alone = fast(pos[i : i + 1, :, src], tmpl[i : i + 1, src], tmpl[i : i + 1, dst])
        n = len(dst)
        _close(batch[i : i + 1, :, :n], alone, f"sample {i}", 1e-10)


def test_fast_path_without_mask_equals_padded(humot_small):
    fast, slow = _twins(humot_small, torch.float64)
    torch.manual_seed(3)
    pos, tmpl, t_dst, seed = (
        torch.randn(*shape, dtype=torch.float64)
        for shape in ((3, 8, 9, 3), (3, 9, 3), (3, 7, 3), (3, 8, 7, 3))
    )
    ours = _run(fast.train(), pos, tmpl, t_dst, None, None, seed)
    ref = _run(slow.train(), pos, tmpl, t_dst, None, None, seed)
    for a, b in zip(ours[:3], ref[:3], strict=True):
        _close(a, b, "unmasked", 1e-10)


def test_token_layout_packs_and_unpacks():
    mask = torch.tensor([[True, True, False], [True, False, False]])
    layout = TokenLayout.of(mask, frames=2)
    grid = torch.arange(2 * 3 * 2 * 1, dtype=torch.float32).reshape(2, 3, 2, 1)
    packed = layout.pack(grid)
    assert packed.flatten().tolist() == [0.0, 1.0, 2.0, 3.0, 6.0, 7.0]
    back = layout.unpack(packed)
    assert torch.equal(back, grid * mask[:, :, None, None])
    assert layout.frame_rows().tolist() == [0, 1, 0, 1, 2, 3]
    full = TokenLayout.of(torch.ones(2, 3, dtype=torch.bool), frames=2)
    assert full.index is None and torch.equal(full.pack(grid).reshape(grid.shape), grid)
    with pytest.raises(ValueError, match="batch and rows"):
        TokenLayout.of(None, frames=2)
