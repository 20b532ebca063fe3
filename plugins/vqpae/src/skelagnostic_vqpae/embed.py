"""After training: per-frame embeddings, the average-pose MLP, retrieval and figures.

* :func:`embed_clip` -> :class:`ClipEmbedding` (phase, frequency, code,
  amplitude, manifold point per frame; saved as ``.npz``), Sec. 4;
  :func:`embed_datasets`: the same for every clip of a data-module split;
* :func:`fit_average_pose`: train the per-dataset average-pose MLPs on a frozen
  VQ-PAE (Sec. 5.2, Eq. 10) when they were not trained alongside;
* :func:`retrieve`: motion retrieval by amplitude + frequency (Sec. 5.4);
* :func:`ellipse_points`, :func:`plot_manifold`, :func:`plot_clip_timing`: the
  phase manifold of Fig. 1 and phase/frequency over time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from skelagnostic.core.motion import Motion
from skelagnostic.errors import SkelagnosticError
from skelagnostic_vqpae.model import phase_manifold
from skelagnostic_vqpae.predictions import EMBEDDING_FIELDS, clips_in_frame_order
from skelagnostic_vqpae.training import VqpaeModel

__all__ = [
    "ClipEmbedding",
    "Retrieval",
    "ellipse_points",
    "embed_clip",
    "embed_datasets",
    "fit_average_pose",
    "plot_clip_timing",
    "plot_manifold",
    "retrieve",
]


@dataclass
class ClipEmbedding:
    """Per-frame phase-manifold embedding of a clip (each frame the pivot of its 1 s window).

    Attributes:
        phase: ``[F]`` phase in cycles, ``(-1/2, 1/2]``.
        frequency: ``[F]`` frequency in Hz.
        code: ``[F]`` codebook index.
        amplitude: ``[F, 2d]`` quantised amplitude.
        manifold: ``[F, d]`` manifold point ``Psi(A, phi)``.
        fps: Frame rate of the embedding (the dataset's).
        dataset: Name of the dataset (character) that encoded it.
    """

    phase: Tensor
    frequency: Tensor
    code: Tensor
    amplitude: Tensor
    manifold: Tensor
    fps: float
    dataset: str

    def __len__(self) -> int:
        return int(self.phase.shape[0])

    def save(self, path: str | Path) -> Path:
        """Write an ``.npz`` with arrays ``phase frequency code amplitude manifold fps dataset``."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(
            path,
            phase=self.phase.numpy(),
            frequency=self.frequency.numpy(),
            code=self.code.numpy(),
            amplitude=self.amplitude.numpy(),
            manifold=self.manifold.numpy(),
            fps=np.float64(self.fps),
            dataset=np.str_(self.dataset),
        )
        return path

    @classmethod
    def load(cls, path: str | Path) -> ClipEmbedding:
        """Read a file written by :meth:`save`.

        Raises:
            SkelagnosticError: The file lacks one of the arrays.
        """
        with np.load(Path(path)) as data:
            missing = {
                "phase",
                "frequency",
                "code",
                "amplitude",
                "manifold",
                "fps",
                "dataset",
            } - set(data.files)
            if missing:
                raise SkelagnosticError(
                    f"{path}: not a VQ-PAE embedding (missing {sorted(missing)})"
                )
            return cls(
                *(
                    torch.from_numpy(data[k])
                    for k in ("phase", "frequency", "code", "amplitude", "manifold")
                ),
                float(data["fps"]),
                str(data["dataset"]),
            )


def embed_clip(aligner: VqpaeModel, motion: Motion) -> ClipEmbedding:
    """Embed every frame of ``motion`` with the VQ-PAE of its skeleton.

    Args:
        aligner: A trained aligner.
        motion: A clip on one of the trained skeletons (any frame rate; resampled).

    Returns:
        The embedding at the dataset frame rate.
    """
    latent = aligner.encode(motion)
    x = latent.extras
    return ClipEmbedding(
        x["phase"],
        x["frequency"],
        x["code"],
        x["amplitude"],
        latent.z,
        latent.fps,
        aligner.dataset_names[int(x["dataset"])],
    )


@torch.no_grad()
def embed_datasets(
    aligner: VqpaeModel, datasets: Mapping[str, Any], fps: float, batch_size: int = 1024
) -> dict[str, list[ClipEmbedding]]:
    """Embed every window of a data-module split, grouped into per-clip embeddings.

    Args:
        aligner: A trained aligner.
        datasets: Dataset name -> windows (``VqpaeDataModule.datasets[split]``).
        fps: Frame rate of the windows.
        batch_size: Windows per forward pass.

    Returns:
        Dataset name -> one :class:`ClipEmbedding` per clip (pivots in frame order; only
        pivots whose window lies inside the clip).
    """
    out: dict[str, list[ClipEmbedding]] = {}
    for name, windows in datasets.items():
        k = aligner.dataset_names.index(name)
        parts: dict[str, list[Tensor]] = {}
        for start in range(0, len(windows), batch_size):
            b = windows.gather(range(start, min(start + batch_size, len(windows))))
            b["features"] = b["features"].to(aligner.device)
            for key, value in aligner.pivot_embedding(k, b).items():
                parts.setdefault(key, []).append(value.detach().cpu())
        cat = {key: torch.cat(v) for key, v in parts.items()}
        out[name] = (
            [
                ClipEmbedding(*(cat[key][sel] for key in EMBEDDING_FIELDS), float(fps), name)
                for _, sel in clips_in_frame_order(cat)
            ]
            if cat
            else []
        )
    return out


def fit_average_pose(
    aligner: VqpaeModel, datamodule: Any, epochs: int = 1, lr: float = 1e-3
) -> dict[str, float]:
    """Train every dataset's average-pose MLP on the frozen VQ-PAE (Sec. 5.2, Eq. 10).

    Each window frame's manifold point ``P[:, t]`` is mapped to its normalised
    root-local pose; MSE, Adam.

    Args:
        aligner: A trained aligner (its VQ-PAEs and codebook stay fixed).
        datamodule: The :class:`~skelagnostic_vqpae.data.VqpaeDataModule` it was trained on
            (set up).
        epochs: Passes over each dataset's training windows.
        lr: Adam learning rate.

    Returns:
        Per dataset, the mean loss of the last epoch.
    """
    if epochs <= 0:
        raise SkelagnosticError(f"fit_average_pose: epochs must be positive, got {epochs}")
    aligner.eval()
    last: dict[str, float] = {}
    for name, loader in datamodule.loaders("train", shuffle=True).items():
        k = aligner.dataset_names.index(name)
        mlp = aligner.characters[k].pose
        opt = torch.optim.Adam(mlp.parameters(), lr=lr)
        for _ in range(epochs):
            losses = []
            for batch in loader:
                with torch.no_grad():
                    p = aligner.encode_dataset(k, batch["features"].to(aligner.device))
                loss = torch.nn.functional.mse_loss(
                    mlp(p.manifold.transpose(1, 2)), batch["poses"].to(aligner.device)
                )
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()))
            last[name] = sum(losses) / len(losses)
        aligner.characters[k].pose_fitted.fill_(True)
    return last


def ellipse_points(codebook: Tensor, samples: int = 64) -> Tensor:
    """``[K, samples, d]`` points of every codebook ellipse at uniformly spaced phases."""
    phase = torch.arange(samples, dtype=codebook.dtype) / samples
    return phase_manifold(codebook.detach().cpu(), phase).transpose(1, 2)


@dataclass(frozen=True)
class Retrieval:
    """A retrieved window: clip index in the searched list, first frame, length, distance."""

    clip: int
    frame: int
    length: int
    distance: float


def retrieve(
    database: Sequence[ClipEmbedding],
    amplitude: Tensor,
    frequency: float,
    top: int = 1,
) -> list[Retrieval]:
    """Motion retrieval by amplitude and frequency (Sec. 5.4).

    Builds one cycle ``Psi(A, phi_i)``, ``phi_i = i f dt``, ``N = round(1 / (f dt))``
    frames, and returns the ``top`` windows of ``N`` frames of the database
    embeddings nearest to it (sum of squared distances of manifold points).

    Args:
        database: Embeddings of the clips to search (same frame rate).
        amplitude: ``[2d]`` a codebook entry.
        frequency: Frequency in Hz.
        top: Number of results.

    Returns:
        The best windows, nearest first.

    Raises:
        SkelagnosticError: Empty database, non-positive frequency or mixed frame rates.
    """
    if not database:
        raise SkelagnosticError("retrieve: database holds no embedding")
    if not frequency > 0:
        raise SkelagnosticError(f"retrieve: frequency must be positive, got {frequency}")
    fps = database[0].fps
    if any(e.fps != fps for e in database):
        raise SkelagnosticError("retrieve: database embeddings have different frame rates")
    n = max(2, round(fps / frequency))
    query = phase_manifold(amplitude.float(), torch.arange(n) * frequency / fps).t()  # [N, d]
    found: list[Retrieval] = []
    for c, emb in enumerate(database):
        if len(emb) < n:
            continue
        windows = emb.manifold.float().unfold(0, n, 1).transpose(1, 2)  # [W, N, d]
        dist = (windows - query).square().sum((1, 2))
        best = torch.topk(dist, min(top, len(dist)), largest=False)
        found += [
            Retrieval(c, int(i), n, float(d))
            for d, i in zip(best.values, best.indices, strict=True)
        ]
    return sorted(found, key=lambda r: r.distance)[:top]


def plot_manifold(
    aligner: VqpaeModel,
    embeddings: Mapping[str, Sequence[ClipEmbedding]],
    out: str | Path | None = None,
    samples: int = 64,
) -> Any:
    """The phase manifold like Fig. 1: PCA of the codebook ellipses, one panel per character.

    Args:
        aligner: A trained aligner.
        embeddings: Per character, embeddings of its clips (codes and points drawn).
        out: Optional image path.
        samples: Phases per ellipse.

    Returns:
        The matplotlib figure.
    """
    from skelagnostic.viz import plot_phase_manifold

    book = aligner._require_built().weight.detach().cpu()
    usage = {n: torch.cat([e.code for e in embs]).numpy() for n, embs in embeddings.items()}
    points = {n: torch.cat([e.manifold for e in embs]).numpy() for n, embs in embeddings.items()}
    return plot_phase_manifold(book.numpy(), usage, points=points, samples=samples, out=out)


def plot_clip_timing(embeddings: Mapping[str, ClipEmbedding], out: str | Path | None = None) -> Any:
    """Phase, frequency and code over time for one or several clips (same frame rate)."""
    from skelagnostic.viz import plot_phase_over_time

    fps = next(iter(embeddings.values())).fps
    return plot_phase_over_time(
        {n: e.phase.numpy() for n, e in embeddings.items()},
        {n: e.frequency.numpy() for n, e in embeddings.items()},
        {n: e.code.numpy() for n, e in embeddings.items()},
        fps=fps,
        out=out,
    )
