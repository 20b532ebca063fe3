"""What a VQ-PAE fit leaves in its run directory (via ``FitSummary``).

:func:`fit_summary` embeds the validation (and training) clips, measures the
manifold overlap of their codes (paper Table 2) and draws the phase manifold
and the per-clip timing; the callback writes them as ``vqpae_metrics.json``,
``vqpae_manifold.png`` and ``vqpae_timing.png``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import torch

from skelagnostic.metrics.functional import manifold_overlap

if TYPE_CHECKING:
    import lightning as L

    from skelagnostic.callbacks import SummaryContent
    from skelagnostic_vqpae.aligner import VqpaeAligner

__all__ = ["fit_summary", "overlap_figures"]


def fit_summary(aligner: VqpaeAligner, trainer: L.Trainer) -> SummaryContent:
    """The manifold figures and pictures of the fit summary (:meth:`VqpaeAligner.fit_summary`).

    * metrics (in ``vqpae_metrics.json``): the manifold overlap (usage,
      overlap, per-dataset share, codes used per dataset) of the per-frame
      codes of the validation clips (``"split": "val"``; the training clips
      without a validation split), and under ``"train"`` the same figures
      for the training clips (the paper's Table 2 measures the training data);
    * ``vqpae_manifold.png``: the phase manifold (PCA of the codebook
      ellipses, one panel per character, its frames' points; paper Fig. 1);
    * ``vqpae_timing.png``: phase, frequency and code over time for the
      first clip of every character.
    """
    dm = trainer.datamodule
    if dm is None or aligner.codebook is None:
        return {}
    splits = [
        name for name in ("val", "train") if any(len(d) for d in dm.datasets.get(name, {}).values())
    ]
    if not splits:
        return {}
    embeddings = {name: aligner.embed_windows(dm.datasets[name], dm.fps) for name in splits}
    figures = {name: overlap_figures(aligner, embeddings[name]) for name in splits}
    metrics = {
        "split": splits[0],
        **figures[splits[0]],
        **({"train": figures["train"]} if splits[0] != "train" else {}),
    }
    shown = {n: embs for n, embs in embeddings[splits[0]].items() if embs}
    if not shown:
        return {"metrics": metrics}
    from skelagnostic_vqpae.embed import plot_clip_timing, plot_manifold

    return {
        "metrics": metrics,
        "figures": {
            "manifold": plot_manifold(aligner, shown),
            "timing": plot_clip_timing({n: embs[0] for n, embs in shown.items()}),
        },
    }


def overlap_figures(aligner: VqpaeAligner, embeddings: Mapping[str, list[Any]]) -> dict[str, Any]:
    """Manifold overlap (Table 2) of per-clip embeddings of every dataset."""
    codes = [
        torch.cat([e.code for e in embeddings.get(n, [])] or [torch.zeros(0, dtype=torch.long)])
        for n in aligner.dataset_names
    ]
    overlap = manifold_overlap(codes, aligner._require_built().num_codes)
    single = len(aligner.dataset_names) < 2  # overlap is not applicable: None, not a number
    return {
        "usage": overlap["usage"],
        "overlap": None if single else overlap["overlap"],
        "per_dataset": {
            n: None if single or math.isnan(v) else v
            for n, v in zip(aligner.dataset_names, overlap["per_dataset"], strict=True)
        },
        "codes_used": {
            n: int(c.unique().numel()) for n, c in zip(aligner.dataset_names, codes, strict=True)
        },
    }
