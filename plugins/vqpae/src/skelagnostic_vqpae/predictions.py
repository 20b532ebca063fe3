"""Per-clip embeddings of a predict run: grouping windows into clips, writing them."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["EMBEDDING_FIELDS", "clips_in_frame_order", "write_embeddings"]

#: Per-pivot fields of an embedding, in :class:`~skelagnostic_vqpae.embed.ClipEmbedding` order.
EMBEDDING_FIELDS = ("phase", "frequency", "code", "amplitude", "manifold")


def clips_in_frame_order(cat: Mapping[str, Tensor]) -> list[tuple[int, Tensor]]:
    """``(clip index, indices of its windows sorted by pivot frame)`` for every clip in ``cat``."""
    out = []
    for c in cat["clip"].unique().tolist():
        sel = (cat["clip"] == c).nonzero().squeeze(1)
        out.append((c, sel[cat["pivot"][sel].argsort()]))
    return out


def write_embeddings(aligner: Any, collected: Mapping[str, list[dict[str, Tensor]]]) -> Path | None:
    """Write predicted embeddings per clip as ``<default_root_dir>/embeddings.npz``.

    Keys are ``<dataset>/<clip id>/<field>`` with fields ``frame`` (pivot frame
    index in the clip, at the dataset frame rate), ``phase``, ``frequency``,
    ``code``, ``amplitude`` and ``manifold``, plus ``fps``. Clip ids come from
    the data module's predict split (``clip<k>`` without one). Only pivots whose
    1 s window lies inside the clip are predicted; for every frame of a clip
    use :func:`skelagnostic_vqpae.embed.embed_clip`. Under DDP the global-zero
    rank writes the windows it predicted (predict on one device for all).

    Args:
        aligner: The aligner that predicted (its trainer, data module and datasets).
        collected: Dataset name -> the outputs of its ``predict_step`` calls.

    Returns:
        The written path, or None (nothing collected, or not the global-zero rank).
    """
    if not collected or aligner.trainer is None or not aligner.trainer.is_global_zero:
        return None
    dm = aligner.trainer.datamodule
    split = "test" if dm is not None and dm.datasets.get("test") else "val"
    ids = getattr(dm, "clip_ids", {}).get(split, {}) if dm is not None else {}
    arrays: dict[str, Any] = {}
    for name, parts in collected.items():
        cat = {k: torch.cat([p[k] for p in parts]) for k in parts[0]}
        names = ids.get(name, [])
        for c, sel in clips_in_frame_order(cat):
            clip = names[c] if c < len(names) else f"clip{c}"
            arrays[f"{name}/{clip}/frame"] = cat["pivot"][sel].numpy()
            for key in EMBEDDING_FIELDS:
                arrays[f"{name}/{clip}/{key}"] = cat[key][sel].numpy()
    spec = next(iter(aligner.hparams["datasets"].values()))
    arrays["fps"] = np.float64(spec["fps"])
    path = Path(aligner.trainer.default_root_dir) / "embeddings.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)
    return path
