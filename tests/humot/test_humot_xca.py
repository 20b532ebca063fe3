"""The span of XCA's channel map (``model.xca``): per frame (default) or per chunk."""

from __future__ import annotations

import lightning as L
import pytest
import torch
from skelagnostic_humot import HumotAligner
from skelagnostic_humot.xcit import XCA, TokenLayout, XCiTBlock

import skelagnostic as sa
from skelagnostic.errors import SkelagnosticError

SMALL = {"dim": 16, "latent": 8, "blocks": 1, "heads": 2, "kernel_size": 3}


def test_a_frame_map_is_the_attention_over_that_frame_alone():
    torch.manual_seed(0)
    attn = XCA(16, 2, scope="frame")
    grid = torch.randn(2, 5, 7, 16)  # [B, G, F, C]
    out = attn.forward_grid(grid)
    for f in range(7):
        torch.testing.assert_close(out[:, :, f], attn(grid[:, :, f]), rtol=1e-5, atol=1e-6)


def test_a_sequence_map_is_the_attention_over_every_token_of_the_sample():
    torch.manual_seed(0)
    attn = XCA(16, 2, scope="sequence")
    grid = torch.randn(2, 5, 7, 16)
    expected = attn(grid.reshape(2, 35, 16)).reshape(2, 5, 7, 16)
    torch.testing.assert_close(attn.forward_grid(grid), expected)


@pytest.mark.parametrize("scope", ["frame", "sequence"])
def test_packed_tokens_give_the_padded_values(scope):
    torch.manual_seed(0)
    block = XCiTBlock(16, 2, mlp_ratio=2.0, layer_scale=1.0, xca_scope=scope).eval()
    grid = torch.randn(3, 6, 5, 16)
    mask = torch.arange(6)[None] < torch.tensor([[6], [4], [2]])
    grid = grid * mask[:, :, None, None]
    layout = TokenLayout.of(mask, 5)
    packed = layout.unpack(block.forward_packed(layout.pack(grid), layout))
    torch.testing.assert_close(packed, block(grid, mask), rtol=1e-5, atol=1e-5)


def test_a_frame_map_changes_the_other_frames_of_nothing():
    """With LPI off (zero layer scale), a change at frame 2 moves frame 2's outputs alone."""
    torch.manual_seed(0)
    block = XCiTBlock(16, 2, mlp_ratio=2.0, layer_scale=1.0, xca_scope="frame").eval()
    with torch.no_grad():
        block.gamma3.zero_()
    grid = torch.randn(1, 4, 6, 16)
    moved = grid.clone()
    moved[0, 1, 2] += 1.0
    diff = (block(moved) - block(grid)).abs().amax(dim=(0, 1, 3))
    assert diff[2] > 1e-3 and bool((diff[[0, 1, 3, 4, 5]] == 0).all())


def test_an_unknown_scope_is_refused_by_name():
    with pytest.raises(SkelagnosticError, match=r"model\.xca must be one of frame, sequence"):
        HumotAligner(**SMALL, xca="joint")


def test_a_checkpoint_from_before_the_option_loads_with_one_map_per_chunk(tmp_path):
    """Its weights were trained with the earlier reading: it must not switch silently."""
    torch.manual_seed(0)
    old = HumotAligner(**SMALL, xca="sequence")
    saved = {k: v for k, v in old.hparams.items() if k != "xca"}
    path = tmp_path / "old.ckpt"
    torch.save(
        {
            "state_dict": old.state_dict(),
            "hyper_parameters": saved,
            "pytorch-lightning_version": L.__version__,
        },
        path,
    )
    loaded = sa.load_aligner("humot", checkpoint=path)
    assert loaded.hparams.xca == "sequence"
    assert loaded.net.encoder.blocks[0].attn.scope == "sequence"
    assert sa.load_aligner("humot", checkpoint=path, xca="frame").hparams.xca == "frame"
