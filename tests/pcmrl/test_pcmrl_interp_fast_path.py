"""PC-MRL stage 2: the keyframe-only encoder (``fast_path``) computes the reference network.

``CITLInterpolator(fast_path=True)`` runs the encoder on each window's keyframe
tokens only; these tests compare its outputs and the gradients of every
parameter and input with the reference path (``fast_path=False``) on the same
weights, in float64 (rtol 1e-10) and in float32 (1e-5).
"""

from __future__ import annotations

import pytest
import torch
from skelagnostic_pcmrl.interp.aligner import PcmrlInterpAligner
from skelagnostic_pcmrl.interp.network import CITLInterpolator

from skelagnostic import procedural

IN, OUT, INTERM, FRAMES = 11, 7, 5, 24


def _keys() -> torch.Tensor:
    """Four windows with 1, 3, 7 and 24 keyframes (frame 0 always a key)."""
    keys = torch.zeros(4, FRAMES, dtype=torch.bool)
    keys[:, 0] = True
    keys[1, [9, 23]] = True
    keys[2, [2, 3, 8, 15, 16, 20]] = True
    keys[3] = True
    return keys


def _networks(
    interm: int, dtype: torch.dtype, layout: str = "skelagnostic"
) -> tuple[CITLInterpolator, CITLInterpolator]:
    """A fast and a reference network with the same random weights (relative tables too)."""
    torch.manual_seed(0)
    kwargs = {"max_relative": 6, "interm_features": interm, "layout": layout}
    fast = CITLInterpolator(IN, OUT, 16, 4, 2, 2, fast_path=True, **kwargs)
    with torch.no_grad():
        for name, param in fast.named_parameters():
            if name.endswith(("rel_k", "rel_v")):  # zero-initialised: make them matter
                param.normal_()
    ref = CITLInterpolator(IN, OUT, 16, 4, 2, 2, fast_path=False, **kwargs)
    ref.load_state_dict(fast.state_dict())
    return fast.to(dtype), ref.to(dtype)


def _run(
    net: CITLInterpolator, inputs: torch.Tensor, keys: torch.Tensor, interm: torch.Tensor | None
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Output and the gradients of a fixed random projection of it."""
    net.zero_grad()
    x = inputs.clone().requires_grad_(True)
    y = None if interm is None else interm.clone().requires_grad_(True)
    out = net(x, keys, y)
    weight = torch.randn(out.shape, generator=torch.Generator().manual_seed(1)).to(out.dtype)
    (out * weight).sum().backward()
    grads = {n: p.grad.clone() for n, p in net.named_parameters() if p.grad is not None}
    grads["inputs"] = x.grad.clone()
    if y is not None:
        grads["interm_inputs"] = y.grad.clone()
    return out.detach(), grads


def _compare(interm: int, dtype: torch.dtype, rtol: float, atol: float) -> None:
    fast, ref = _networks(interm, dtype)
    keys = _keys()
    inputs = torch.randn(4, FRAMES, IN, dtype=dtype)
    interm_inputs = torch.randn(4, FRAMES, interm, dtype=dtype) if interm else None
    out_fast, grads_fast = _run(fast, inputs, keys, interm_inputs)
    out_ref, grads_ref = _run(ref, inputs, keys, interm_inputs)
    torch.testing.assert_close(out_fast, out_ref, rtol=rtol, atol=atol)
    assert grads_fast.keys() == grads_ref.keys()
    for name, grad in grads_ref.items():
        # a weight's gradient sums over every window and frame, in another order on each
        # path (and on each CPU's kernels): its rounding scales with the largest entry,
        # so the absolute tolerance is relative to it (float64 holds both to 1e-10)
        scale = max(1.0, float(grad.abs().max()))
        torch.testing.assert_close(
            grads_fast[name], grad, rtol=rtol, atol=atol * scale, msg=lambda m, n=name: f"{n}: {m}"
        )


@pytest.mark.parametrize("interm", [0, INTERM], ids=["zero-tokens", "lerp-tokens"])
def test_fast_path_equals_reference_float64(interm: int) -> None:
    _compare(interm, torch.float64, rtol=1e-10, atol=1e-12)


def test_fast_path_equals_reference_float32() -> None:
    _compare(INTERM, torch.float32, rtol=1e-5, atol=1e-5)


def test_fast_path_encodes_only_the_keyframe_tokens() -> None:
    fast, ref = _networks(0, torch.float32)
    keys = _keys()[:3]  # largest keyframe count 7
    seen: dict[str, tuple[int, ...]] = {}
    for name, net in (("fast", fast), ("ref", ref)):
        hook = net.encoder[0].register_forward_hook(
            lambda m, args, out, name=name: seen.__setitem__(name, tuple(out.shape))
        )
        net(torch.randn(3, FRAMES, IN), keys)
        hook.remove()
    assert seen == {"fast": (3, 7, 16), "ref": (3, FRAMES, 16)}


def test_authors_layout_takes_the_reference_path() -> None:
    fast, ref = _networks(0, torch.float64, layout="authors")
    seen: list[int] = []
    fast.encoder[0].register_forward_hook(lambda m, args, out: seen.append(out.shape[1]))
    keys, inputs = _keys(), torch.randn(4, FRAMES, IN, dtype=torch.float64)
    torch.testing.assert_close(fast(inputs, keys), ref(inputs, keys), rtol=0, atol=0)
    assert seen == [FRAMES]


def test_aligner_option_reaches_the_network_and_keeps_the_parameters() -> None:
    skeleton = procedural.skeleton("biped31").to_dict()
    fast = PcmrlInterpAligner(dim=16, heads=2, layers=1, skeleton=skeleton)
    ref = PcmrlInterpAligner(dim=16, heads=2, layers=1, skeleton=skeleton, fast_path=False)
    assert fast.net is not None and ref.net is not None
    assert (fast.net.fast_path, ref.net.fast_path) == (True, False)
    assert fast.hparams.fast_path is True
    # checkpoints of either load into the other: same parameter names and shapes
    ref.load_state_dict(fast.state_dict())
