"""Weights files (``export format=safetensors``): checkpoint entries, and one-line errors.

The round trip of a trained run through ``skelagnostic export`` and ``ckpt=`` is in
``test_export.py``, beside the other formats.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from skelagnostic.aligners.checkpoints import (
    CheckpointError,
    CheckpointNotFoundError,
    load_checkpoint,
)
from skelagnostic.aligners.export import ExportError, export_aligner
from skelagnostic.aligners.weights import read_weights, weights_model

st = pytest.importorskip("safetensors.torch")


def test_checkpoint_entries_travel_in_the_metadata(
    tmp_path: Path, pcmrl_tiny: dict[str, int]
) -> None:
    # PC-MRL keeps its target skeleton in the checkpoint, outside the state_dict
    from skelagnostic_pcmrl.recon.aligner import PcmrlReconAligner

    torch.manual_seed(0)
    aligner = PcmrlReconAligner(**pcmrl_tiny, target="biped22").eval()
    (file,) = export_aligner(aligner, "safetensors", tmp_path, "pcmrl")
    assert read_weights(file)["pcmrl"]["target"]["parents"] == list(aligner.target_skeleton.parents)
    loaded = load_checkpoint(PcmrlReconAligner, tmp_path).eval()
    count = pcmrl_tiny["num_source_points"]
    points = torch.randn(2, 12, count, 3, generator=torch.Generator().manual_seed(2))
    groups = torch.randint(0, 5, (2, count), generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        want, got = aligner.reconstruct(points, groups, 1), loaded.reconstruct(points, groups, 1)
    for key in ("root", "rotations", "positions"):
        assert torch.equal(got[key], want[key]), key


def test_export_needs_the_model_name(example_plugin: Path, tmp_path: Path) -> None:
    from skelagnostic_example.aligner import ExampleAligner

    with pytest.raises(ExportError, match="registered name"):
        export_aligner(ExampleAligner(hidden=8, latent=4), "safetensors", tmp_path)


# ------------------------------------------------------------------------------ errors
@pytest.fixture
def exported(example_plugin: Path, tmp_path: Path) -> tuple[Path, dict[str, torch.Tensor], dict]:
    """A small exported example aligner: its file, tensors and metadata."""
    from skelagnostic_example.aligner import ExampleAligner

    (file,) = export_aligner(ExampleAligner(hidden=8, latent=4), "safetensors", tmp_path, "example")
    with st.safe_open(str(file), framework="pt") as handle:
        meta = handle.metadata()
    return file, st.load_file(str(file)), meta


def load_example(path: Path) -> object:
    from skelagnostic_example.aligner import ExampleAligner

    from skelagnostic.plugins import get_plugin_manager

    aligners = get_plugin_manager().aligner_classes()
    return load_checkpoint(ExampleAligner, path, option="ckpt", aligners=aligners)


def test_a_corrupt_file_names_the_file(exported: tuple) -> None:
    file, _, _ = exported
    file.write_bytes(file.read_bytes()[:40])  # truncated
    with pytest.raises(CheckpointError, match="truncated or corrupt") as info:
        load_example(file)
    assert str(file) in str(info.value) and str(info.value).startswith("ckpt: ")
    with pytest.raises(CheckpointNotFoundError, match="no weights file"):
        load_example(file.with_name("other.safetensors"))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"model_config": "{not json"}, "metadata field 'model_config' is not a JSON object"),
        ({"format": "other"}, "metadata field 'format' is 'other'"),
        ({"model": "humot"}, "metadata field 'model' is 'humot', this is model=example"),
        ({"checkpoint_entries": None}, "has no metadata field 'checkpoint_entries'"),
    ],
)
def test_a_bad_metadata_field_is_named(exported: tuple, change: dict, message: str) -> None:
    file, tensors, meta = exported
    meta = {k: v for k, v in {**meta, **change}.items() if v is not None}
    st.save_file(tensors, str(file), metadata=meta)
    with pytest.raises(CheckpointError, match=message) as info:
        load_example(file.parent)
    assert str(file) in str(info.value)


def test_a_tensor_of_another_shape_is_named(exported: tuple) -> None:
    file, tensors, meta = exported
    name = next(k for k, v in tensors.items() if v.dim() == 2)
    tensors[name] = torch.zeros(tensors[name].shape[0] + 1, tensors[name].shape[1])
    st.save_file(tensors, str(file), metadata=meta)
    with pytest.raises(CheckpointError, match=f"tensor '{name}' has shape") as info:
        load_example(file)
    assert str(file) in str(info.value)
    del tensors[name]
    st.save_file(tensors, str(file), metadata=meta)
    with pytest.raises(CheckpointError, match=f"tensor '{name}' is missing from the file"):
        load_example(file)


def test_the_model_name_comes_from_the_file(exported: tuple) -> None:
    file, _, _ = exported
    assert weights_model(file.parent) == "example"
