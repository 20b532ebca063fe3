"""VQ-PAE's networks as export graphs (ONNX / TorchScript): per character, encoder and decoder.

:func:`export_graphs` is :meth:`VqpaeModel.export_graphs
<skelagnostic_vqpae.training.VqpaeModel.export_graphs>`; ``skelagnostic export`` calls it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor, nn

from skelagnostic.aligners.export import ExportGraph, Method
from skelagnostic_vqpae.codebook import SharedCodebook
from skelagnostic_vqpae.model import VQPAE, phase_manifold

if TYPE_CHECKING:
    from skelagnostic_vqpae.training import VqpaeModel

__all__ = ["export_graphs"]


class _PivotEncoder(nn.Module):
    """One character's VQ-PAE encoder as a graph: normalised windows -> pivot embedding.

    The same computation as :meth:`VqpaeModel.forward_dataset` up to the
    manifold point at the pivot, where ``Phi = phi + f * 0 = phi``.
    """

    def __init__(self, pae: VQPAE, codebook: SharedCodebook) -> None:
        super().__init__()
        self.pae = pae
        self.register_buffer("codebook", codebook.weight.detach().clone())

    def forward(self, windows: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        """``[B, C, T]`` -> phase ``[B]``, frequency ``[B]``, code ``[B]``, amplitude, point."""
        latent = self.pae.encoder(windows)
        phase, frequency, _ = self.pae.timing(latent)
        raw = self.pae.amp_mlp(latent.mean(dim=-1))
        d2 = (
            raw.square().sum(1, keepdim=True)
            - 2 * raw @ self.codebook.t()
            + self.codebook.square().sum(1)
        )
        code = d2.argmin(dim=1)
        amplitude = self.codebook[code]
        point = phase_manifold(amplitude, phase.unsqueeze(-1))[..., 0]
        return phase, frequency, code, amplitude, point


def export_graphs(aligner: VqpaeModel) -> list[ExportGraph]:
    """Per character: the encoder (phase, frequency, code, amplitude, manifold point).

    And, when its average-pose MLP was trained, the decoder from a manifold
    point to the average pose. The window length is fixed by the
    architecture (the frequency MLP reads its ``T // 2 + 1`` rfft bins), so
    only the batch axis is dynamic.

    Raises:
        SkelagnosticError: The aligner has no datasets yet.
    """
    book = aligner._require_built()
    graphs = []
    for name, char in zip(aligner.dataset_names, aligner.characters, strict=True):
        spec = aligner.hparams["datasets"][name]
        window = int(spec["window"])
        meta = {
            "dataset": name,
            "skeleton": spec.get("skeleton"),  # None for an authors' run (.authors)
            "fps": float(spec["fps"]),
            "window": window,
            "pivot": window // 2,
            "channels": int(spec["channels"]),
        }
        graphs.append(_encoder_graph(char, book, spec, meta))
        if bool(char.pose_fitted) and not spec.get("pose_features"):
            graphs.append(_pose_graph(char, int(aligner.hparams.latent), spec, meta))
    return graphs


def _stem(name: str) -> str:
    """A dataset name as a file-name part."""
    return "".join(c if c.isalnum() or c in "_.-" else "_" for c in name)


def _authors(spec: dict[str, Any]) -> bool:
    """Whether the dataset was trained on the authors' features (``data.features=authors``)."""
    return spec.get("features", "raw") == "authors"


def _encoder_graph(
    char: Any, book: torch.Tensor, spec: dict[str, Any], meta: dict[str, Any]
) -> ExportGraph:
    """The encoder graph of one character (see :func:`export_graphs`)."""
    name, channels, window = meta["dataset"], meta["channels"], meta["window"]
    fixed = {
        "window": f"{window} frames ({meta['fps']:g} fps): the frequency "
        f"MLP reads the {window // 2 + 1} rfft bins of the window"
    }
    outputs = ("phase", "frequency", "code", "amplitude", "manifold")
    representation = (
        "the WalkTheDog exporter's velocities (skelagnostic_vqpae.features."
        "authors_features) of the whole clip in metres"
        if _authors(spec)
        else "RootLocalVelocities of the motion in metres"
    )
    return ExportGraph(
        f"encoder_{_stem(name)}",
        _PivotEncoder(char.pae, book),
        (torch.zeros(2, channels, window).normal_(),),
        ("windows",),
        outputs,
        {k: {0: "batch"} for k in ("windows", *outputs)},
        description=(
            f"{name!r}: normalised windows [B, {channels}, {window}] centred on the "
            "pivot frame -> pivot phase (cycles), frequency (Hz), codebook index, "
            "quantised amplitude [B, 2d] and phase-manifold point [B, d]"
        ),
        fixed_axes=fixed,
        metadata={
            **meta,
            "representation": representation
            + ", [T, J, 3] flattened to [T, J*3] and transposed to [J*3, T]",
            "normalisation": {
                "input_mean": char.input_mean,
                "input_std": char.input_std,
                "formula": "(features - input_mean) / input_std",
            },
            "preprocess": "resample to fps; the window of frame i holds frames "
            "i - pivot .. i + pivot (repeat the end frames at "
            "the clip edges)",
        },
    )


def _pose_graph(char: Any, latent: int, spec: dict[str, Any], meta: dict[str, Any]) -> ExportGraph:
    """The average-pose decoder graph of one character (see :func:`export_graphs`)."""
    name, channels = meta["dataset"], meta["channels"]
    representation = (
        "the WalkTheDog exporter's root-local positions"
        if _authors(spec)
        else "GlobalPositions(frame='root')"
    )
    return ExportGraph(
        f"pose_decoder_{_stem(name)}",
        Method(char.pose, "forward"),
        (torch.zeros(2, latent).normal_(),),
        ("manifold",),
        ("pose",),
        {"manifold": {0: "batch"}, "pose": {0: "batch"}},
        description=(
            f"{name!r}: phase-manifold point [B, d] -> normalised "
            f"average root-local pose [B, {channels}] (Sec. 5.2)"
        ),
        metadata={
            **meta,
            "representation": representation + ", [J, 3] flattened to [J*3]",
            "normalisation": {
                "pose_mean": char.pose_mean,
                "pose_std": char.pose_std,
                "formula": "pose * pose_std + pose_mean",
            },
            "postprocess": "inverse kinematics gives rotations",
        },
    )
